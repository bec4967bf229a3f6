"""reach-cal season: many nights' calibrated spectra in LST bins, errors in two parts.

Nights are simulated with the engine's own simulation: a calibration run
(:func:`calibration.model.simulate.simulate_run`) solved into a solution, and antenna
cycles of a known power-law sky calibrated with it, each night with its own solution
and noise. Run files are written by the receiver's own store (``RunStore``), as the
observe step writes them. The statistics run in memory through the same per-run
functions (``bin_run``/``combine``); one test holds that the file path gives the same.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import h5py
import numpy as np
import pytest

from calibration.choice.model_fit import OrderChoice
from calibration.cli import main
from calibration.core.sidereal import apparent_lst_h
from calibration.io.calibrated_spectra import (
    RunSpectra,
    Site,
    SolutionRecord,
    read_calibrated_spectra,
)
from calibration.model.data import Integration
from calibration.model.reflections import reach_source_reflection
from calibration.model.simulate import SimulationConfig, simulate_run, simulate_source
from calibration.season.binning import bin_run, combine, lst_edges
from calibration.season.season_file import read_season
from calibration.solve.solvers import solve
from reach_receiver.store import RunStore
from reach_receiver.store.handover import HandOver

SITE = Site("REACH Karoo", 21.52, -30.97)
SITE_YAML = "site: {name: REACH Karoo, longitude_deg: 21.52, latitude_deg: -30.97}\n"
#: 2024-03-01 00:00 UTC; nights start here, one sidereal day apart.
EPOCH = 1_709_251_200.0
SIDEREAL_DAY_S = 86_164.0905
ORDERS = OrderChoice.fixed((4, 4, 4, 4, 4))  # the simulated receiver's (4, 3, 4, 4, 3) inside


def sky_k(freq_hz: np.ndarray, index: float = -2.5) -> np.ndarray:
    """The true sky: a power law, the same at every LST (so each bin's truth is known)."""
    return 3000.0 * (freq_hz / 75e6) ** index


@dataclasses.dataclass(frozen=True)
class Night:
    """A night's solution and the receiver it calibrates."""

    solution: object
    sim: object
    digest: str


def make_night(seed: int, width_hz: float = 400e3, cal_s: float = 30.0) -> Night:
    """A calibration run (seed) solved at fixed orders: one night's solution."""
    config = SimulationConfig(channel_width_hz=width_hz, integration_s=cal_s)
    sim = simulate_run(config, rng=seed)
    return Night(solve(sim.data, choice=ORDERS), sim, f"solution-{seed}")


def cycles(night: Night, rng: np.random.Generator, n: int, seconds: float, sky: np.ndarray):
    """``n`` antenna cycles calibrated with the night's solution: (spectrum, radiometer std)."""
    sim = night.sim
    freq = sim.data.freq_hz
    gamma = reach_source_reflection("ant", freq)
    out = []
    for _ in range(n):
        ant = simulate_source(
            "ant", freq, gamma, sim.gamma_rec_true, sky, sim.truth,
            Integration(seconds, seconds, seconds), sim.data.channel_width_hz, rng,
            known_temperature=False,
        )
        out.append(night.solution.calibrate(freq, sim.data.gamma_rec, ant,
                                            sim.data.channel_width_hz))
    return out


def night_times(night_index: int, n: int, start_lst_h: float = 2.0, step_s: float = 900.0):
    """Mid-times of ``n`` cycles from ``start_lst_h``, on night ``night_index``."""
    t0 = EPOCH + night_index * SIDEREAL_DAY_S
    lst0 = apparent_lst_h([t0], SITE.longitude_deg)[0]
    offset = ((start_lst_h - lst0) % 24.0) * 3600.0 / 1.0027379
    return t0 + offset + step_s * (np.arange(n) + 0.5)


def run_spectra(night: Night, spectra, times: np.ndarray, flags=None, path="mem") -> RunSpectra:
    """The in-memory form of a run file holding these calibrated spectra."""
    mean = np.stack([s.mean for s in spectra])
    flags = np.zeros(mean.shape, dtype=bool) if flags is None else flags
    meas = np.stack([s.std_measurement for s in spectra])
    return RunSpectra(
        path=path, run_name=path, site=SITE, freq_hz=spectra[0].freq_hz,
        names=tuple(f"ant_{i:04d}" for i in range(len(spectra))), mean=mean,
        std_radiometer=meas, std_calibration=np.stack([s.std_calibration for s in spectra]),
        std_reflection=np.zeros_like(mean), flags=flags, time_s=np.asarray(times),
        integration_s=np.full(len(spectra), 600.0),
        lst_h=apparent_lst_h(times, SITE.longitude_deg),
        solution=np.zeros(len(spectra), dtype=np.int64),
        solutions=(SolutionRecord(night.digest, path, "m", float(times[0]), "radiometric"),),
        sweeps=tuple(f"{path}:s11" for _ in spectra),
    )


def write_run(directory: Path, night: Night, spectra, times, flags=None,
              night_flags=None, powers=None) -> Path:
    """A receiver run file with the solution, each cycle and its calibrated spectrum.

    ``night_flags`` ``(cycle, channel)``: also the observe step's ``rfi_night_ant`` check.
    ``powers(i)``: cycle ``i``'s power at each Dicke position, on every channel from 0 Hz
    as the spectrometer stores them (by default 1 on the band's channels only).
    """
    freq = spectra[0].freq_hz
    store = RunStore(directory, name="night", schedule_files=[], site_yaml=SITE_YAML,
                     metadata={}, channel_width_hz=night.sim.data.channel_width_hz,
                     band_hz=(freq[0], freq[-1]))
    with store:
        s11_ant = store.add_s11("ant", freq, reach_source_reflection("ant", freq),
                                timestamp=times[0], settings={}, calibrated=True)
        s11_lna = store.add_s11("lna", freq, night.sim.data.gamma_rec, timestamp=times[0],
                                settings={}, calibrated=True)
        store.add_solution(night.solution, timestamp=times[0] - 60, verification={})
        width = night.sim.data.channel_width_hz
        stored = freq.size if powers is None else round(freq[-1] / width) + 1
        for i, (spectrum, t) in enumerate(zip(spectra, times, strict=True)):
            positions = ("source", "load", "ns")
            number = store.add_dicke(
                "ant", spectra={p: np.full((1, stored), 1.0 if powers is None
                                           else powers(i)[p]) for p in positions},
                timestamps={p: [t - 5, t + 5] for p in positions},
                integration_s=dict.fromkeys(positions, 300.0),
                n_spectra=dict.fromkeys(positions, 2), temperature_k=None,
                switch_states={}, counters={}, timestamp=t + 600,
            )
            handover = HandOver((freq[0], freq[-1]), night.sim.data.channel_width_hz,
                                {"ant": (number,)}, {"ant": s11_ant, "lna": s11_lna}, ())
            store.add_calibrated(
                f"ant_{i:04d}", freq, spectrum.mean, spectrum.std,
                np.zeros(freq.size, bool) if flags is None else flags[i], timestamp=t + 600,
                errors={"std_calibration": spectrum.std_calibration,
                        "std_radiometer": spectrum.std_measurement},
                handover=handover,
            )
        if night_flags is not None:
            store.add_check("rfi_night_ant", True, timestamp=times[-1] + 700,
                            details={"spectra": [f"ant_{i:04d}" for i in range(len(spectra))],
                                     "threshold_sigma": 5.0},
                            arrays={"flags": night_flags})
    return directory / "run.h5"


def season_of(runs, width_h: float = 1.0):
    edges = lst_edges(width_h)
    return combine(bin_run(r, edges) for r in runs)


def test_the_binned_sky_minus_the_truth_over_its_stated_error_has_rms_one():
    """Seasons of three nights each, over seeds, sky indices and integrations."""
    z = []
    for seed in range(12):
        rng = np.random.default_rng(100 + seed)
        index = rng.uniform(-2.8, -2.2)
        seconds = float(rng.choice([60.0, 600.0, 3600.0]))
        runs = []
        for k in range(3):
            night = make_night(1000 * seed + k, cal_s=float(rng.choice([30.0, 120.0])))
            sky = sky_k(night.sim.data.freq_hz, index)
            times = night_times(k, 6)
            runs.append(run_spectra(night, cycles(night, rng, 6, seconds, sky), times,
                                    path=f"night{k}"))
        season = season_of(runs)
        used = ~season.flags
        assert used.any(axis=1).sum() == 2  # 6 cycles of 15 min from LST 2 h: bins 2 and 3
        truth = sky_k(season.freq_hz, index)[None, :]
        z.append(((season.mean - truth) / season.std)[used])
    rms = float(np.sqrt(np.mean(np.concatenate(z) ** 2)))
    assert 0.9 < rms < 1.1, rms


def test_each_error_part_matches_a_monte_carlo_of_its_own_source():
    """New radiometer noise only: scatter = radiometer part; new solutions: calibration part."""
    nights = [make_night(7 + k) for k in range(2)]
    freq = nights[0].sim.data.freq_hz
    sky = sky_k(freq)
    times = [night_times(k, 6) for k in range(2)]
    radiometer_repeats = []
    for rep in range(40):
        rng = np.random.default_rng(rep)
        runs = [run_spectra(n, cycles(n, rng, 6, 600.0, sky), t, path=f"n{k}")
                for k, (n, t) in enumerate(zip(nights, times, strict=True))]
        radiometer_repeats.append(season_of(runs))
    means = np.stack([s.mean for s in radiometer_repeats])[:, 2]  # LST bin 2
    predicted = np.mean([s.std_radiometer[2] ** 2 for s in radiometer_repeats], axis=0)
    ratio_r = float(np.mean(np.var(means, axis=0, ddof=1)) / np.mean(predicted))
    assert 0.85 < ratio_r < 1.15, ratio_r

    calibration_repeats = []
    for rep in range(30):
        rng = np.random.default_rng(12345)  # the same radiometer noise every time
        runs = []
        for k in range(2):
            night = make_night(500 + 2 * rep + k)
            runs.append(run_spectra(night, cycles(night, rng, 6, 3600.0, sky), times[k],
                                    path=f"n{k}"))
        calibration_repeats.append(season_of(runs))
    means = np.stack([s.mean for s in calibration_repeats])[:, 2]
    predicted = np.mean([s.std_calibration[2] ** 2 for s in calibration_repeats], axis=0)
    ratio_c = float(np.mean(np.var(means, axis=0, ddof=1)) / np.mean(predicted))
    # 60 independent solutions, channels correlated: the variance ratio to about 25 %
    assert 0.6 < ratio_c < 1.4, ratio_c
    radiometer = np.mean([s.std_radiometer[2] ** 2 for s in calibration_repeats])
    assert np.mean(predicted) > 3 * radiometer  # the calibration part is what varied


def test_flagged_channels_get_no_weight(tmp_path):
    night = make_night(3)
    rng = np.random.default_rng(3)
    spectra = cycles(night, rng, 4, 600.0, sky_k(night.sim.data.freq_hz))
    times = night_times(0, 4, step_s=600.0)  # all in LST bin 2
    n_ch = night.sim.data.freq_hz.size
    flags = np.zeros((4, n_ch), dtype=bool)
    flags[0, 10:20] = True
    flags[:, 50] = True  # bad in every spectrum: the bin's channel has no data
    bad = [dataclasses.replace(s, mean=np.where(f, 1e6, s.mean))
           for s, f in zip(spectra, flags, strict=True)]
    path = write_run(tmp_path / "night", night, bad, times, flags)
    assert main(["season", str(path), "-o", str(tmp_path / "season.h5")]) == 0
    season = read_season(tmp_path / "season.h5")
    assert season.flags[2, 50]
    assert np.isnan(season.mean[2, 50])
    assert np.array_equal(season.count[2, 10:20], [3] * 10)
    assert np.array_equal(season.count[2, 21:50], [4] * 29)
    clean = np.delete(np.arange(n_ch), 50)
    truth = sky_k(season.freq_hz)
    assert np.all(np.abs(season.mean[2, clean] - truth[clean]) < 6 * season.std[2, clean])


def test_the_file_path_gives_the_in_memory_season(tmp_path):
    """Run files from the store, read back, give the season computed in memory."""
    runs, paths = [], []
    for k in range(2):
        night = make_night(40 + k)
        rng = np.random.default_rng(k)
        spectra = cycles(night, rng, 3, 600.0, sky_k(night.sim.data.freq_hz))
        times = night_times(k, 3)
        paths.append(write_run(tmp_path / f"night{k}", night, spectra, times))
        runs.append(run_spectra(night, spectra, times))
    read = [read_calibrated_spectra(p) for p in paths]
    assert read[0].site == SITE
    assert len({r.solutions[0].digest for r in read}) == 2
    assert main(["season", *map(str, paths), "-o", str(tmp_path / "s.h5"),
                 "--lst-bin-h", "0.5"]) == 0
    from_files = read_season(tmp_path / "s.h5")
    in_memory = season_of(runs, 0.5)
    np.testing.assert_allclose(from_files.mean, in_memory.mean, rtol=1e-12, equal_nan=True)
    np.testing.assert_allclose(from_files.std_radiometer, in_memory.std_radiometer,
                               rtol=1e-12, equal_nan=True)
    np.testing.assert_allclose(from_files.std_calibration, in_memory.std_calibration,
                               rtol=1e-12, equal_nan=True)
    assert [r.solution for r in from_files.spectra] == [
        from_files.solutions[0].digest] * 3 + [from_files.solutions[1].digest] * 3
    with h5py.File(tmp_path / "s.h5") as f:
        assert f["mean"].attrs["units"] == "K"
        assert f["weight"].attrs["units"] == "K^-2"
        assert f.attrs["format"] == "reach-calibration-season"


def _empty_run(directory: Path) -> Path:
    with RunStore(directory, name="empty", schedule_files=[], site_yaml=SITE_YAML, metadata={},
                  channel_width_hz=400e3) as store:
        store.add_event("note", "nothing calibrated", timestamp=EPOCH)
    return directory / "run.h5"


@pytest.mark.parametrize("case", ["no spectra", "grids", "missing", "bin width"])
def test_bad_input_is_a_short_error_and_nothing_written(tmp_path, capsys, case):
    night = make_night(5)
    rng = np.random.default_rng(5)
    good = write_run(tmp_path / "good", night,
                     cycles(night, rng, 2, 600.0, sky_k(night.sim.data.freq_hz)),
                     night_times(0, 2))
    argv = [str(good)]
    if case == "no spectra":
        argv.append(str(_empty_run(tmp_path / "empty")))
    elif case == "grids":
        other = make_night(6, width_hz=800e3)
        argv.append(str(write_run(tmp_path / "other", other,
                                  cycles(other, rng, 2, 600.0, sky_k(other.sim.data.freq_hz)),
                                  night_times(1, 2))))
    elif case == "missing":
        argv.append(str(tmp_path / "nowhere" / "run.h5"))
    extra = ["--lst-bin-h", "0.7"] if case == "bin width" else []
    out = tmp_path / "season.h5"
    capsys.readouterr()  # what writing the run files logged is not the command's answer
    assert main(["season", *argv, "-o", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert 1 <= len(err) <= 2, err
    assert err[0].startswith("reach-cal: error:"), err
    assert "Traceback" not in "\n".join(err)
    assert not out.exists()
    assert not list(tmp_path.glob(".season.h5*"))
