"""reach-cal's inputs: no output over an input or measurements, unsound files and options refused.

Every case runs the ``reach-cal`` command line (:func:`calibration.cli.main`) on a small
simulated run and its solution, and checks the exit status, the one-line message and that
every input is byte for byte as it was.
"""

import argparse
import hashlib
import os
import shutil

import h5py
import numpy as np
import pytest

from calibration.cli import main
from calibration.cli.args import number_arg
from calibration.cli.files import check_outputs
from calibration.core.errors import InvalidDataError
from calibration.io.solution_file import read_solution

CALIBRATORS = "cold,hot,r25,r100,c10open,c10short"


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A run of six calibrators on 41 channels of 2 MHz, and its solution."""
    d = tmp_path_factory.mktemp("engine")
    run, sol = str(d / "run.h5"), str(d / "sol.h5")
    assert main(["simulate", "-o", run, "--channel-width-hz", "2e6", "--calibrators",
                 CALIBRATORS]) == 0
    assert main(["solve", run, "-o", sol, "--max-orders", "5,5,5,5,5"]) == 0
    return d


@pytest.fixture
def work(base, tmp_path, monkeypatch):
    """A copy of the run and solution, as the working directory."""
    for name in ("run.h5", "sol.h5"):
        shutil.copy(base / name, tmp_path / name)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def refused(argv, capsys, says):
    """Run ``reach-cal argv``: exit 2, one message holding ``says``, no traceback."""
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    assert says.lower() in err.strip().splitlines()[-1].lower(), err
    return err


def measured(work, name):
    """A copy of the run without its simulation truth: measurements nobody can remake."""
    shutil.copy(work / "run.h5", work / name)
    with h5py.File(work / name, "r+") as f:
        del f["simulation_truth"]
    return work / name


# ------------------------------------------------------------------ outputs
@pytest.mark.parametrize("spelling", ["run.h5", "./run.h5", "link.h5", "hard.h5"])
def test_solve_refuses_to_write_its_solution_over_its_run(work, capsys, spelling):
    os.symlink("run.h5", work / "link.h5")
    os.link(work / "run.h5", work / "hard.h5")
    before = digest(work / "run.h5")
    refused(["solve", "run.h5", "-o", spelling], capsys, "input")
    assert digest(work / "run.h5") == before
    assert (work / "link.h5").is_symlink()


@pytest.mark.parametrize(
    "argv",
    [
        ["solve", "run.h5", "-o", "m.h5"],
        ["apply", "sol.h5", "run.h5", "-o", "m.h5"],
        ["apply", "sol.h5", "run.h5", "--csv", "m.h5"],
        ["simulate", "-o", "m.h5"],
        ["validate", "run.h5", "--leave-one-out", "-o", "m.csv"],
        ["import", "edges", ".", "-o", "m.h5", "--temperatures", "amb=300"],
    ],
    ids=lambda argv: " ".join(argv[:2]),
)
def test_no_command_writes_over_a_measured_run(work, capsys, argv):
    target = measured(work, next(a for a in argv if a.startswith("m.")))
    before = digest(target)
    refused(argv, capsys, "measurements")
    assert digest(target) == before


@pytest.mark.parametrize("fmt", ["reach-receiver-run", "reach-receiver-part"])
def test_the_receivers_run_files_and_parts_are_measurements_too(work, capsys, fmt):
    target = measured(work, "m.h5")
    with h5py.File(target, "r+") as f:
        f.attrs["format"] = fmt
    refused(["solve", "run.h5", "-o", "m.h5"], capsys, "measurements")


def test_a_solution_replaces_a_solution_and_a_simulation_a_simulation(work, capsys):
    assert main(["solve", "run.h5", "-o", "sol.h5", "--orders", "4,3,4,4,3"]) == 0
    shutil.copy(work / "run.h5", work / "sim.h5")
    assert main(["simulate", "-o", "sim.h5", "--channel-width-hz", "4e6", "--calibrators",
                 CALIBRATORS]) == 0
    assert main(["apply", "sol.h5", "run.h5", "-o", "out.h5", "--csv", "out.csv"]) == 0
    assert main(["apply", "sol.h5", "run.h5", "-o", "out.h5", "--csv", "out.csv"]) == 0


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["apply", "sol.h5", "run.h5", "-o", "sol.h5"], "input"),
        (["apply", "sol.h5", "run.h5", "--csv", "run.h5"], "input"),
        (["apply", "sol.h5", "run.h5", "-o", "x.h5", "--csv", "x.h5"], "same file"),
        (["solve", "run.h5", "-o", "notes.txt"], "not an HDF5"),
        (["solve", "run.h5", "-o", "d"], "directory"),
        (["report", "sol.h5", "--run", "run.h5", "-o", "run.h5"], "input"),
        (["import", "vna", "d", "-o", "d", "--devices", "lna"], "input"),
    ],
)
def test_other_outputs_over_inputs_or_foreign_files_are_refused(work, capsys, argv, says):
    (work / "notes.txt").write_text("field notes\n")
    (work / "d").mkdir()
    before = {p.name: digest(p) for p in work.iterdir() if p.is_file()}
    refused(argv, capsys, says)
    assert {p.name: digest(p) for p in work.iterdir() if p.is_file()} == before


# ------------------------------------------------------------------ files read
def change(path, name, value=None, attr=None):
    """Replace dataset ``name`` by ``value(old)`` (keeping its attributes), or set ``attr``."""
    with h5py.File(path, "r+") as f:
        if attr is not None:
            f[name].attrs[attr[0]] = attr[1]
            return
        old, attrs = f[name][()], dict(f[name].attrs)
        del f[name]
        f.create_dataset(name, data=value(old)).attrs.update(attrs)


def nan(v):
    return np.full_like(v, np.nan)


@pytest.mark.parametrize(
    ("name", "value", "attr", "says"),
    [
        ("posterior/mean", nan, None, "mean is not finite"),
        ("posterior/scale", lambda v: v + np.inf, None, "scale is not finite"),
        ("posterior/scale", lambda v: -np.abs(v), None, "covariance"),
        ("posterior", None, ("noise_variance", float("nan")), "noise_variance"),
        ("posterior", None, ("dof", -1.0), "dof"),
        ("posterior", None, ("n_rows", "many"), "n_rows"),
        ("posterior/orders", lambda v: -v, None, "orders"),
        ("posterior/orders", lambda v: v * 0 + 10**6, None, "orders"),
        ("evidence/orders", lambda v: -v, None, "orders"),
        ("evidence/log_evidence", nan, None, "evidence"),
        ("/", None, ("metadata", '{"best_orders": [-1, 2, 3, 4, 5]}'), "best_orders"),
        ("/", None, ("metadata", '{"averaged": true, "model_weights": [7]}'), "model_weights"),
    ],
)
def test_an_unsound_solution_file_is_refused_by_name(work, capsys, name, value, attr, says):
    change(work / "sol.h5", name, value, attr)
    refused(["apply", "sol.h5", "run.h5"], capsys, says)
    refused(["summary", "sol.h5"], capsys, says)


def test_a_run_on_another_channel_grid_is_not_calibrated(work, capsys):
    for group in ("observation_data", "observation_metadata/temperatures"):
        with h5py.File(work / "run.h5", "r") as f:
            names = list(f[group])
        for name in names:
            change(work / "run.h5", f"{group}/{name}", lambda v: v[..., ::4])
    change(work / "run.h5", "observation_metadata", attr=("channel_width_hz", 8e6))
    refused(["apply", "sol.h5", "run.h5"], capsys, "8e+06 Hz wide")
    refused(["summary", "sol.h5", "--run", "run.h5"], capsys, "2e+06 Hz channels")


def test_a_run_offset_from_the_solutions_grid_is_not_calibrated(work, capsys):
    change(work / "sol.h5", "basis", attr=("f_lo_hz", 49e6))
    change(work / "sol.h5", "basis", attr=("f_hi_hz", 131e6))
    change(work / "run.h5", "observation_data/frequencies", lambda v: v + 0.3e6)
    refused(["apply", "sol.h5", "run.h5"], capsys, "grid")


def test_solve_records_the_channel_grid_it_solved(work):
    metadata = read_solution(work / "sol.h5").metadata
    assert metadata["channel_width_hz"] == 2e6
    assert metadata["grid_origin_hz"] == 50e6


@pytest.mark.parametrize(
    ("name", "attr", "says"),
    [
        ("observation_metadata", ("channel_width_hz", "wide"), "channel_width_hz"),
        ("observation_data/hot_spectra", ("integration_s_load", "long"), "integration_s_load"),
        ("observation_metadata/temperatures/hot", ("std_k", "warm"), "std_k"),
    ],
)
def test_a_run_attribute_that_is_not_a_number_is_named(work, capsys, name, attr, says):
    change(work / "run.h5", name, attr=attr)
    refused(["solve", "run.h5", "-o", "out.h5"], capsys, says)


# ------------------------------------------------------------------ options
@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["solve", "run.h5", "-o", "o.h5", "--orders", "99,99,99,99,99"], "0-16"),
        (["solve", "run.h5", "-o", "o.h5", "--max-orders", "17,2,2,2,2"], "0-16"),
        (["solve", "run.h5", "-o", "o.h5", "--band", "50,inf"], "--band"),
        (["solve", "run.h5", "-o", "o.h5", "--smooth-s11", "0"], "--smooth-s11"),
        (["solve", "run.h5", "-o", "o.h5", "--exclude-inconsistent", "0"], "--exclude"),
        (["summary", "sol.h5", "--top", "-5"], "--top"),
        (["summary", "sol.h5", "--top", "0"], "--top"),
        (["simulate", "-o", "n.h5", "--channel-width-hz", "-1"], "--channel-width-hz"),
        (["simulate", "-o", "n.h5", "--channel-width-hz", "nan"], "--channel-width-hz"),
        (["simulate", "-o", "n.h5", "--channel-width-hz", "1e-3"], "65536"),
        (["simulate", "-o", "n.h5", "--integration-s", "0"], "--integration-s"),
        (["simulate", "-o", "n.h5", "--band", "-10", "50"], "--band"),
        (["simulate", "-o", "n.h5", "--vna-sigma", "-1"], "--vna-sigma"),
        (["simulate", "-o", "n.h5", "--seed", "-1"], "--seed"),
        (["apply", "sol.h5", "run.h5", "--vna-accuracy", "1"], "--vna-accuracy"),
        (["apply", "sol.h5", "run.h5", "--vna-accuracy", "10000000"], "--vna-accuracy"),
        (["apply", "sol.h5", "run.h5", "--vna-correlation-mhz", "0"], "--vna-correlation"),
        (["apply", "sol.h5", "run.h5", "--seed", "-2"], "--seed"),
        (["import", "edges", "d", "-o", "n.h5", "--temperatures", "amb=-5"], "kelvin"),
        (["import", "edges", "d", "-o", "n.h5", "--temperatures", "amb=300",
          "--integration-s", "-1"], "--integration-s"),
    ],
)
def test_every_numeric_option_is_range_checked_before_any_work(work, capsys, argv, says):
    refused(argv, capsys, says)
    assert not (work / "n.h5").exists()
    assert not (work / "o.h5").exists()


def test_number_arg_takes_finite_numbers_in_range_only():
    positive = number_arg(float, 0.0, open_low=True)
    assert positive("2.5") == 2.5
    small = number_arg(int, 1, 10)
    assert small("10") == 10
    for parse, text in [(positive, "0"), (positive, "nan"), (positive, "inf"),
                        (positive, "x"), (small, "11"), (small, "2.5"), (small, "0")]:
        with pytest.raises(argparse.ArgumentTypeError, match=repr(text)):
            parse(text)


def test_a_run_is_replaced_only_by_the_command_that_makes_it_again(work, capsys):
    (work / "lab").mkdir()
    imported = measured(work, "imported.h5")
    with h5py.File(imported, "r+") as f:
        f.attrs["imported_from"] = str(work / "lab")
    assert check_outputs({"-o": ("imported.h5", "run")}, [], remakes="lab") is None
    for remakes in ("simulation", "elsewhere", None):
        with pytest.raises(InvalidDataError, match="holds measurements"):
            check_outputs({"-o": ("imported.h5", "run")}, [], remakes=remakes)
    assert check_outputs({"-o": ("run.h5", "run")}, [], remakes="simulation") is None
    with pytest.raises(InvalidDataError, match="holds measurements"):
        check_outputs({"-o": ("run.h5", "run")}, [], remakes="lab")


def test_limits_too_small_for_the_data_are_honoured_and_said(work, capsys):
    """--max-orders is a hard limit; where it leaves the fit s^2 >> 1 the solve says so."""
    assert main(["solve", "run.h5", "-o", "small.h5", "--max-orders", "2,2,2,2,2"]) == 0
    out = capsys.readouterr().out
    assert "warning: noise scale s^2 = " in out
    assert "ended at the order limit [2, 2, 2, 2, 2]" in out
