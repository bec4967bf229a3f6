"""The engine on a real calibration: EDGES-3, day 2022-316, against EDGES' published solution.

The data (edges-cal test data, MIT) live beside the checkout, never in it; see its README.

How the bounds are set (fixed from the physics below, not fitted to the results):

* Noise. ``sigma_f = |X_L T_NS| sqrt(var Q_f)``: the radiometer-limited error of one
  channel of a calibrated load, with ``var Q`` measured from the spectrum's own
  channel-to-channel scatter (:func:`calibration.io.edges_text.empirical_q_variance`) and
  ``T_NS = 1000 sca`` from the *published* solution, so the bound does not depend on the
  fit under test. Its band RMS is the RMS a noise-limited calibration reaches (35 fitted
  coefficients over 11472 rows reduce it by only 0.15%). ``NOISE_MARGIN = 1.1`` allows
  10% for the noise estimate (block MADs over 2866 channels: ~2% statistical; the MAD of
  second differences also picks up a little of the open/short's sharp S11 structure).
* Systematics. ``S_MATCHED = 0.05 K`` for a matched load (10% of the 0.5 K absorption
  feature a global 21-cm experiment must resolve). A reflective load multiplies every
  receiver-model error by ``X_L = |1 - G G_rec|^2 / (1 - |G|^2)`` (about 6 for the open
  and short, 1 for amb and hot), so its allowance is ``S_MATCHED * rms(X_L)``.
* Hot load. Its physical temperature at the S11 plane is ``G 393.22 + (1 - G) 306.5``
  with the cable gain ``G`` of the published pipeline's loss model (reproduced here, and
  checked against edges-cal when installed). In case that 4-inch UT-141C-SP model is not
  this receiver's actual cable, the hot bound adds the whole correction, max 0.30 K.
* Bound on the RMS of calibrated minus physical: ``sqrt((1.1 sigma)^2 + S^2 [+ loss^2])``.
  Agreement with the published solution: both may be off by their allowance ``S`` in
  opposite directions, so their calibrated temperatures may differ by ``2 S``.

Found, and asserted as such: no 7-term model meets the open/short bound (ours 0.77/0.82 K,
EDGES' own pipeline 0.75/0.82 K, against 0.72/0.78 K); both leave +-0.3 K mean offsets on the
open and short. The evidence-chosen orders meet it. The 7-term solution is therefore held to
the published 7-term pipeline on the open and short (same model size: at most 5% worse).
"""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calibration.choice.model_fit import OrderChoice
from calibration.io import edges_text as et
from calibration.io.edges_import import load_edges3_run
from calibration.model.noise_waves import design_terms
from calibration.solve.radiometric_solver import solve_radiometric

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "edges3-2022-316"
pytestmark = pytest.mark.skipif(
    not DATA.is_dir(),
    reason=f"the shared EDGES-3 data set is not beside this checkout (looked for {DATA})",
)

NOISE_MARGIN = 1.1
S_MATCHED_K = 0.05
PUBLISHED_7TERM_TOLERANCE = 1.05
N_SPECTRA = 450


@pytest.fixture(scope="module")
def data():
    return load_edges3_run(DATA)


@pytest.fixture(scope="module")
def published():
    return et.read_published_solution(DATA)


@pytest.fixture(scope="module")
def solutions(data):
    return {
        "evidence": solve_radiometric(data),
        "seven": solve_radiometric(data, OrderChoice.fixed((7, 7, 7, 7, 7))),
    }


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def noise_k(data, published, name):
    """Band RMS of the radiometer-limited error of a calibrated load (module docstring)."""
    src = data.sources[name]
    x_l = design_terms(src.gamma, data.gamma_rec).x_l
    return rms(x_l * 1000.0 * published["sca"] * np.sqrt(src.q_variance_override))


def allowance_k(data, name):
    src = data.sources[name]
    return S_MATCHED_K * rms(design_terms(src.gamma, data.gamma_rec).x_l)


def bound_k(data, published, name):
    b2 = (NOISE_MARGIN * noise_k(data, published, name)) ** 2 + allowance_k(data, name) ** 2
    if name == "hot":
        gain = data.metadata["hot_load_gain"]
        b2 += float(np.max((1 - gain) * (et.T_HOT_K - et.T_COLD_K))) ** 2
    return float(np.sqrt(b2))


def calibrated(solution, data, name):
    src = data.sources[name]
    return solution.calibrate(data.freq_hz, data.gamma_rec, src, data.channel_width_hz).mean


def test_reader(data, published):
    assert data.names == ["amb", "hot", "open", "short"]
    assert data.n_channels == 2868
    assert data.metadata["n_spectra"] == dict.fromkeys(data.names, N_SPECTRA)
    np.testing.assert_allclose(data.freq_hz, published["freq_hz"], atol=1.0)
    # 200 MHz / 4096 grid, printed to 1 Hz in the files
    assert data.metadata["channel_spacing_hz"] == pytest.approx(200e6 / 4096, abs=1.0)
    assert data.channel_width_hz == pytest.approx(73.67e3, rel=1e-3)
    np.testing.assert_allclose(data.gamma_rec, published["s11_lna"], atol=2e-6)
    for src in data.sources.values():
        np.testing.assert_allclose(src.q, (src.p_source - 300.0) / 1000.0, rtol=0, atol=1e-15)


