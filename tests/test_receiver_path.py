"""The receiver's path to the calibrators' plane, and EDGES-3's raw VNA readings (day 2022-319).

The raw readings (``../shared/data/edges3-2022-319-vna``, a real VNA's files) corrected with
EDGES' kit must reproduce the pipeline's corrected reflections (``../edges3-2022-316``:
``s11amb.csv`` ... ``s11ant.csv`` to 1e-7, the receiver's ``s11.csv`` to 1e-8), and the
receiver's path (EDGES' ``corrcsv`` line) must turn ``s11.csv`` into ``s11lna.csv``. A
receiver read with standards of its own and no path given is refused, naming the options.
"""

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from calibration.cli import main
from calibration.core.errors import InvalidDataError
from calibration.io import edges_text as et
from calibration.io.hdf5_io import read_run
from calibration.io.receiver_path import (
    EDGES3_RECEIVER_CABLE,
    ReceiverCable,
    read_measured_path,
)
from calibration.io.vna_import import (
    KIT_EXAMPLE,
    VnaLayout,
    check_receiver_plane,
    correct_exports,
    read_cal_kit,
)
from calibration.rf.touchstone import TouchstoneData, read_touchstone, write_touchstone_network

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
VNA, RUN = SHARED / "edges3-2022-319-vna", SHARED / "edges3-2022-316"
needs_data = pytest.mark.skipif(
    not (VNA.is_dir() and RUN.is_dir()),
    reason=f"the shared EDGES-3 data sets are not beside this checkout (looked in {SHARED})",
)
PREFIX = "2022_319_14_"
LOADS = ("amb", "hot", "open", "short", "ant")
CALIBRATORS_STANDARDS = {s: f"{PREFIX}{s[0].upper()}.s1p" for s in ("short", "open", "load")}
RECEIVER_STANDARDS = {s: f"{PREFIX}lna_{s[0].upper()}.s1p" for s in ("short", "open", "load")}
EDGES3_LAYOUT = VnaLayout(
    device=PREFIX + "{name}.s1p",
    standards=CALIBRATORS_STANDARDS,
    per_device={"lna": RECEIVER_STANDARDS},
)
#: the data set's README: the pipeline reproduces the loads to better than 1e-7 and the
#: receiver reading to about 1e-8 (what the CSVs' printed digits allow)
LOADS_TOL, RECEIVER_TOL = 1e-7, 1e-8
#: the brief: the receiver with its path within 1e-3 (its reading alone is 0.06 off)
PATH_TOL = 1e-3


def kit(tmp_path):
    path = tmp_path / "kit.json"
    path.write_text(KIT_EXAMPLE)
    return read_cal_kit(path)


@needs_data
def test_raw_readings_reproduce_the_pipelines_reflections(tmp_path):
    corrected = correct_exports(VNA, (*LOADS, "lna"), EDGES3_LAYOUT, kit(tmp_path))
    for name in LOADS:
        f, g = corrected[name]
        f_csv, g_csv = et.read_s11_csv(RUN / f"s11{name}.csv")
        np.testing.assert_allclose(f, f_csv, rtol=0, atol=1.0)
        assert np.max(np.abs(g - g_csv)) < LOADS_TOL, name
    f, g = corrected["lna"]
    _, reading = et.read_s11_csv(RUN / "s11.csv")
    assert np.max(np.abs(g - reading)) < RECEIVER_TOL
    _, receiver = et.read_s11_csv(RUN / "s11lna.csv")
    assert np.max(np.abs(g - receiver)) > 0.05  # the reading alone is not the receiver's S11
    assert np.max(np.abs(EDGES3_RECEIVER_CABLE.apply(f, g) - receiver)) < PATH_TOL


@needs_data
def test_the_receiver_path_as_a_two_port_file(tmp_path):
    """The same path given as a measured .s2p on a coarser grid (interpolated)."""
    corrected = correct_exports(VNA, ("lna",), EDGES3_LAYOUT, kit(tmp_path))
    f, g = corrected["lna"]
    grid = np.linspace(39e6, 201e6, 400)
    s = EDGES3_RECEIVER_CABLE.line().s_parameters(grid)
    write_touchstone_network(tmp_path / "path.s2p", TouchstoneData(grid, s))
    _, receiver = et.read_s11_csv(RUN / "s11lna.csv")
    moved = read_measured_path(tmp_path / "path.s2p").apply(f, g)
    assert np.max(np.abs(moved - receiver)) < PATH_TOL
    with pytest.raises(InvalidDataError, match="outside the file's"):
        read_measured_path(tmp_path / "path.s2p").apply(np.array([30e6, 50e6]), g[:2])


def test_cable_added_then_removed_is_the_identity():
    """Over random lines and reflections: (4.6) undoes (4.7), and the line is passive."""
    rng = np.random.default_rng(392)
    f = np.linspace(40e6, 200e6, 81)
    for _ in range(20):
        length = rng.uniform(0.01, 2.0)
        cable = ReceiverCable(length, rng.uniform(-10, 10), rng.uniform(-95, 50))
        gamma = 0.9 * rng.random(f.size) * np.exp(2j * np.pi * rng.random(f.size))
        undo = ReceiverCable(-length, cable.eps_pct, cable.sigma_pct)
        back = undo.apply(f, cable.apply(f, gamma))
        np.testing.assert_allclose(back, gamma, rtol=0, atol=1e-12)
        s = cable.line().s_parameters(f)
        assert np.all(np.linalg.norm(s, ord=2, axis=(1, 2)) <= 1 + 1e-12)
    with pytest.raises(InvalidDataError, match="length_m != 0"):
        ReceiverCable(0.0)


