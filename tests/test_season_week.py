"""A short simulated week: ``reachd --sim`` on its timers, ``reach-cal season`` over its runs.

The suite's version of ``python -m benchmarks.season_week`` (its module doc has the
statistics): ``reachd --sim`` at its 3000x clock with the timers of the benchmark's site
(four 6-h slots a sidereal day, all of them observing here, so that whichever fires
first after the daemon serves is an observing run), stopped once two observing runs
completed, each with its own calibration and a few calibrated antenna cycles on 5 MHz of
band. The plan (calibrators, Dicke and antenna integrations, cycles) is drawn from a
seeded family. The tolerances follow from how many independent numbers each statistic
holds: a channel's radiometer noise is independent of every other's, while a solution's
error over the band is a few independent numbers, as many as its posterior says
(:func:`benchmarks.season_week.calibration_numbers`: about 1.5 over 5 MHz). A sum of
``k`` squared standard normals is chi^2 with ``k`` degrees of freedom, so each bound is a
chi^2 quantile: with two solutions the calibration part is known to a factor of a few
only (the benchmark's 80-odd solutions test it finely); the radiometer part, to 1 %.

The season must also read the observe step's night flags (``rfi_night_<source>``): a run
file written through the receiver's store, as the observe step writes it, whose night
flags mark channels that the cycles' own flags do not.
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from benchmarks.season_week import (
    Sums,
    WeekPlan,
    add_run,
    add_season,
    calibration_numbers,
    run_week,
    season_of,
)
from calibration.cli import main
from calibration.io.calibrated_spectra import read_calibrated_spectra
from calibration.season.binning import Season
from calibration.season.season_file import read_season
from tests.test_season import Night, cycles, make_night, night_times, sky_k, write_run

#: Tail probability each bound of a statistic allows (about that of 4 sigma).
TAIL = 1e-4
#: The family the short week's plan is drawn from (the benchmark runs seeds over it).
#: The open and shorted cables in every set: without a reflective calibrator the noise
#: waves' cos and sin terms are not identified (the solver refuses such a run).
CALIBRATOR_SETS = (("cold", "hot", "c10open", "c10short"),
                   ("cold", "hot", "c10open", "c10short", "r100"),
                   ("cold", "hot", "c10open", "c10short", "c2r36"))


def _plan() -> WeekPlan:
    rng = np.random.default_rng(39)
    return WeekPlan(
        days=3.0, compression=3000.0, seed=int(rng.integers(1000)), observing=4,
        cycles=2, position_s=float(rng.choice([100.0, 200.0, 400.0])),
        dicke_s=float(rng.choice([60.0, 120.0])), band_mhz=(60.0, 65.0),
        calibrators=CALIBRATOR_SETS[int(rng.integers(len(CALIBRATOR_SETS)))],
        observing_runs=2, start_real_s=5.0,
    )


@pytest.fixture(scope="module")
def week(tmp_path_factory):
    where = tmp_path_factory.mktemp("week")
    plan = _plan()
    done = run_week(where, plan)
    assert len(done.observing_runs) >= 2, (done.jobs, (where / "reachd.log").read_text()[-3000:])
    season = season_of(done.observing_runs, where / "season.h5", 1.0)
    runs = [read_calibrated_spectra(p / "run.h5") for p in done.observing_runs]
    return done, season, runs


def test_the_timers_ran_the_observing_runs_each_with_its_own_solution(week):
    done, season, runs = week
    assert all(re.fullmatch(r"timer observe-[0-3] \((on time|late)\)",
                            j["origin"]) for j in done.jobs), done.jobs
    assert len(season.solutions) == len(done.observing_runs)
    assert sum(r.mean.shape[0] for r in runs) == len(season.spectra)
    assert season.freq_hz[0] >= 60e6
    assert season.freq_hz[-1] <= 65e6


def _mean_square_bounds(share_r: float, n_r: float, n_c: float) -> tuple[float, float]:
    """Bounds on ``share_r chi2_r / n_r + (1 - share_r) chi2_c / n_c`` (mean z^2 when both
    parts are stated right), each tail at most ``2 TAIL``: a sum exceeds the sum of its
    terms' upper quantiles no more often than one of them does."""
    lo = share_r * chi2.ppf(TAIL, n_r) / n_r + (1 - share_r) * chi2.ppf(TAIL, n_c) / n_c
    hi = share_r * chi2.isf(TAIL, n_r) / n_r + (1 - share_r) * chi2.isf(TAIL, n_c) / n_c
    return float(lo), float(hi)


