"""Every figure is drawn from a simulated run, at its stated size, and is not blank."""

from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.image import imread
from matplotlib.text import Text
from matplotlib.transforms import Bbox
from scipy import stats

from calibration.io.run_records import TemperatureLog
from calibration.model.simulate import SimulationConfig, simulate_run
from calibration.regression.conjugate import LinearPosterior
from calibration.report import figures
from calibration.report.figures.parameters import evidence_profile, parameter_bands
from calibration.report.figures.sources import SHOWN_CHOICE_SHARE
from calibration.report.figures.style import DPI, WIDTH_IN
from calibration.solve.radiometric_solver import solve_radiometric

#: 201 channels and six calibrators: every figure in about a second.
CONFIG = SimulationConfig(
    channel_width_hz=400e3, calibrators=("cold", "hot", "r25", "r100", "c10open", "c10short")
)
#: Standard deviation of a rendered figure's grey levels (0-1) below which it is blank.
MIN_PIXEL_STD = 0.08
#: Fraction of non-white pixels a figure with data must reach.
MIN_INK = 0.03


@pytest.fixture(scope="module")
def run():
    return simulate_run(CONFIG, rng=11)


@pytest.fixture(scope="module")
def solution(run):
    return solve_radiometric(run.data)


def render(fig: Figure, path: Path) -> np.ndarray:
    """Save ``fig`` as PNG and return its grey levels; check its size and its layout."""
    figures.save_png(fig, path)
    pixels = imread(path)
    width, height = fig.get_size_inches() * DPI
    assert pixels.shape[:2] == (round(height), round(width))
    assert pixels.shape[1] == round(WIDTH_IN * DPI)
    assert_laid_out(fig)
    return pixels[..., :3].mean(axis=2)


def assert_laid_out(fig: Figure) -> None:
    """Every axes with its labels and title, each legend and the title: inside, apart.

    The layout is fixed (margins in inches, not searched): this is what the search
    guaranteed, checked on the drawn figure.
    """
    renderer = fig.canvas.get_renderer()
    boxes = {f"axes {i} ({ax.get_title()!r})": ax.get_tightbbox(renderer)
             for i, ax in enumerate(fig.axes)}
    boxes.update({f"legend {i}": lg.get_window_extent(renderer)
                  for i, lg in enumerate(fig.legends)})
    if fig.get_suptitle():
        boxes["title"] = fig._suptitle.get_window_extent(renderer)
    page = fig.bbox.padded(0.5)  # the rounding of a pixel
    for name, box in boxes.items():
        assert page.x0 <= box.x0 <= box.x1 <= page.x1, (name, box, page)
        assert page.y0 <= box.y0 <= box.y1 <= page.y1, (name, box, page)
    names = list(boxes)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            overlap = Bbox.intersection(boxes[a], boxes[b])
            assert overlap is None or min(overlap.width, overlap.height) < 1, (a, b, overlap)


def assert_drawn(fig: Figure, path: Path) -> None:
    grey = render(fig, path)
    assert grey.std() > MIN_PIXEL_STD
    assert np.mean(grey < 0.95) > MIN_INK


def texts(fig: Figure) -> str:
    return " ".join(t.get_text() for t in fig.findobj(Text))


def test_parameters_with_truth_and_bands(run, solution, tmp_path):
    fig = figures.noise_wave_parameters(solution, truth=run.truth.parameters)
    assert_drawn(fig, tmp_path / "parameters.png")
    assert "68" in texts(fig)
    assert "truth" in texts(fig)


def test_parameter_bands_of_one_model_are_student_t_intervals(run, solution):
    moments = {f.name: getattr(solution.posterior, f.name) for f in fields(LinearPosterior)}
    stored = replace(solution, posterior=LinearPosterior(**moments))  # one model, no mixture
    freq = run.data.freq_hz
    mean, bands = parameter_bands(stored, freq)
    np.testing.assert_allclose(mean, stored.evaluate(freq), rtol=0, atol=1e-12)
    z = stats.t.ppf(0.84, stored.posterior.dof)
    lo, hi = bands[0.68]
    np.testing.assert_allclose(hi, -lo, rtol=1e-12)
    np.testing.assert_allclose(hi, z * stored.parameter_std(freq), rtol=1e-12)
    # The mixture's bands come from its draws: about its std, and wider at 95 %.
    _, mixed = parameter_bands(solution, freq)
    width68 = mixed[0.68][1] - mixed[0.68][0]
    width95 = mixed[0.95][1] - mixed[0.95][0]
    assert np.all(width95 > width68)
    np.testing.assert_allclose(
        np.median(width68 / (2 * solution.parameter_std(freq)), axis=1), 1.0, atol=0.1
    )