def test_receiver_with_its_own_standards_needs_its_path():
    with pytest.raises(InvalidDataError) as err:
        check_receiver_plane(EDGES3_LAYOUT, "lna", path_given=False)
    lines = str(err.value).splitlines()
    assert len(lines) <= 2
    assert "--receiver-cable" in lines[-1]
    assert "--receiver-path" in lines[-1]
    assert RECEIVER_STANDARDS["short"] in lines[0]
    check_receiver_plane(EDGES3_LAYOUT, "lna", path_given=True)
    check_receiver_plane(EDGES3_LAYOUT, "lna", path_given=False, planes_coincide=True)
    check_receiver_plane(EDGES3_LAYOUT, "amb", path_given=False)  # the loads' own plane
    check_receiver_plane(VnaLayout(), "lna", path_given=False)


def test_kit_file_names_what_is_missing_or_unknown(tmp_path):
    path = tmp_path / "kit.json"
    for text, message in (
        ("{}", r"kit.json: no 'short' standard"),
        ('{"short": {}, "open": {}}', r"kit.json: no 'load' standard"),
        ('{"short": {}, "open": {}, "load": {}, "lod": {}}', r"unknown keys lod"),
    ):
        path.write_text(text)
        with pytest.raises(Exception, match=message) as err:
            read_cal_kit(path)
        assert len(str(err.value).splitlines()) == 1
    path.write_text(json.dumps({"short": {}, "open": {}, "load": {}}))
    ideal = read_cal_kit(path).reflections(np.array([1e8]))
    np.testing.assert_array_equal(ideal[:, 0], [-1, 1, 0])


# --- the command line: reach-cal import edges --vna / import vna on the real readings ---

VNA_ARGS = [
    "--vna", str(VNA), "--device", PREFIX + "{name}.s1p",
    "--standards", ",".join(f"{k}={v}" for k, v in CALIBRATORS_STANDARDS.items()),
    "--standards-for", "lna:" + ",".join(f"{k}={v}" for k, v in RECEIVER_STANDARDS.items()),
]  # fmt: skip


def import_vna_run(tmp_path, *extra):
    (tmp_path / "kit.json").write_text(KIT_EXAMPLE)
    out = tmp_path / "run.h5"
    out.unlink(missing_ok=True)
    status = main([
        "import", "edges", str(RUN), "-o", str(out), "--hot-cable", "ut141c",
        "--temperatures", "amb=306.5,hot=393.22,open=306.5,short=306.5",
        "--kit", str(tmp_path / "kit.json"), *VNA_ARGS, *extra,
    ])  # fmt: skip
    return status, out


@needs_data
def test_cli_import_edges_vna_moves_the_receiver_or_refuses(tmp_path, capsys):
    status, _ = import_vna_run(tmp_path)
    assert status == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2  # refused in two lines, naming the options
    assert err[0].startswith("reach-cal: error: the receiver 'lna' is read with its own")
    assert "--receiver-cable" in err[1]
    assert not (tmp_path / "run.h5").exists()

    def spline(name, freq):
        f, g = et.read_s11_csv(RUN / name)
        return CubicSpline(f, g)(freq)

    for option, expected, tol in (
        (("--receiver-cable", "edges3"), "s11lna.csv", PATH_TOL),
        (("--receiver-cable", "length_m=0.108204,eps_pct=-1.24,sigma_pct=-91.5"), "s11lna.csv",
         PATH_TOL),
        (("--receiver-path", "none"), "s11.csv", RECEIVER_TOL),
    ):  # fmt: skip
        status, run = import_vna_run(tmp_path, *option)
        assert status == 0, capsys.readouterr().err
        out = capsys.readouterr().out
        assert ("moved to the loads' plane" in out) == (option[1] != "none")
        data, _ = read_run(run)
        assert np.max(np.abs(data.gamma_rec - spline(expected, data.freq_hz))) < tol, option
        for name in data.names:
            gamma = spline(f"s11{name}.csv", data.freq_hz)
            assert np.max(np.abs(data.sources[name].gamma - gamma)) < LOADS_TOL, name


@needs_data
def test_cli_import_vna_reproduces_the_corrected_files(tmp_path, capsys):
    (tmp_path / "kit.json").write_text(KIT_EXAMPLE)
    args = ["import", "vna", str(VNA), "-o", str(tmp_path / "out"), "--devices",
            ",".join((*LOADS, "lna")), "--kit", str(tmp_path / "kit.json"), *VNA_ARGS[2:]]
    assert main(args) == 0, capsys.readouterr().err
    for name in (*LOADS, "lna"):
        _, g, _ = read_touchstone(tmp_path / "out" / f"{name}.s1p")
        _, g_csv = et.read_s11_csv(RUN / ("s11.csv" if name == "lna" else f"s11{name}.csv"))
        assert np.max(np.abs(g - g_csv)) < (RECEIVER_TOL if name == "lna" else LOADS_TOL), name
    # with the receiver's path, its S11 is the pipeline's s11lna.csv
    moved = [*args[:4], str(tmp_path / "moved"), *args[5:], "--receiver", "lna",
             "--receiver-cable", "edges3"]  # fmt: skip
    assert main(moved) == 0, capsys.readouterr().err
    assert "lna moved to the loads' plane: UT-141C-SP line of 108.2 mm" in capsys.readouterr().out
    _, g, _ = read_touchstone(tmp_path / "moved" / "lna.s1p")
    _, g_csv = et.read_s11_csv(RUN / "s11lna.csv")
    assert np.max(np.abs(g - g_csv)) < PATH_TOL
    assert main([*moved[:-2]]) == 2
    assert "--receiver NAME and --receiver-cable" in capsys.readouterr().err
