"""Laboratory data in: the general EDGES importer, raw VNA exports, ``reach-cal import``.

The real EDGES-3 run (``../shared/data/edges3-2022-316``, see ``tests/test_edges3_real.py``)
checks that the new path gives what :func:`calibration.io.edges_import.load_edges3_run` gave:
the same arrays, bit for bit, through the run file, and the same solution. Raw VNA exports
are made from known reflections with seeded random error terms and a modelled kit; their
correction must return the reflections to the rounding of the arithmetic (1e-12).
"""

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from calibration.choice.model_fit import OrderChoice
from calibration.cli import main
from calibration.core.errors import FileFormatError, InvalidDataError
from calibration.io import edges_text as et
from calibration.io.edges_import import (
    EdgesImport,
    EdgesLayout,
    MeasuredLoss,
    import_edges,
    load_edges3_run,
    read_gain_table,
)
from calibration.io.hdf5_io import read_run, run_noise_source_model, run_power_spectra
from calibration.io.solution_file import read_solution
from calibration.io.vna_import import VnaLayout, correct_exports, read_cal_kit
from calibration.rf.cal_kit import CalKit, LoadStandard, Offset, OpenStandard, ShortStandard
from calibration.rf.one_port import OnePortTerms
from calibration.rf.touchstone import read_touchstone, write_touchstone
from calibration.solve.radiometric_solver import solve_radiometric

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "edges3-2022-316"
needs_data = pytest.mark.skipif(
    not DATA.is_dir(),
    reason=f"the shared EDGES-3 data set is not beside this checkout (looked for {DATA})",
)
TEMPERATURES = "amb=306.5,hot=393.22,open=306.5,short=306.5"
SAME_FLOAT_ROUNDING = 1e-12  # reflections through solve + correct: a few ulps of |G| ~ 1

#: A Keysight-style kit with every term (85033E-like numbers), in the JSON of read_cal_kit.
KIT_JSON = {
    "name": "test-kit",
    "short": {"l0": 2.077, "l1": -108.5, "l2": 2.17, "l3": -0.01, "offset": {"delay_s": 31.8e-12}},
    "open": {"c0": 49.43, "c1": -310.1, "c2": 23.17, "c3": -0.16, "offset": {"delay_s": 29.2e-12}},
    "load": {"resistance_ohm": 50.3, "offset": {"delay_s": 1e-12, "loss_gohm_per_s": 2.3}},
}


def assert_same_run(a, b):
    """Every array of two runs equal, bit for bit."""
    assert a.names == b.names
    np.testing.assert_array_equal(a.freq_hz, b.freq_hz)
    np.testing.assert_array_equal(a.gamma_rec, b.gamma_rec)
    assert a.channel_width_hz == b.channel_width_hz
    for name in a.names:
        sa, sb = a.sources[name], b.sources[name]
        for attr in ("gamma", "p_source", "p_load", "p_ns", "temperature_k", "q_variance_override"):
            np.testing.assert_array_equal(getattr(sa, attr), getattr(sb, attr), err_msg=name)
        assert sa.integration == sb.integration


@pytest.fixture(scope="module")
def today():
    return load_edges3_run(DATA)


def import_cli(tmp_path, *extra, directory=DATA, expect=0):
    out = tmp_path / "run.h5"
    args = ["import", "edges", str(directory), "-o", str(out), "--temperatures", TEMPERATURES]
    assert main([*args, *extra]) == expect
    return out


