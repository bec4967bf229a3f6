"""The solver as an option wherever a calibration is made (issue 14, item 6).

``reach-cal solve / apply / summary / report / validate`` with every method of
:data:`calibration.solve.solvers.METHODS` on seeded simulated runs (REACH's band at 16 iTPM
channels per channel: 410 channels, so a solve takes at most a few tenths of a second);
per-channel solution files round-trip exactly; a bad solver in a schedule or a site file
is refused at its file and line; and a short simulated run through the real schedule path
with ``solver: bayesian`` stores, uses, summarises, reports and shows its per-channel
solution.
"""

import re
from pathlib import Path
from textwrap import dedent

import h5py
import numpy as np
import pytest
import yaml
from scipy import stats
from sites import DEVICES, planning_site

from calibration.cli import main as reach_cal
from calibration.core.errors import FileFormatError, InvalidDataError
from calibration.io.hdf5_io import read_run, read_truth
from calibration.io.solution_file import read_solution, write_solution
from calibration.model.noise_waves import design_terms, source_temperature
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run
from calibration.solve.per_frequency import ChannelSolution
from calibration.solve.solution import Solution
from calibration.solve.solvers import (
    METHODS,
    PER_CHANNEL_METHODS,
    POLYNOMIAL_METHODS,
    solution_noise_floor,
    solve,
)
from reach_receiver.cli import run_main
from reach_receiver.config.site import SiteError, load_site, parse_site
from reach_receiver.daemon.status_figures import current_solution
from reach_receiver.run import compile_text
from reach_receiver.schedule.compile import ScheduleError
from reach_receiver.store import read_run_file

WIDTH = str(16 * ITPM_CHANNEL_WIDTH_HZ)
SEEDS = (2, 3, 4)
#: Seven calibrators: least squares keeps 2 residual dof (Student-t errors with 2 dof).
SEVEN = "cold,hot,r25,r100,c10open,c10short,c2r69"
SCHEDULES = Path(__file__).resolve().parents[1] / "schedules"


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """One simulated run file (12 calibrators and ``ant``, with the truth) per seed."""
    directory = tmp_path_factory.mktemp("runs")
    files = {}
    for seed in SEEDS:
        files[seed] = directory / f"run{seed}.h5"
        args = ["simulate", "-o", str(files[seed]), "--seed", str(seed), "--channel-width-hz"]
        assert reach_cal([*args, WIDTH]) == 0
    return files


def solved_and_applied(
    tmp: Path, run: Path, method: str, calibrators: str | None
) -> tuple[np.ndarray, float]:
    """``reach-cal solve`` then ``apply`` on ``ant``: its error in stated std, and the dof."""
    sol, out = tmp / f"{method}.h5", tmp / f"{method}-ant.h5"
    subset = ["--calibrators", calibrators] if calibrators else []
    assert reach_cal(["solve", str(run), "-o", str(sol), "--method", method, *subset]) == 0
    assert reach_cal(["apply", str(sol), str(run), "-o", str(out)]) == 0
    with h5py.File(out, "r") as f:
        freq, mean, std = (f[k][()] for k in ("frequencies", "mean", "std_calibration"))
        dof = float(f.attrs["dof"])
    data, extra = read_run(run)
    ant, truth = extra["ant"], read_truth(run)
    assert truth is not None
    np.testing.assert_array_equal(freq, data.freq_hz)
    # The simulator's temperature of ant at the same measured Q: the error the calibration
    # adds, which std_calibration states.
    true_t = source_temperature(truth.theta(freq), design_terms(ant.gamma, data.gamma_rec), ant.q)
    return (mean - true_t) / std, dof