def test_noise_is_smoothed_white_noise(data):
    """The smoothing behind the 73.7 kHz bandwidth shows in the data's own noise.

    Lag-1 correlation of second differences: -0.564 for the Gauss-smoothed channels,
    -0.667 for independent ones. Its statistical error over 2866 values is ~0.025; 0.06
    is 2.4 sigma and still 4 sigma from the independent-channel value.
    """
    r1, r2, r3 = (et.neighbour_correlation(k) for k in (1, 2, 3))
    expected = (-4 + 7 * r1 - 4 * r2 + r3) / (6 - 8 * r1 + 2 * r2)
    assert expected == pytest.approx(-0.564, abs=1e-3)
    for name, src in data.sources.items():
        d2 = np.diff(src.p_source, 2)
        assert np.corrcoef(d2[:-1], d2[1:])[0, 1] == pytest.approx(expected, abs=0.06), name


def test_empirical_q_variance_against_radiometer_equation(data):
    """Measured scatter against the radiometer equation (450 cycles, 5.37 s, 73.7 kHz).

    With a noiseless receiver the equation is a floor: the measured variance must exceed
    it (it does, 5-8 times). The receiver's own noise, one number in T* units, is not in
    the files: fitted on the ambient load, the same number must then predict the other
    three loads' variance within a factor 1.5 (a common-mode receiver noise is the same
    for every load; found within 1.2).
    """
    empirical = {n: et.empirical_q_variance(s.p_source) for n, s in data.sources.items()}
    for name, src in data.sources.items():
        floor = et.radiometer_q_variance(src.p_source, N_SPECTRA)
        assert np.mean(empirical[name] >= floor) > 0.99, name
    amb = data.sources["amb"]
    offset = float(np.median(et.receiver_offset_k(amb.p_source, empirical["amb"], N_SPECTRA)))
    assert 0.0 < offset < 2000.0
    for name, src in data.sources.items():
        predicted = et.radiometer_q_variance(src.p_source, N_SPECTRA, t_offset_k=offset)
        assert 1 / 1.5 < np.median(empirical[name] / predicted) < 1.5, name


def test_engine_radiometer_equation_on_pseudo_powers(data):
    """Without the override the engine's radiometer equation is the noiseless-receiver floor."""
    for src in data.sources.values():
        plain = replace(src, q_variance_override=None)
        np.testing.assert_allclose(
            plain.q_variance(data.channel_width_hz),
            et.radiometer_q_variance(src.p_source, N_SPECTRA),
            rtol=1e-12,
        )


@pytest.mark.parametrize("name", ["amb", "hot", "open", "short"])
def test_evidence_orders_reach_the_bound(data, published, solutions, name):
    src = data.sources[name]
    error = rms(calibrated(solutions["evidence"], data, name) - src.temperature_k)
    assert error <= bound_k(data, published, name)
    # and no better than the noise allows: a sanity check on the noise estimate
    assert error >= noise_k(data, published, name) / NOISE_MARGIN


@pytest.mark.parametrize("name", ["amb", "hot", "open", "short"])
def test_seven_terms(data, published, solutions, name):
    src = data.sources[name]
    error = rms(calibrated(solutions["seven"], data, name) - src.temperature_k)
    if name in ("amb", "hot"):
        assert error <= bound_k(data, published, name)
    else:  # module docstring: no 7-term model meets the bound; match EDGES' pipeline
        theirs = et.published_calibrated_temperature(published, src.p_source, src.gamma)
        assert error <= PUBLISHED_7TERM_TOLERANCE * rms(theirs - src.temperature_k)


@pytest.mark.parametrize("which", ["evidence", "seven"])
@pytest.mark.parametrize("name", ["amb", "hot", "open", "short"])
def test_agreement_with_published(data, published, solutions, which, name):
    src = data.sources[name]
    theirs = et.published_calibrated_temperature(published, src.p_source, src.gamma)
    ours = calibrated(solutions[which], data, name)
    assert rms(ours - theirs) <= 2 * allowance_k(data, name)


@pytest.mark.parametrize("name", ["amb", "hot"])
def test_published_solution_on_matched_loads(data, published, name):
    """Reader, EDGES formula and hot-load loss together reproduce the published calibration."""
    src = data.sources[name]
    theirs = et.published_calibrated_temperature(published, src.p_source, src.gamma)
    assert rms(theirs - src.temperature_k) <= bound_k(data, published, name)
    assert abs(np.mean(theirs - src.temperature_k)) < 0.01


def test_hot_load_loss_is_what_the_pipeline_applied(data, published):
    hot = data.sources["hot"]
    theirs = et.published_calibrated_temperature(published, hot.p_source, hot.gamma)
    correction = (1 - data.metadata["hot_load_gain"]) * (et.T_HOT_K - et.T_COLD_K)
    assert np.min(correction) > 0.1
    assert np.max(correction) < 0.35
    # against 393.22 K the published hot load is low by the correction, on average
    assert np.mean(theirs - et.T_HOT_K) == pytest.approx(-np.mean(correction), abs=0.01)


def test_raw_s11_files(published):
    """Cubic splines through the raw VNA points instead of the pipeline's S11 models."""
    raw = load_edges3_run(DATA, use_modelled_s11=False)
    sol = solve_radiometric(raw, OrderChoice.fixed((7, 7, 7, 7, 7)))
    amb = raw.sources["amb"]
    assert rms(calibrated(sol, raw, "amb") - amb.temperature_k) <= bound_k(raw, published, "amb")


# The cross-check of these EDGES formulas against the installed edges-cal package (it
# agrees to 1e-12 K) lives in benchmarks/real_data_edges3.py: edges-cal is a benchmark
# dependency, not a test one.
