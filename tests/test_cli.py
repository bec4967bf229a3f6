"""``reach-cal`` end to end, in process, and the installed console script."""

import re
import shutil
import subprocess

import h5py
import numpy as np
import pytest

from calibration.cli import main
from calibration.io.hdf5_io import read_run
from calibration.io.solution_file import read_solution
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ

WIDTH = str(16 * ITPM_CHANNEL_WIDTH_HZ)


@pytest.fixture
def run_file(tmp_path, capsys):
    path = tmp_path / "run.h5"
    assert main(["simulate", "-o", str(path), "--seed", "4", "--channel-width-hz", WIDTH]) == 0
    capsys.readouterr()
    return path


def _number(pattern: str, text: str) -> float:
    match = re.search(pattern, text)
    assert match, f"{pattern!r} not in:\n{text}"
    return float(match.group(1))


def test_simulate_solve_apply_summary(tmp_path, capsys):
    run, sol = tmp_path / "run.h5", tmp_path / "sol.h5"
    out, csv = tmp_path / "ant.h5", tmp_path / "ant.csv"
    assert main(["simulate", "-o", str(run), "--seed", "2", "--channel-width-hz", WIDTH]) == 0
    assert "wrote" in capsys.readouterr().out
    data, extra = read_run(run)
    assert len(data.names) == 12
    assert list(extra) == ["ant"]

    assert main(["solve", str(run), "-o", str(sol)]) == 0
    text = capsys.readouterr().out
    assert "orders (unc, cos, sin, NS, L): " in text
    assert "log evidence" in text
    assert "noise scale" in text
    assert re.search(r"in \d+\.\d+ s", text)
    solution = read_solution(sol)
    assert solution.method == "radiometric"
    assert len(solution.evidence_table) > 1  # chosen by evidence
    assert solution.metadata["run_file"] == str(run)

    assert main(["apply", str(sol), str(run), "-o", str(out), "--csv", str(csv)]) == 0
    text = capsys.readouterr().out
    assert "RMS std" in text
    assert "averaged models disagree" not in text  # twelve calibrators decide the model
    with h5py.File(out, "r") as f:
        assert f.attrs["source"] == "ant"
        np.testing.assert_array_equal(f["frequencies"][()], data.freq_hz)
        std, cal, meas = (f[k][()] for k in ("std", "std_calibration", "std_measurement"))
        np.testing.assert_allclose(std**2, cal**2 + meas**2, rtol=1e-12)
        choice = f["std_model_choice"][()]
        assert np.all(choice <= cal * (1 + 1e-9))
        share = np.sum(choice**2) / np.sum(cal**2)
        assert f.attrs["model_choice_share"] == pytest.approx(share, rel=1e-9, abs=1e-15)
        assert f.attrs["model_choice_share"] < 0.5
        mean = f["mean"][()]
        lo68, hi68, lo95, hi95 = (
            f[k][()] for k in ("lower_68", "upper_68", "lower_95", "upper_95")
        )
    assert np.all((lo95 < lo68) & (lo68 < mean) & (mean < hi68) & (hi68 < hi95))
    # A Gaussian's 68 % interval is 2 sd wide; a mixture over models' a little narrower.
    assert 1.6 < np.median((hi68 - lo68) / std) <= 2.0 + 1e-9
    table = np.loadtxt(csv, delimiter=",", skiprows=1)
    assert table.shape == (data.n_channels, 6)
    np.testing.assert_array_equal(table[:, 5], 0.0)  # no VNA systematic asked for
    np.testing.assert_allclose(table[:, 1], mean, rtol=1e-9)
    # The mock antenna is at the ambient 298 K; the calibration must recover it.
    assert abs(np.mean(mean) - 298.0) < 0.05

    assert main(["summary", str(sol), "--run", str(run), "--source", "ant"]) == 0
    text = capsys.readouterr().out
    orders = ",".join(map(str, solution.orders_used))
    assert f"model used, orders (unc, cos, sin, NS, L): {orders} (weight " in text
    for name in ("unc", "cos", "sin", "NS", "L"):
        assert re.search(rf"^\s+{name}: ", text, re.MULTILINE)
    ratio = _number(r"distance to floor: predicted ([\d.]+)", text)
    # At or below the radiometer noise floor: the Cramer-Rao bound is the unbiased
    # estimator's at the true orders, and the widths fitted at the chosen model shrink
    # below it (this run: predicted 0.63 of it, actual 0.57; the REACH-like ensemble's
    # median error 0.88 of it, docs/results.md, "Model choice").
    assert 0.5 < ratio < 1.3
    floor_mk = _number(r"noise floor RMS.*: ([\d.]+) mK", text)
    actual_mk = _number(r"actual calibration error RMS.*: ([\d.]+) mK", text)
    assert 0 < actual_mk < 2 * ratio * floor_mk  # within twice its predicted error