@pytest.mark.parametrize("calibrators", [None, SEVEN], ids=["12", "7"])
@pytest.mark.parametrize("method", PER_CHANNEL_METHODS)
def test_per_channel_methods_recover_the_truth_within_their_errors(
    runs, tmp_path, capsys, method, calibrators
):
    z, dofs = [], set()
    for seed, run in runs.items():
        (tmp_path / str(seed)).mkdir()
        zs, dof = solved_and_applied(tmp_path / str(seed), run, method, calibrators)
        z.append(zs)
        dofs.add(dof)
    capsys.readouterr()
    pooled = np.concatenate(z)  # 3 x 410 channels, independent: no shared smooth error
    (dof,) = dofs
    m = 12 if calibrators is None else 7
    assert dof == (m - 5 if method == "least-squares" else np.inf)
    # Inside the stated 68 % interval (Student-t with the stated dof): 0.68 expected, the
    # binomial sd over 1230 channels is 0.013, so +-0.05 is ~4 sd.
    half = stats.norm.ppf(0.84) if np.isinf(dof) else stats.t.ppf(0.84, dof)
    inside = float(np.mean(np.abs(pooled) <= half))
    assert 0.63 <= inside <= 0.73, inside
    # Unbiased: the median error within 0.1 std (its sd over 1230 channels is ~0.04).
    assert abs(float(np.median(pooled))) < 0.1


@pytest.mark.parametrize("calibrators", [None, SEVEN], ids=["12", "7"])
@pytest.mark.parametrize("method", POLYNOMIAL_METHODS)
def test_polynomial_methods_recover_the_truth_within_their_errors(
    runs, tmp_path, capsys, method, calibrators
):
    rms = []
    for seed, run in runs.items():
        (tmp_path / str(seed)).mkdir()
        z, _ = solved_and_applied(tmp_path / str(seed), run, method, calibrators)
        rms.append(float(np.sqrt(np.mean(z**2))))
    capsys.readouterr()
    # A polynomial solution's error is smooth, one draw of a few tens of coefficients per
    # run, so the channels are not independent: each run's RMS error in stated std is
    # below 2 (a 2-sigma excursion over the whole band; 0.2-1.2 seen over 12 seeds and
    # both sets), and over the seeds neither far below 1 (errors overstated) nor above.
    assert max(rms) < 2.0, rms
    assert 0.3 < float(np.sqrt(np.mean(np.square(rms)))) < 1.5, rms


def test_per_channel_summary_report_validate_and_refusals(runs, tmp_path, capsys):
    run = runs[SEEDS[0]]
    sol = tmp_path / "bayes.h5"
    assert reach_cal(["solve", str(run), "-o", str(sol), "--method", "bayesian"]) == 0
    text = capsys.readouterr().out
    assert "(bayesian, 12 calibrators, 410 channels)" in text
    assert "log evidence (sum over channels" in text
    assert "NC346A" in text or "noise source" in text  # T_NS against the diode's ENR table
    solution = read_solution(sol)
    assert isinstance(solution, ChannelSolution)
    assert solution.metadata["run_file"] == str(run)

    assert reach_cal(["summary", str(sol), "--run", str(run)]) == 0
    text = capsys.readouterr().out
    assert "bayesian solver, per channel on 50.000-129.883 MHz" in text
    assert "calibrators (12): cold, hot" in text
    for name in ("unc", "cos", "sin", "NS", "L"):
        assert f"  {name:>3}: " in text
        assert " +- " in text
    assert "per channel model" in text
    ratio = float(text.split("distance to floor: predicted ")[1].split(",")[0].split()[0])
    assert 0.7 < ratio < 1.3  # the Bayesian posterior at its own (per-channel) floor
    assert "actual calibration error RMS" in text

    report = tmp_path / "report"  # the run's figures: the run test's report draws them
    assert reach_cal(["report", str(sol), "-o", str(report)]) == 0
    assert {p.stem for p in report.glob("*.png")} == {"parameters"}  # no evidence figure
    summary = (report / "summary.md").read_text()
    assert "| evidence figure | not drawn: a per-channel solution" in summary
    assert "| method | bayesian (per channel) |" in summary

    validated = tmp_path / "loo.json"
    args = ["validate", str(run), "--leave-one-out", "--method", "least-squares"]
    assert reach_cal([*args, "-o", str(validated)]) == 0
    assert '"method": "least-squares"' in validated.read_text()
    capsys.readouterr()

    args = ["solve", str(run), "-o", str(tmp_path / "x.h5"), "--method", "bayesian"]
    assert reach_cal([*args, "--check-consistency"]) == 0
    assert "calibrator consistency" in capsys.readouterr().out
    for extra, word in ((["--orders", "3,3,3,3,3"], "orders"), (["--basis", "power"], "basis")):
        assert reach_cal([*args, *extra]) == 2
        err = capsys.readouterr().err
        assert "solves each channel on its own" in err
        assert word in err
    four = ["--method", "bayesian", "--calibrators", "cold,hot,r25,r100"]
    assert reach_cal(["solve", str(run), "-o", str(tmp_path / "y.h5"), *four]) == 2
    assert "at least 5 calibrators" in capsys.readouterr().err


