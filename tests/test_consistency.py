"""Calibrator consistency (``calibration.checks.consistency``): naming a calibrator stated wrong.

Simulated runs of 820 channels (8 iTPM channels each, 50-130 MHz, 600 s per Dicke
position) with the twelve REACH calibrators and the eight of thesis table 4.1; one
calibrator's stated temperature is set ``offset`` K off its true one. The check must name
it and recover the offset within 5 of its own standard errors; with no wrong calibrator it
must name none. Orders are fixed at the truth's (4, 3, 4, 4, 3) for speed (a check of 12
calibrators is 12 solves, 0.2 s); one case uses the evidence search.

Measured over more seeds by ``python -m benchmarks.consistency`` (fixed orders, 10 seeds
per culprit and offset, signs alternating, 134 s): every culprit (12-set: c2r36, c10open,
r100, c10r250; 8-set: cold, c10r250, r25, c2r91) at 0.05, 0.5, 1, 2 and 5 K was named in
10 of 10 runs; at 0.02 K in 3-10 of 10. With no culprit, 200 seeds per set, one was named
in 3/200 (12-set) and 4/200 (8-set) runs: 1.75 % over 400 against the stated alpha of 1 %
(Poisson p = 0.11 for 7 or more if the rate were 1 %). Here: 3 seeds per case, 24 null
runs per set, and the null's pooled held-out ``z`` must be standard normal (mean within
0.3, std within 0.8-1.2: the z of one run share its data, so the effective sample is
smaller than its size).
"""

from dataclasses import replace

import numpy as np
import pytest
from simulations import TABLE_4_1_ORDER

from calibration.checks.consistency import check_consistency, exclude_inconsistent
from calibration.choice.model_fit import OrderChoice
from calibration.core.errors import InvalidDataError
from calibration.model.data import CalibrationData
from calibration.model.simulate import (
    ITPM_CHANNEL_WIDTH_HZ,
    REACH_CALIBRATORS,
    SimulationConfig,
    simulate_run,
)
from calibration.solve.radiometric_solver import solve_radiometric

SETS = {"reach12": REACH_CALIBRATORS, "table4.1": TABLE_4_1_ORDER}
WIDTH_HZ = 8 * ITPM_CHANNEL_WIDTH_HZ
TRUE_ORDERS = (4, 3, 4, 4, 3)
SEEDS = (71, 72, 73)
N_NULL = 16


def solve_fixed(data: CalibrationData):
    return solve_radiometric(data, OrderChoice.fixed(TRUE_ORDERS))


def config(set_name: str) -> SimulationConfig:
    return SimulationConfig(calibrators=SETS[set_name], channel_width_hz=WIDTH_HZ)


def with_offset(data: CalibrationData, name: str, offset_k: float) -> CalibrationData:
    source = data.sources[name]
    wrong = replace(source, temperature_k=np.asarray(source.temperature_k) + offset_k)
    return replace(data, sources={**data.sources, name: wrong})


@pytest.fixture(scope="module")
def runs():
    return {s: [simulate_run(config(s), rng=seed).data for seed in SEEDS] for s in SETS}


@pytest.mark.parametrize(
    ("set_name", "culprit", "offset_k"),
    [
        ("reach12", "c2r36", 0.5),
        ("reach12", "c10open", -1.0),
        ("reach12", "r100", 5.0),
        ("reach12", "c10r250", 2.0),
        ("table4.1", "cold", 0.5),
        ("table4.1", "c10r250", -5.0),
        ("table4.1", "r25", 1.0),
        ("table4.1", "c2r91", -2.0),
    ],
)
def test_names_the_calibrator_stated_wrong(runs, set_name, culprit, offset_k):
    for data in runs[set_name]:
        report = check_consistency(with_offset(data, culprit, offset_k), solve_fixed)
        worst = report.worst
        assert worst is not None
        assert worst.name == culprit, report.lines()
        assert abs(worst.offset_k - offset_k) <= 5 * worst.offset_std_k, report.lines()


@pytest.mark.parametrize("set_name", list(SETS))
def test_consistent_runs_name_none_and_z_is_standard_normal(set_name):
    named, z = [], []
    for seed in range(N_NULL):
        report = check_consistency(simulate_run(config(set_name), rng=500 + seed).data, solve_fixed)
        named.append(report.worst)
        z += [c.z for c in report.checkable]
    assert sum(n is not None for n in named) <= 1  # alpha = 0.01: expect 0.16 of 16
    assert abs(np.mean(z)) < 0.3
    assert 0.8 < np.std(z) < 1.2


def test_evidence_search_names_it_too():
    data = with_offset(simulate_run(config("reach12"), rng=74).data, "c2r69", 0.5)
    choice = OrderChoice(max_orders=(6, 5, 6, 6, 5))
    report = check_consistency(data, lambda d: solve_radiometric(d, choice))
    assert report.worst is not None
    assert report.worst.name == "c2r69"


def test_a_wrong_hot_load_is_not_blamed_on_another(runs):
    """The hot load alone sets T_NS: its offset moves T_NS, which no other load can see."""
    for offset_k in (5.0, -5.0):
        report = check_consistency(with_offset(runs["reach12"][0], "hot", offset_k), solve_fixed)
        assert report.worst is None
        assert report.not_checkable == ("hot",)


def test_exclusion_re_solves_without_it_and_recovers_the_truth():
    run = simulate_run(config("reach12"), rng=75)
    result = exclude_inconsistent(with_offset(run.data, "c10open", 1.0), solve_fixed)
    assert result.excluded == ("c10open",)
    assert len(result.rounds) == 2
    assert result.rounds[1].worst is None
    assert result.solution is not None
    assert "c10open" not in result.solution.calibrators
    spectrum = result.solution.calibrate(
        run.data.freq_hz, run.data.gamma_rec, run.validation, run.data.channel_width_hz
    )
    error = spectrum.mean - run.validation_temperature_k
    assert np.sqrt(np.mean(error**2)) < 1.2 * np.sqrt(np.mean(spectrum.std**2))


def test_two_wrong_calibrators_and_the_exclusion_limit(runs):
    data = with_offset(with_offset(runs["reach12"][1], "c2r27", 1.0), "r25", -2.0)
    limited = exclude_inconsistent(data, solve_fixed, max_exclusions=1)
    assert len(limited.excluded) == 1
    assert limited.excluded[0] in ("c2r27", "r25")
    assert "limit of 1" in limited.stopped
    both = exclude_inconsistent(data, solve_fixed, max_exclusions=3)
    assert sorted(both.excluded) == ["c2r27", "r25"]
    assert both.rounds[-1].worst is None


def test_refusals_are_reported_not_raised():
    """Three ambient loads: every solve refuses T_NS; nothing is checkable or excluded."""
    cfg = replace(config("reach12"), calibrators=("cold", "r25", "c10open"))
    result = exclude_inconsistent(simulate_run(cfg, rng=1).data, solve_fixed)
    assert result.excluded == ()
    assert result.rounds[0].not_checkable == ("cold", "r25", "c10open")
    assert result.solution is None
    assert "T_NS" in (result.refused or "")
    assert "refused" in "\n".join(result.lines())


def test_bad_arguments():
    data = simulate_run(config("table4.1"), rng=1).data
    with pytest.raises(InvalidDataError, match="alpha"):
        check_consistency(data, solve_fixed, alpha=0.0)
    with pytest.raises(InvalidDataError, match="offset_sd_k"):
        check_consistency(data, solve_fixed, offset_sd_k=0.0)
    with pytest.raises(InvalidDataError, match="max_exclusions"):
        exclude_inconsistent(data, solve_fixed, max_exclusions=-1)