def test_apply_with_the_vna_accuracy_adds_its_systematic_error(run_file, tmp_path, capsys):
    """Table 2.3 read as 2 sigma, 24 draws: the spread over refits goes into the std, the
    HDF5 (with its draws) and the CSV; too few draws are refused."""
    sol, out, csv = tmp_path / "sol.h5", tmp_path / "ant.h5", tmp_path / "ant.csv"
    assert main(["solve", str(run_file), "-o", str(sol), "--orders", "3,3,3,3,3"]) == 0
    args = ["apply", str(sol), str(run_file), "-o", str(out), "--csv", str(csv)]
    assert main([*args, "--vna-accuracy", "24", "--vna-correlation-mhz", "10"]) == 0
    text = capsys.readouterr().out
    assert "VNA accuracy (table 2.3, bound = 2 sigma), correlated over 10 MHz, 24 draws" in text
    systematic_mk = _number(r"VNA systematic ([\d.]+) mK", text)
    with h5py.File(out, "r") as f:
        std, cal, meas, vna = (
            f[k][()] for k in ("std", "std_calibration", "std_measurement", "std_systematic")
        )
        assert f["systematic_draws"].shape == (24, std.size)
    np.testing.assert_allclose(std**2, cal**2 + meas**2 + vna**2, rtol=1e-12)
    # 0.4-4 dB on every reflection moves a calibrated load by kelvins, not millikelvins
    assert 100 < systematic_mk < 20_000
    np.testing.assert_allclose(np.loadtxt(csv, delimiter=",", skiprows=1)[:, 5], vna)
    assert main([*args, "--vna-accuracy", "1"]) == 2
    assert "at least 2 draws" in capsys.readouterr().err


def test_thesis_with_fixed_orders_and_subset(run_file, tmp_path, capsys):
    sol = tmp_path / "thesis.h5"
    calibrators = "hot,cold,r25,r100,c2r27,c2r69,c10open,c10short"
    args = [
        "solve",
        str(run_file),
        "-o",
        str(sol),
        "--method",
        "thesis",
        "--orders",
        "3,3,3,3,3",
        "--calibrators",
        calibrators,
    ]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "(fixed; 15 coefficients)" in text
    assert "noise sigma" in text
    solution = read_solution(sol)
    assert solution.method == "thesis"
    assert solution.orders == (3, 3, 3, 3, 3)
    assert solution.calibrators == tuple(calibrators.split(","))
    assert main(["summary", str(sol), "--run", str(run_file), "--top", "1"]) == 0
    text = capsys.readouterr().out
    assert "(8 calibrators)" in text
    assert "evidence table: 1 models" in text


def test_missing_run_file_is_an_error_without_traceback(tmp_path, capsys):
    missing = tmp_path / "nope.h5"
    assert main(["solve", str(missing), "-o", str(tmp_path / "sol.h5")]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("reach-cal: error: ")
    assert "nope.h5" in lines[0]
    assert "Traceback" not in captured.err
    assert not (tmp_path / "sol.h5").exists()


def test_operator_errors_exit_2(run_file, tmp_path, capsys):
    sol = tmp_path / "sol.h5"
    # files swapped: a run is not a solution
    assert main(["apply", str(run_file), str(run_file)]) == 2
    assert "expected 'reach-calibration-solution'" in capsys.readouterr().err
    # no such source in the run
    assert main(["solve", str(run_file), "-o", str(sol), "--orders", "3,3,3,3,3"]) == 0
    capsys.readouterr()
    assert main(["apply", str(sol), str(run_file), "--source", "moon"]) == 2
    assert "no source 'moon'" in capsys.readouterr().err
    # unknown calibrator for the simulation, and one the run does not have
    assert main(["simulate", "-o", str(tmp_path / "x.h5"), "--calibrators", "hot,sun"]) == 2
    assert "unknown calibrators ['sun']" in capsys.readouterr().err
    assert main(["solve", str(run_file), "-o", str(sol), "--calibrators", "hot,xyz"]) == 2
    assert "xyz" in capsys.readouterr().err
    # too few calibrators for the model: the engine's IllPosedError
    too_few = [
        "solve",
        str(run_file),
        "-o",
        str(sol),
        "--orders",
        "6,6,6,6,6",
        "--calibrators",
        "hot,cold",
    ]
    assert main(too_few) == 2
    assert capsys.readouterr().err.startswith("reach-cal: error: ")


def test_usage_errors_exit_2(tmp_path, capsys):
    assert main(["solve", "run.h5", "-o", "x.h5", "--orders", "1,2,3"]) == 2
    assert "5 comma-separated term counts" in capsys.readouterr().err
    assert main(["simulate", "-o", str(tmp_path / "absent" / "run.h5")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main([]) == 2
    assert main(["--help"]) == 0
    assert "simulate" in capsys.readouterr().out


def test_console_script_help():
    # The README's test command installs the package, console scripts included.
    exe = shutil.which("reach-cal")
    assert exe is not None, "reach-cal is not on PATH: install the package (pip install -e .)"
    result = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    for command in ("simulate", "solve", "apply", "summary"):
        assert command in result.stdout