def test_orders_with_a_per_channel_solver_are_an_invalid_data_error():
    run = simulate_run(SimulationConfig(channel_width_hz=64 * ITPM_CHANNEL_WIDTH_HZ), rng=1)
    with pytest.raises(InvalidDataError, match="apply only to the polynomial solvers"):
        solve(run.data, "bayesian", basis_kind="legendre")
    with pytest.raises(InvalidDataError, match="unknown solver 'bayes'"):
        solve(run.data, "bayes")
    assert METHODS[0] == "radiometric"


@pytest.mark.parametrize("seed", [5, 6])
def test_per_channel_solution_files_round_trip_exactly(tmp_path, seed):
    run = simulate_run(SimulationConfig(channel_width_hz=64 * ITPM_CHANNEL_WIDTH_HZ), rng=seed)
    five = run.data.subset(run.data.names[:5])  # least squares with no residual: inf errors
    for data, method in ((run.data, "bayesian"), (five, "least-squares"), (run.data, "thesis")):
        solution = solve(data, method)
        solution = type(solution)(**{**vars(solution), "metadata": {"run_file": "r.h5", "n": 3}})
        path = tmp_path / f"{method}.h5"
        write_solution(path, solution)
        again = read_solution(path)
        assert type(again) is type(solution)
        assert again.method == solution.method
        assert again.calibrators == solution.calibrators
        assert dict(again.metadata) == dict(solution.metadata)
        if isinstance(solution, ChannelSolution):
            assert isinstance(again, ChannelSolution)
            for name in ("freq_hz", "mean", "covariance"):
                np.testing.assert_array_equal(getattr(again, name), getattr(solution, name))
            if solution.log_evidence is None:
                assert again.log_evidence is None
                assert np.all(np.isinf(np.diagonal(again.covariance, axis1=1, axis2=2)))
            else:
                np.testing.assert_array_equal(again.log_evidence, solution.log_evidence)
            means = solution.summary()["band_mean_k"]
            assert again.summary()["band_mean_k"] == pytest.approx(means)
            with h5py.File(path, "r") as f:
                assert f.attrs["solution_kind"] == "per-channel"
                units = {k: f["channels"][k].attrs["units"] for k in f["channels"]}
            assert units["frequencies"] == "Hz"
            assert units["covariance"] == "K^2"
        else:
            np.testing.assert_array_equal(again.posterior.mean, solution.posterior.mean)


def test_solution_files_without_a_kind_still_read_and_an_unknown_kind_is_refused(tmp_path):
    run = simulate_run(SimulationConfig(channel_width_hz=64 * ITPM_CHANNEL_WIDTH_HZ), rng=7)
    path = tmp_path / "old.h5"
    write_solution(path, solve(run.data, "thesis"))
    with h5py.File(path, "r+") as f:
        del f.attrs["solution_kind"]  # as every file before the per-channel solvers
    assert isinstance(read_solution(path), Solution)
    with h5py.File(path, "r+") as f:
        f.attrs["solution_kind"] = "spline"
    with pytest.raises(FileFormatError, match="unknown solution_kind 'spline'"):
        read_solution(path)