def test_the_season_minus_the_true_sky_over_its_stated_error_has_rms_one(week):
    done, season, _runs = week
    sums = Sums()
    add_season(sums, season)
    used = ~season.flags
    share_r = float(np.mean(season.std_radiometer[used] ** 2 / season.std[used] ** 2))
    numbers = sum(calibration_numbers(str(p / "run.h5")) for p in done.observing_runs)
    lo, hi = _mean_square_bounds(share_r, sums.z_n, numbers)
    assert lo < sums.rms**2 < hi, (sums.rms, lo, hi, share_r, numbers)


def test_each_error_part_against_the_scatter_of_its_own_source(week):
    _, _season, runs = week
    sums = Sums()
    for run in runs:
        add_run(sums, run)
    # the cycles' scatter: one independent chi^2 term per channel and degree of freedom
    assert chi2.ppf(TAIL, sums.dof) < sums.chi2 < chi2.isf(TAIL, sums.dof), sums.ratio_r
    # the runs' residuals: chi^2 of the solutions' independent numbers, plus what the
    # radiometer noise that is subtracted adds (normal, at 4 sigma)
    k = sums.cal_numbers
    noise = 4.0 * math.sqrt(sums.cal_noise_var) / sums.cal_stated
    lo, hi = chi2.ppf(TAIL, k) / k - noise, chi2.isf(TAIL, k) / k + noise
    assert lo < sums.ratio_c < hi, (sums.ratio_c, lo, hi, k)


# ------------------------------------------------------------------ the night's flags
def _night_run(directory: Path, night: Night, n: int, night_flags: np.ndarray,
               store_flags: bool = True) -> Path:
    """A run file as the observe step writes it: solution, cycles, each calibrated, and
    (``store_flags``) the night's flags, ``rfi_night_ant`` over the cycles' names."""
    freq = night.sim.data.freq_hz
    rng = np.random.default_rng(n)
    spectra = cycles(night, rng, n, float(rng.choice([60.0, 600.0])), sky_k(freq))
    # what the night flags mark is interference: far off
    spectra = [dataclasses.replace(s, mean=np.where(f, 1e6, s.mean))
               for s, f in zip(spectra, night_flags, strict=True)]
    times = night_times(0, n, step_s=600.0)  # every cycle in LST bin 2
    return write_run(directory, night, spectra, times,
                     night_flags=night_flags if store_flags else None)


def _season(run: Path, out: Path) -> Season:
    assert main(["season", str(run.parent), "-o", str(out)]) == 0
    return read_season(out)


@pytest.mark.parametrize(("seed", "n"), [(11, 4), (12, 6)])
def test_the_night_flags_of_the_observe_step_give_no_weight(tmp_path, seed, n):
    rng = np.random.default_rng(seed)
    night = make_night(seed)
    n_ch = night.sim.data.freq_hz.size
    everywhere = int(rng.integers(n_ch))  # bad all night: the bin's channel has no data
    once = rng.choice(np.delete(np.arange(n_ch), everywhere), size=5, replace=False)
    which = int(rng.integers(n))
    flags = np.zeros((n, n_ch), dtype=bool)
    flags[:, everywhere] = True
    flags[which, once] = True
    path = _night_run(tmp_path / "night", night, n, flags)
    season = _season(path, tmp_path / "season.h5")
    assert season.flags[2, everywhere]
    assert np.isnan(season.mean[2, everywhere])
    assert np.array_equal(season.count[2, once], [n - 1] * 5)
    clean = np.delete(np.arange(n_ch), everywhere)
    assert np.all(np.abs(season.mean[2, clean] - sky_k(season.freq_hz)[clean])
                  < 6 * season.std[2, clean])


def test_without_the_night_flags_those_channels_would_count(tmp_path):
    """The control: the same far-off values, no ``rfi_night_ant``: the season takes them."""
    night = make_night(11)
    flags = np.zeros((4, night.sim.data.freq_hz.size), dtype=bool)
    flags[:, 7] = True
    path = _night_run(tmp_path / "night", night, 4, flags, store_flags=False)
    season = _season(path, tmp_path / "season.h5")
    assert not season.flags[2, 7]
    assert season.mean[2, 7] > 1e5