@needs_data
def test_cli_import_gives_todays_run_and_solution(tmp_path, capsys, today):
    run = import_cli(tmp_path, "--hot-cable", "ut141c")
    assert "cable model UT-141C-SP" in capsys.readouterr().out
    data, extra = read_run(run)
    assert extra == {}
    assert_same_run(data, today)
    np.testing.assert_array_equal(data.metadata["hot_load_gain"], today.metadata["hot_load_gain"])
    # the arrays are equal, so any solve agrees; fixed orders keep the test quick
    assert main(["solve", str(run), "-o", str(tmp_path / "sol.h5"), "--orders", "7,7,7,7,7"]) == 0
    ours = read_solution(tmp_path / "sol.h5")
    theirs = solve_radiometric(today, OrderChoice.fixed((7, 7, 7, 7, 7)))
    assert ours.best_orders == theirs.best_orders
    np.testing.assert_array_equal(ours.posterior.mean, theirs.posterior.mean)
    assert main(["summary", str(tmp_path / "sol.h5")]) == 0
    # EDGES' noise source is not REACH's NC346A: its ENR table is not held to it
    printed = capsys.readouterr().out
    assert "noise source: not checked, the run's noise source is not recorded" in printed
    assert "PASS" not in printed
    assert "FAIL" not in printed
    # the importer's stand-in powers are marked as such
    assert run_power_spectra(run) == "placeholder"
    assert run_noise_source_model(run) is None


@needs_data
def test_other_file_names(tmp_path, today):
    """An ``*_alan.txt`` layout, found by patterns with wildcards."""
    for name in ("amb", "hot", "open", "short"):
        shutil.copy(DATA / f"sp{name}.txt", tmp_path / f"2022_316_sp{name}_alan.txt")
    shutil.copy(DATA / "s11_modelled.txt", tmp_path / "s11_modelled_alan.txt")
    layout = EdgesLayout(spectrum="*_sp{name}_alan.txt", s11_modelled="s11_*_alan.txt")
    temps = {"amb": et.T_COLD_K, "hot": et.T_HOT_K, "open": et.T_COLD_K, "short": et.T_COLD_K}
    assert_same_run(import_edges(tmp_path, EdgesImport(temps, layout)), today)
    (tmp_path / "2022_317_spamb_alan.txt").write_text("")
    with pytest.raises(FileFormatError, match=r"matched 2 \(2022_316_spamb_alan.txt, 2022_317"):
        import_edges(tmp_path, EdgesImport(temps, layout))


@needs_data
def test_measured_gain_table(tmp_path, today):
    """The cable model's gain as a measured table on the channels: the same hot load."""
    table = tmp_path / "gain.txt"
    gain = today.metadata["hot_load_gain"]
    rows = [f"{float(f) / 1e6!r} {float(g)!r}" for f, g in zip(today.freq_hz, gain, strict=True)]
    # rows far outside the band with unphysical gains (edges-cal's table at 40 MHz) are unread
    outside = ["40.0 1.02", "45.0 1.01", *rows, "199.0 1.03"]
    table.write_text("# freq_MHz power_gain\n" + "\n".join(outside) + "\n")
    run = import_cli(tmp_path, "--hot-loss", str(table))
    data, _ = read_run(run)
    # f / 1e6 * 1e6 may differ from f by an ulp, so interpolation may move G by ~1e-16
    np.testing.assert_allclose(
        data.sources["hot"].temperature_k, today.sources["hot"].temperature_k, rtol=0, atol=1e-12
    )
    # no loss: the hot load at its thermometer's temperature
    plain, _ = read_run(import_cli(tmp_path))
    np.testing.assert_array_equal(plain.sources["hot"].temperature_k, et.T_HOT_K)


def test_gain_table_errors(tmp_path):
    path = tmp_path / "gain.txt"
    path.write_text("# f g\n50 0.99\n60 zz\n")
    with pytest.raises(FileFormatError, match=r"gain.txt:3: 'zz' is not a number"):
        read_gain_table(path)
    path.write_text("50 0.99\n60 1.2\n")
    with pytest.raises(InvalidDataError, match=r"gain.txt:2: power gain 1.2 at 60 MHz is not in"):
        read_gain_table(path).gain_at(np.array([55e6]), np.zeros(1, complex))
    path.write_text("50 0.99\n\n50 0.98\n")
    with pytest.raises(FileFormatError, match=r"gain.txt:3: frequencies must increase"):
        read_gain_table(path)
    path.write_text("50 0.99\n60 0.98\n")
    loss = read_gain_table(path)
    assert isinstance(loss, MeasuredLoss)
    with pytest.raises(InvalidDataError, match="covers 50-60 MHz, not the band"):
        loss.gain_at(np.array([55e6, 70e6]), np.zeros(2, complex))