def test_channel_floor_is_the_bayesian_posteriors_size():
    run = simulate_run(SimulationConfig(channel_width_hz=64 * ITPM_CHANNEL_WIDTH_HZ), rng=8)
    data = run.data
    bayes = solve(data, "bayesian")
    floor = solution_noise_floor(bayes, data, run.validation, run.truth.theta(data.freq_hz))
    spectrum = bayes.calibrate(data.freq_hz, data.gamma_rec, run.validation)
    # At the truth with radiometer noise only, the posterior's std is the Cramer-Rao bound
    # up to the linearisation point (the posterior mean, not the truth): within 5 %.
    np.testing.assert_allclose(spectrum.std_calibration, floor.std, rtol=0.05)
    polynomial = solution_noise_floor(solve(data, "radiometric"), data, run.validation)
    assert floor.rms > 3 * polynomial.rms  # each channel learnt from that channel alone


@pytest.mark.parametrize("seed", [8, 9, 10])
def test_an_averaged_solutions_floor_is_that_of_the_model_it_uses(seed):
    """The floor counts the terms of the model used, not the envelope of those averaged."""
    from calibration.solve.noise_floor import noise_floor

    run = simulate_run(SimulationConfig(channel_width_hz=64 * ITPM_CHANNEL_WIDTH_HZ), rng=seed)
    data = run.data
    solution = solve(data, "radiometric")
    assert solution.metadata.get("averaged")
    used, envelope = solution.orders_used, solution.orders
    assert used != envelope
    assert all(n <= m for n, m in zip(used, envelope, strict=True))
    floor = solution_noise_floor(solution, data, run.validation)
    at_used = noise_floor(data, run.validation, solution.parameters.truncated(used))
    np.testing.assert_allclose(floor.std, at_used.std)
    # Fewer coefficients, less to learn: the envelope's floor is the higher, so the old
    # distance to it (predicted / floor) read low.
    assert floor.rms < noise_floor(data, run.validation, solution.parameters).rms


# --------------------------------------------------------------------------- schedules, sites
BAD_STEP = """\
schedule: s
steps:
  - initialise
  - calibrate: {solver: bayes}
"""


def test_a_bad_solver_in_a_schedule_is_refused_at_its_line():
    with pytest.raises(ScheduleError) as caught:
        compile_text(BAD_STEP, "night.yaml", site=planning_site())
    (problem,) = [p for p in caught.value.problems if p.key == "calibrate.solver"]
    assert (problem.file, problem.line) == ("night.yaml", 4)
    assert "must be one of radiometric, thesis, least-squares, bayesian" in problem.message
    assert "did you mean 'bayesian'?" in problem.message
    text = BAD_STEP.replace("bayes}", "least-squares}")
    good = compile_text(text, "n.yaml", site=planning_site())
    assert good.steps[-1].solver == "least-squares"


def test_too_few_vna_accuracy_draws_are_refused_at_their_line():
    text = BAD_STEP.replace("{solver: bayes}", "{vna_accuracy: 1}")
    with pytest.raises(ScheduleError) as caught:
        compile_text(text, "night.yaml", site=planning_site())
    (problem,) = caught.value.problems
    assert (problem.file, problem.line, problem.key) == ("night.yaml", 4, "calibrate.vna_accuracy")
    assert "at least 2 draws" in problem.message
    good = compile_text(text.replace(": 1}", ": 16}"), "n.yaml", site=planning_site())
    assert good.steps[-1].vna_accuracy == 16


def test_the_site_files_solver_is_read_written_back_and_refused_at_its_line(tmp_path):
    site = planning_site(solver="bayesian")
    assert parse_site(yaml.safe_load(site.to_yaml())).solver == "bayesian"
    assert "solver" not in planning_site().to_yaml()  # the default is not written
    path = tmp_path / "site.yaml"
    document = {"devices": DEVICES, "calibration": {"band_hz": [50e6, 130e6], "solver": "ls"}}
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    with pytest.raises(SiteError) as err:
        load_site(path)
    lines = path.read_text().splitlines()
    line = next(i for i, text in enumerate(lines, 1) if "solver" in text)
    assert f"{path}:{line}: calibration.solver: must be one of radiometric" in str(err.value)