def test_evidence_landscape(solution, tmp_path):
    assert_drawn(figures.evidence_landscape(solution), tmp_path / "evidence.png")
    profile = evidence_profile(solution)
    for name, n in zip(profile, solution.best_orders, strict=True):
        assert profile[name][n] == 0.0  # the best model is on every profile


def test_evidence_landscape_without_a_table_says_so(solution, tmp_path):
    fig = figures.evidence_landscape(replace(solution, evidence_table={}))
    render(fig, tmp_path / "empty.png")
    assert "no evidence table" in texts(fig)


def test_calibrated_sources(run, solution, tmp_path):
    data = run.data
    spectra = {
        name: solution.calibrate(data.freq_hz, data.gamma_rec, src, data.channel_width_hz)
        for name, src in {**data.sources, "ant": run.validation}.items()
    }
    references = {name: src.temperature_k for name, src in data.sources.items()}
    fig = figures.calibrated_sources(spectra, references)
    assert_drawn(fig, tmp_path / "sources.png")
    assert "cold:" in texts(fig)
    assert "ant: calibrated T (no reference)" in texts(fig)
    # The models' spread is drawn where it is a visible share of a source's error bars.
    shown = any(spectra[n].model_choice_share >= SHOWN_CHOICE_SHARE for n in references)
    assert ("of which the choice of model" in texts(fig)) == shown


def test_calibrated_sources_show_where_the_models_disagree(tmp_path):
    """Four calibrators, VNA noise, the truth beyond the identified box (seed 6): the
    antenna's calibration error is mostly the spread between the averaged models (0.81 of
    its variance), drawn as its own curve inside the calibration's and named in the
    legend."""
    from tests.test_errors_in_variables import beyond_run

    weak = beyond_run(6)
    data = weak.data
    solution = solve_radiometric(data)
    spectra = {
        name: solution.calibrate(
            data.freq_hz, data.gamma_rec, src, data.channel_width_hz, data.gamma_rec_std
        )
        for name, src in {**data.sources, "ant": weak.validation}.items()
    }
    references = {name: src.temperature_k for name, src in data.sources.items()}
    references["ant"] = weak.validation_temperature_k
    fig = figures.calibrated_sources(spectra, references)
    assert_drawn(fig, tmp_path / "sources_weak.png")
    assert "of which the choice of model" in texts(fig)
    assert spectra["ant"].model_choice_share > 0.5


def test_reflections(run, tmp_path):
    fig = figures.reflections(run.data, {"ant": run.validation})
    assert_drawn(fig, tmp_path / "reflections.png")
    assert "receiver (LNA)" in texts(fig)


def test_dicke_powers(run, tmp_path):
    assert_drawn(figures.dicke_powers(run.data, {"ant": run.validation}), tmp_path / "d.png")


def test_flagged_channels_from_a_mask_and_by_name(run, tmp_path):
    freq = run.data.freq_hz
    mask = np.zeros(freq.size, dtype=bool)
    mask[[20, 21, 22, 150]] = True
    fig = figures.flagged_channels(freq, mask)
    assert_drawn(fig, tmp_path / "flags.png")
    assert "run: 4 (1.99%)" in texts(fig)
    coarse = freq[::2]
    named = {"ant": mask, "obs": (coarse, np.zeros(coarse.size, dtype=bool))}
    render(figures.flagged_channels(freq, named), tmp_path / "named.png")
    with pytest.raises(ValueError, match="flags of 'ant'"):
        figures.flagged_channels(freq, {"ant": mask[:-1]})


def test_flagged_channels_without_flags_says_so(run, tmp_path):
    fig = figures.flagged_channels(run.data.freq_hz, None)
    render(fig, tmp_path / "none.png")
    assert "no channel flags" in texts(fig)
    clean = figures.flagged_channels(run.data.freq_hz, np.zeros(run.data.n_channels, bool))
    render(clean, tmp_path / "clean.png")
    assert "no channel flagged" in texts(clean)


def test_temperatures(tmp_path):
    rng = np.random.default_rng(3)
    times = 1.79e9 + 30.0 * np.arange(600)
    values = np.column_stack([25 + 0.05 * rng.standard_normal(600), 97 + np.sin(times / 3e3)])
    log = TemperatureLog(times, values, ("MS1 switch", "heated load thermistor"))
    fig = figures.temperatures(log)
    assert_drawn(fig, tmp_path / "temperatures.png")
    assert "heated load thermistor" in texts(fig)
    empty = figures.temperatures(None)
    render(empty, tmp_path / "no-log.png")
    assert "no thermocouple log" in texts(empty)