def test_gain_table_read_over_the_band_only(tmp_path):
    """A table over the whole spectrum (edges-cal's ``hot_load_loss.txt``) whose model
    exceeds 1 far outside the band: only the rows the band's interpolation uses count."""
    rng = np.random.default_rng(18)
    path = tmp_path / "hot_load_loss.txt"
    for on_grid in (False, True) * 5:
        f = np.sort(rng.uniform(0, 200, 300))
        lo, hi = np.sort(rng.uniform(45, 195, 2))
        channels = np.linspace(lo, hi, 50) * 1e6
        if on_grid:  # channels on the table's rows: no row beyond the band is used
            channels = f[(f >= lo) & (f <= hi)] * 1e6
            used = (f >= lo) & (f <= hi)
        else:  # the rows around each channel, one beyond each edge
            below = np.searchsorted(f * 1e6, channels, "right") - 1
            used = np.isin(np.arange(f.size), np.r_[below, below + 1])
        if channels.size < 2:
            continue
        gain = np.where(used, rng.uniform(0.98, 1.0, f.size), 1.3)
        rows = [f"{float(a)!r} {float(b)!r}" for a, b in zip(f, gain, strict=True)]
        path.write_text("# freq, loss\n" + "\n".join(rows))
        loss = read_gain_table(path)
        np.testing.assert_array_equal(
            loss.gain_at(channels, np.zeros(channels.size, complex)),
            np.interp(channels, f * 1e6, gain),
        )
        with pytest.raises(InvalidDataError, match=r"hot_load_loss.txt:\d+: power gain 1.3 at "):
            loss.gain_at(f[[0, -1]] * 1e6, np.zeros(2, complex))
        gain[np.flatnonzero(used)[used.sum() // 2]] = 1.01
        rows = [f"{float(a)!r} {float(b)!r}" for a, b in zip(f, gain, strict=True)]
        path.write_text("\n".join(rows))
        with pytest.raises(InvalidDataError, match=r"power gain 1.01 at [\d.]+ MHz"):
            read_gain_table(path).gain_at(channels, np.zeros(channels.size, complex))


@needs_data
def test_band_beyond_the_data_is_named_before_the_vna_is_blamed(tmp_path, today):
    temps = {"amb": et.T_COLD_K, "hot": et.T_HOT_K, "open": et.T_COLD_K, "short": et.T_COLD_K}
    with pytest.raises(InvalidDataError, match=r"s11_modelled.txt\) covers 50.0061-189.996 MHz; "
                       r"--band 45,198 reaches beyond: give --band 50.01,189.99"):  # fmt: skip
        import_edges(DATA, EdgesImport(temps, band_mhz=(45.0, 198.0)))
    names = ("amb", "hot", "open", "short", "lna")
    exports = {n: et.read_s11_csv(DATA / f"s11{n}.csv") for n in names}
    f, g = exports["amb"]
    short = {**exports, "amb": (f[f <= 110.5e6], g[f <= 110.5e6])}
    with pytest.raises(InvalidDataError, match=r"S11 of amb \(the corrected reflections\) "
                       r"covers 40-110.4 MHz; --band 50,190 reaches beyond: give --band 50,110.4"):
        import_edges(DATA, EdgesImport(temps), short)
    # a model used beyond its fit: |Gamma| > 1 from some frequency on is named, with the band
    grown = {**exports, "amb": (f, np.where(f > 150e6, 1.39 * np.exp(1j * f / 1e7), g))}
    with pytest.raises(InvalidDataError) as err:
        import_edges(DATA, EdgesImport(temps), grown)
    lines = str(err.value).splitlines()
    assert len(lines) == 2
    assert re.match(r"S11 of amb \(given\): \|Gamma\| reaches 1\.\d+ at 15\d\.\d+ MHz "
                    r"\(>= 1 from 150\.\d+ MHz\)", lines[0])  # fmt: skip
    assert re.match(r"if its data end there, give --band 50,1(49|50)\.\d+; else check the VNA",
                    lines[1])  # fmt: skip


def test_temperatures_must_name_every_load():
    with pytest.raises(InvalidDataError, match="no temperature given for the loads open, short"):
        EdgesImport({"amb": 300.0, "hot": 370.0})
    with pytest.raises(InvalidDataError, match="which are not loads"):
        EdgesImport({"amb": 300.0, "hot": 370.0, "open": 300.0, "short": 300.0, "cold": 1.0})


def test_cli_errors_are_file_line(tmp_path, capsys):
    bad = tmp_path / "run"
    bad.mkdir()
    (bad / "spamb.txt").write_text("48.0 300.1 1 450 // header\n48.1 x 1\n")
    for name in ("hot", "open", "short"):
        (bad / f"sp{name}.txt").write_text("48.0 300.1 1 450 // header\n48.1 300.2 1\n")
    assert main(["import", "edges", str(bad), "-o", str(tmp_path / "r.h5"),
                 "--temperatures", TEMPERATURES]) == 2  # fmt: skip
    assert (
        f"reach-cal: error: {bad / 'spamb.txt'}:2: 'x' is not a number" in capsys.readouterr().err
    )
    assert main(["import", "edges", str(tmp_path / "none"), "-o", str(tmp_path / "r.h5"),
                 "--temperatures", TEMPERATURES]) == 2  # fmt: skip
    assert "'spamb.txt' must match one file, matched 0" in capsys.readouterr().err
    assert main(["import", "edges", str(bad), "-o", str(tmp_path / "r.h5")]) == 2
    assert "--temperatures" in capsys.readouterr().err


# --- raw VNA exports -------------------------------------------------------------------


def random_terms(rng, n):
    """Error terms of a plausible port: directivity ~0.05, match ~0.1, tracking ~0.9."""

    def c(scale, size=n):
        return scale * (rng.standard_normal(size) + 1j * rng.standard_normal(size))

    return OnePortTerms(c(0.05), c(0.1), 0.9 * np.exp(1j * rng.uniform(0, 2 * np.pi, n)) + c(0.01))


def write_raw_exports(directory, devices, kit, rng, per_device=False):
    """Raw readings of each device and of the kit's standards through random error terms.

    ``devices``: ``{name: (freq_hz, actual gamma)}``. Standards are shared (``cal_*.s1p``)
    unless ``per_device`` (``{name}_*.s1p``, the port's terms drawn again for each device).
    """
    directory.mkdir(exist_ok=True)
    shared = None
    for name, (freq, gamma) in devices.items():
        terms = shared if shared is not None else random_terms(rng, freq.size)
        if not per_device:
            shared = terms
        write_touchstone(directory / f"{name}.s1p", freq, terms.embed(gamma), fmt="MA", unit="MHz")
        prefix = f"{name}_" if per_device else "cal_"
        for standard, actual in zip(("short", "open", "load"), kit.reflections(freq), strict=True):
            write_touchstone(directory / f"{prefix}{standard}.s1p", freq, terms.embed(actual))


def test_correct_exports_recovers_reflections(tmp_path):
    rng = np.random.default_rng(12)
    freq = np.linspace(40e6, 200e6, 151)
    actual = {
        n: 0.3 * rng.standard_normal(151) * np.exp(2j * np.pi * rng.random(151)) for n in "abc"
    }
    (tmp_path / "kit.json").write_text(json.dumps(KIT_JSON))
    kit = read_cal_kit(tmp_path / "kit.json")
    assert kit.name == "test-kit"
    assert kit.open.offset.delay_s == 29.2e-12
    devices = {n: (freq, g) for n, g in actual.items()}
    for per_device, layout in ((False, None), (True, VnaLayout(standards={
            s: f"{{name}}_{s}.s1p" for s in ("short", "open", "load")}))):  # fmt: skip
        raw = tmp_path / f"raw{per_device}"
        write_raw_exports(raw, devices, kit, rng, per_device)
        corrected = correct_exports(raw, ("a", "b", "c"), layout, kit)
        for name, (f, g) in corrected.items():
            np.testing.assert_allclose(f, freq, rtol=1e-15)
            np.testing.assert_allclose(g, actual[name], rtol=0, atol=SAME_FLOAT_ROUNDING)
    # with the ideal kit instead of the modelled one the correction is wrong, visibly
    wrong = correct_exports(tmp_path / "rawFalse", ("a",))["a"][1]
    assert np.max(np.abs(wrong - actual["a"])) > 1e-3


def test_cli_import_vna(tmp_path, capsys):
    rng = np.random.default_rng(3)
    freq = np.linspace(50e6, 150e6, 41)
    actual = {"amb": 0.01 * np.exp(1j * freq / 1e7), "lna": 0.03 * np.exp(-1j * freq / 2e7)}
    (tmp_path / "kit.json").write_text(json.dumps(KIT_JSON))
    write_raw_exports(tmp_path / "raw", {n: (freq, g) for n, g in actual.items()},
                      read_cal_kit(tmp_path / "kit.json"), rng)  # fmt: skip
    out = tmp_path / "corrected"
    args = ["import", "vna", str(tmp_path / "raw"), "-o", str(out), "--devices", "amb,lna"]
    assert main([*args, "--kit", str(tmp_path / "kit.json")]) == 0
    assert "corrected 2 devices" in capsys.readouterr().out
    for name, gamma in actual.items():
        _, g, _ = read_touchstone(out / f"{name}.s1p")
        np.testing.assert_allclose(g, gamma, rtol=0, atol=SAME_FLOAT_ROUNDING)


def test_vna_errors(tmp_path, capsys):
    freq = np.linspace(50e6, 150e6, 11)
    kit = CalKit(
        ShortStandard(offset=Offset(delay_s=3e-11)), OpenStandard(c0=40.0), LoadStandard(49.0)
    )
    write_raw_exports(tmp_path / "raw", {"amb": (freq, np.full(11, 0.01 + 0j))}, kit,
                      np.random.default_rng(1))  # fmt: skip
    write_touchstone(tmp_path / "raw" / "hot.s1p", freq[:-1], np.zeros(10))
    with pytest.raises(FileFormatError, match=r"hot.s1p: measured at other frequencies"):
        correct_exports(tmp_path / "raw", ("amb", "hot"), kit=kit)
    (tmp_path / "raw" / "hot.s1p").write_text("# Hz S RI R 50\n1e8 0.1\n")
    with pytest.raises(FileFormatError, match=r"hot.s1p:2:"):
        correct_exports(tmp_path / "raw", ("hot",), kit=kit)
    bad_kit = tmp_path / "kit.json"
    for text, message in (
        ('{"open": {"c0": 1,\n "c9": 2}}', r"kit.json: open: unknown keys c9"),
        ('{"open": {"c0": 1,\n }', r"kit.json:2: "),
        ('{"load": {"resistance_ohm": "fifty"}}', r"load.resistance_ohm: expected a number"),
        ('{"short": {"offset": {"loss_gohm_per_s": -1}}}', r"short.offset: .*loss must be >= 0"),
    ):
        bad_kit.write_text(text)
        with pytest.raises(FileFormatError, match=message):
            read_cal_kit(bad_kit)
    args = ["import", "vna", str(tmp_path / "raw"), "-o", str(tmp_path / "out")]
    assert main([*args, "--devices", "amb", "--kit", str(bad_kit)]) == 2
    assert "reach-cal: error:" in capsys.readouterr().err
    assert main([*args, "--devices", "amb", "--standards", "short=a,open=b"]) == 2
    assert "expected short=P,open=P,load=P" in capsys.readouterr().err


@needs_data
def test_edges_run_from_raw_vna_exports(tmp_path, capsys):
    """``import edges --vna``: S11s corrected from raw exports equal the exports' own S11s.

    The corrected S11s of the data set (``s11<name>.csv``, each on its own grid) are
    embedded with per-device random error terms and a modelled kit; the run imported
    through the raw exports must match the one imported from the CSVs (``--s11 raw``)
    to the correction's rounding.
    """
    rng = np.random.default_rng(316)
    kit_path = tmp_path / "kit.json"
    kit_path.write_text(json.dumps(KIT_JSON))
    devices = {
        n: et.read_s11_csv(DATA / f"s11{n}.csv") for n in ("amb", "hot", "open", "short", "lna")
    }
    write_raw_exports(tmp_path / "raw", devices, read_cal_kit(kit_path), rng, per_device=True)
    standards = ",".join(f"{s}={{name}}_{s}.s1p" for s in ("short", "open", "load"))
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    via_vna = import_cli(tmp_path / "a", "--vna", str(tmp_path / "raw"), "--kit", str(kit_path),
                         "--standards", standards)  # fmt: skip
    assert "corrected" in capsys.readouterr().out
    via_csv = import_cli(tmp_path / "b", "--s11", "raw")
    (a, _), (b, _) = read_run(via_vna), read_run(via_csv)
    np.testing.assert_allclose(a.gamma_rec, b.gamma_rec, rtol=0, atol=SAME_FLOAT_ROUNDING)
    for name in a.names:
        np.testing.assert_allclose(
            a.sources[name].gamma, b.sources[name].gamma, rtol=0, atol=SAME_FLOAT_ROUNDING
        )
        np.testing.assert_array_equal(a.sources[name].p_source, b.sources[name].p_source)


def test_import_help_gives_every_default_and_unit(capsys):
    for kind in ("edges", "vna"):
        assert main(["import", kind, "--help"]) == 0
        text = capsys.readouterr().out
        options = text.split("options:", 1)[1].split("\nthe receiver's path: with")[0]
        entries = re.split(r"\n  (?=-)", options)[1:]
        for entry in entries:
            flat = " ".join(entry.split())
            if flat.startswith(("-h", "-o", "--devices")) or "(no default)" in flat:
                continue
            assert "default" in flat, flat
        assert '"short", "open" and "load" are required' in text  # the kit format
        assert max(len(line) for line in text.splitlines()) <= 80


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--band", "50", "190"], "expected LO,HI in MHz, one argument as solve takes it"),
        (["--band", "190,50"], "expected finite 0 <= LO < HI"),
        (["--receiver-cable", "length=3"], "expected edges3 or length_m=M"),
        (["--receiver-cable", "length_m=0"], "--receiver-cable: receiver cable: needs length_m"),
        (["--temperatures", "amb=22.85,hot=120.07,open=22.85,short=22.85"],
         "look like Celsius: amb at 22.85 K (296 K if 22.85 is Celsius)"),
        (["--temperatures", "amb=77,hot=393,open=77,short=77", "--cryogenic"],
         "'spamb.txt' must match one file"),  # accepted: the files are looked for
    ],
)
def test_import_option_errors_say_what_to_give(tmp_path, capsys, options, message):
    args = ["import", "edges", str(tmp_path), "-o", str(tmp_path / "r.h5"),
            "--temperatures", TEMPERATURES, *options]  # fmt: skip
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err
    assert len(err.strip().splitlines()[-1]) < 200


def test_an_empty_kit_is_refused_by_name(tmp_path, capsys):
    (tmp_path / "kit.json").write_text("{}")
    args = ["import", "vna", str(tmp_path), "-o", str(tmp_path / "out"), "--devices", "amb",
            "--kit", str(tmp_path / "kit.json")]  # fmt: skip
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "kit.json: no 'short' standard" in err[0]
