"""``reach-cal solve --contributions`` and ``reach-cal plan`` on simulated runs.

Two runs (different seeds and integration times, 410 channels): the contributions
table names every calibrator once with shares adding to 1, each error without a
calibrator above the error with all; the plan reaches its target in less instrument
time than the round-robin; bad requests end in one line saying what to do.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from calibration.cli.design import power_law
from calibration.cli.main import main
from calibration.core.constants import ITPM_CHANNEL_WIDTH_HZ, REACH_CALIBRATORS


@pytest.fixture(scope="module", params=[(3, "120"), (11, "600")])
def run(request, tmp_path_factory):
    seed, seconds = request.param
    path = tmp_path_factory.mktemp("design") / "run.h5"
    code = main([
        "simulate", "-o", str(path), "--seed", str(seed), "--integration-s", seconds,
        "--channel-width-hz", str(ITPM_CHANNEL_WIDTH_HZ * 16),
    ])
    assert code == 0
    return path


def test_solve_contributions_lists_every_calibrator(run, tmp_path, capsys):
    assert main(["solve", str(run), "-o", str(tmp_path / "s.h5"), "--contributions"]) == 0
    out = capsys.readouterr().out
    now = float(re.search(r"predicted calibration error ([\d.]+) mK", out).group(1))
    rows = re.findall(r"^  (\S+)\s+([\d.]+)\s+([\d.]+)\s+(\S+)$", out, re.M)
    assert sorted(r[0] for r in rows) == sorted(REACH_CALIBRATORS)
    assert sum(float(r[2]) for r in rows) == pytest.approx(1.0, abs=0.01)
    shares = [float(r[2]) for r in rows]
    assert shares == sorted(shares, reverse=True)
    for name, _, _, without in rows:
        assert without == "undetermined" or float(without) > now, name


def test_plan_reaches_the_target_in_less_time_than_the_round_robin(run, capsys):
    assert main(["plan", str(run), "--target-mk", "2", "--interest", "60,100"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"over 60[\d.]*-100 MHz", out)  # the channels inside the band
    rows = re.findall(r"^  (\S+)\s+([\d.]+)$", out, re.M)
    assert sorted(r[0] for r in rows) == sorted(REACH_CALIBRATORS)
    assert min(float(r[1]) for r in rows) == 60.0
    planned = float(re.search(r"instrument time ([\d.]+) h", out).group(1))
    predicted = float(re.search(r"predicted ([\d.]+) mK", out).group(1))
    robin = float(re.search(r"round-robin to the same target: [\d.e+]+ s each, ([\d.]+) h", out)
                  .group(1))
    assert predicted <= 2.0
    assert planned < robin
    assert "warning" not in out


def test_plan_says_when_the_budget_is_too_small(run, capsys):
    assert main(["plan", str(run), "--target-mk", "0.5", "--budget-h", "1"]) == 0
    out = capsys.readouterr().out
    assert "is not reached within --budget-h 1: raise --budget-h or the target" in out


@pytest.mark.parametrize(("argv", "says"), [
    (["plan", "{run}", "--target-mk", "2", "--antenna", "sky"], "name one with --antenna"),
    (["plan", "{run}", "--target-mk", "-1"], "--target-mk"),
    (["solve", "{run}", "-o", "{out}", "--contributions", "--method", "thesis"],
     "--method radiometric"),
    (["plan", "{run}", "--target-mk", "2", "--antenna-index", "-2.5"], "needs --antenna-k"),
])
def test_bad_requests_end_in_one_line_with_the_way_out(run, tmp_path, capsys, argv, says):
    argv = [a.format(run=run, out=tmp_path / "s.h5") for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert says in err
    assert "Traceback" not in err
    assert len([line for line in err.splitlines() if "error:" in line]) == 1


@pytest.mark.parametrize(("t0", "index", "seed"), [(2500.0, -2.5, 0), (298.0, 0.0, 1),
                                                   (4000.0, -2.8, 2)])
def test_the_antenna_s_power_law_is_fitted_to_its_calibrated_spectrum(t0, index, seed):
    """``T_0 (f/75 MHz)^beta`` back from a spectrum with 1 % noise per channel, 50-130 MHz."""
    freq = np.linspace(50e6, 130e6, 400)
    truth = t0 * (freq / 75e6) ** index
    noisy = truth * (1 + 0.01 * np.random.default_rng(seed).normal(size=freq.size))
    fitted_t0, fitted_index = power_law(freq, noisy, "ant")
    assert fitted_t0 == pytest.approx(t0, rel=0.003)  # 1 % / sqrt(400) and the slope's share
    assert fitted_index == pytest.approx(index, abs=0.01)


def test_plan_with_a_sky_antenna_says_so_and_leans_on_the_hot_load(run, capsys):
    argv = ["plan", str(run), "--target-mk", "50", "--antenna-k", "2500", "--antenna-index", "-2.5"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    rows = dict(re.findall(r"^  (\S+)\s+([\d.]+)$", out, re.M))
    assert max(rows, key=lambda name: float(rows[name])) == "hot", out