# --------------------------------------------------------------------------- a run, per channel
PER_CHANNEL_RUN = """\
schedule: per-channel
include: [{common}]
vars: {{cal: [cold, hot, c10open, c10short, r25, r100, c2r27, c2r69]}}
steps:
  - initialise: {{}}
  - temperatures: {{period_s: 10}}
  - vna_calibrate: {{}}
  - s11: {{targets: '${{cal}}'}}
  - s11: {{targets: [ant, lna]}}
  - dicke: {{sources: '${{cal}}', seconds: 60}}
  - dicke: {{sources: [ant], seconds: 60}}
  - calibrate: {{solver: bayesian, f_lo_hz: 60.0e+6, f_hi_hz: 75.0e+6, vna_accuracy: 8}}
  - observe: {{cycles: 1, seconds: 60}}
  - safe: {{}}
"""


def test_a_run_with_a_per_channel_solver_stores_uses_reports_and_shows_it(tmp_path, capsys):
    schedule = tmp_path / "per_channel.yaml"
    schedule.write_text(dedent(PER_CHANNEL_RUN.format(common=SCHEDULES / "common.yaml")))
    out = tmp_path / "runs"
    assert run_main([str(schedule), "--sim", "--seed", "3", "--out", str(out), "-q"]) == 0
    text = capsys.readouterr().out
    assert "solution: bayesian, per channel (" in text
    assert "log evidence (sum over channels, eq. 4.22)" in text
    # The antenna's actual error against the simulator's truth, each channel in units of
    # its own floor: over the 1228 channels whose floor is within 10x the median, so their
    # RMS is 1 to ~2 % (0.95-1.01 seen over 12 runs idle, 0.94-1.05 over 60 with two runs
    # at once beside a two-core numpy load; CI once 1.103, so the whole output, with its
    # largest channel, is shown on failure). The one channel
    # beyond took this RMS to 1.17 once in CI. The ratio of the two RMS values on the line
    # above it is not held either:
    # at 62.2 MHz the eight calibrators' reflections line up, that channel's floor is
    # hundreds of times the median, and that one channel made the ratio anything from 0.16
    # to 0.93 between runs (the iTPM simulator's skips under load change the noise drawn).
    assert "actual calibration error against the simulator's truth: " in text
    normalised = float(text.split("per channel: RMS of error / floor ")[1].split(" ")[0])
    assert 0.9 < normalised < 1.1, text
    # The largest channel's ratio and frequency are printed (a diagnosis, not a bound).
    assert re.search(r"over 1228 channels \(largest \d+\.\d\d at \d+\.\d{3} MHz\)", text), text
    # The VNA's data-sheet error on the antenna, 8 refits: tens of kelvins for a per-channel
    # solve from 8 calibrators (median 42-43 K seen, RMS 45-48 K), where the floor is
    # tenths. The median, not the RMS: the degenerate channel above once took the RMS over
    # the band to 255 K in CI.
    line = text.split("VNA systematic on 'ant': ")[1]
    median = float(line.split("median ")[1].split(" mK")[0])
    assert 1_000 < median < 200_000, median
    assert "correlated over 5 MHz, 8 draws" in text
    (directory,) = [p for p in out.iterdir() if p.is_dir()]
    contents = read_run_file(directory / "run.h5")
    solution = contents.solution()
    assert isinstance(solution, ChannelSolution)
    assert solution.method == "bayesian"
    assert solution.band_hz[0] >= 60e6
    assert solution.band_hz[1] <= 75e6
    assert len(solution.calibrators) >= 5
    # The observe step calibrated the antenna's cycle with it, over its channels.
    (calibrated,) = contents.of_kind("calibrated")
    arrays = contents.read(calibrated)
    np.testing.assert_array_equal(arrays["frequencies"], solution.freq_hz)
    assert np.all(np.isfinite(arrays["mean"]))
    assert np.all(arrays["std"] > 0)
    # The run's report, drawn by the session: no evidence figure, and the summary says so.
    report = directory / "report"
    stems = {p.stem for p in report.glob("*.png")}
    assert {"parameters", "sources", "dicke"} <= stems
    assert "evidence" not in stems
    assert "not drawn: a per-channel solution" in (report / "summary.md").read_text()
    # The status page's figure of the current solution.
    figure = current_solution(out)
    assert "per channel" in figure.get_suptitle()
    assert len(figure.axes) == 10
