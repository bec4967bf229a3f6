"""Touchstone files as real VNAs write them, read as scikit-rf reads them.

scikit-rf (``skrf.Network(path)``, 2.2) is the reference wherever it reads a variant. It
cannot read three things real files contain (``test_scikit_rf_cannot_read_these``): a
``#`` line before the option line that is not one (``#48212!Agilent ...``: it takes it
for the option line), ``BEGIN``/``END`` lines (not numbers), and option lines whose tokens
are reordered or leave out any but trailing ones (it reads them by position). Such
variants are compared with scikit-rf's reading of a *twin* file (the same data lines under
the canonical option line ``# <unit> S <format> R <z0>``, without markers and vendor
lines) and with the known truth they were generated from.
"""

import os
import re
from decimal import Decimal

import numpy as np
import pytest
import skrf
from touchstone_variants import DATA_ROOT, Variant, make_variant

from calibration.io import edges_text as et
from calibration.rf import touchstone as ts
from reach_receiver.store import touchstone as store_touchstone

RTOL = 1e-12


def assert_same(freq_hz, s, ref_freq_hz, ref_s, rtol=RTOL):
    np.testing.assert_allclose(freq_hz, ref_freq_hz, rtol=rtol, atol=0)
    np.testing.assert_allclose(s, ref_s, rtol=rtol, atol=0)


def skrf_read(path):
    network = skrf.Network(str(path))
    return network.f, network.s, network.z0


def write(path, text):
    path.write_bytes(text.encode("latin-1"))
    return path


# --- generated variants against scikit-rf and the truth --------------------------------


@pytest.mark.parametrize("seed", range(400))
def test_generated_variant_reads_as_scikit_rf_and_the_truth(tmp_path, seed):
    variant: Variant = make_variant(np.random.default_rng(seed))
    path = write(tmp_path / variant.name, variant.text)
    twin = write(tmp_path / f"twin.s{variant.ports}p", variant.twin_text)
    got = ts.read_touchstone_network(path)
    assert got.n_ports == variant.ports
    assert got.z0 == variant.z0
    assert_same(got.freq_hz, got.s, variant.freq_hz, variant.s)
    ref_f, ref_s, ref_z0 = skrf_read(twin)
    assert_same(got.freq_hz, got.s, ref_f, ref_s)
    np.testing.assert_array_equal(ref_z0, variant.z0)
    if variant.skrf_reads_it:
        assert_same(got.freq_hz, got.s, *skrf_read(path)[:2])


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("vendor.s1p", "#48212!Agilent Technologies,N5225A\n# Hz S RI R 50\n1 0.5 0\n"),
        ("vendor2.s1p", "#Keysight PNA-X export\n# Hz S RI R 50\n1 0.5 0\n"),
        ("markers.s1p", "BEGIN\n# Hz S RI R 50\n1 0.5 0\nEND\n"),
        ("reordered.s1p", "# S RI Hz R 50\n1 0.5 0\n"),
        ("format_only.s1p", "# RI\n1 0.5 0\n"),
        ("reference_only.s1p", "# R 50\n1 0.5 0\n"),
    ],
)
def test_scikit_rf_cannot_read_these(tmp_path, name, text):
    """Why those variants are tested against the truth (scikit-rf 2.2 raises on each)."""
    path = write(tmp_path / name, text)
    with pytest.raises(ValueError):  # noqa: PT011 - scikit-rf's messages vary
        skrf.Network(str(path))
    assert ts.read_touchstone_network(path).s.shape == (1, 1, 1)


def test_a_pna_file_fetched_over_scpi(tmp_path):
    """BEGIN, an IEEE 488.2 block header glued to the first comment, END: known truth."""
    text = (
        "BEGIN\n#48212!Agilent Technologies,N5225A,MY51451234,A.09.90.02\n"
        "!Date: Tuesday, November 08, 2022 10:12:45\n!Correction: S11(Full 1 Port(3))\n"
        "!S1P File: Measurement: S11:\n# Hz S  DB   R 50\n"
        "40000000 -20 90\n40500000 -6.0205999132796239 -180 ! half\nEND\n"
    )
    freq, s11, z0 = ts.read_touchstone(write(tmp_path / "lna.s1p", text))
    np.testing.assert_array_equal(freq, [40e6, 40.5e6])
    np.testing.assert_allclose(s11, [0.1j, -0.5], rtol=0, atol=1e-15)
    assert z0 == 50.0
    network = ts.read_touchstone_network(tmp_path / "lna.s1p")
    assert network.comments[0] == "Agilent Technologies,N5225A,MY51451234,A.09.90.02"
    assert network.comments[-1] == "half"
    # without BEGIN, END and the block header it is a file scikit-rf reads: the same numbers
    plain = "\n".join(text.replace("#48212", "").splitlines()[1:-1])
    assert_same(freq, s11, *(a.ravel() for a in skrf_read(write(tmp_path / "p.s1p", plain))[:2]))


# --- every form of the option line --------------------------------------------------------

OPTION_FORMS = [
    ("#", 1e9, "ma", 50.0),
    ("# ", 1e9, "ma", 50.0),
    ("#GHz", 1e9, "ma", 50.0),
    ("# hz", 1.0, "ma", 50.0),
    ("# S", 1e9, "ma", 50.0),
    ("# s ri", 1e9, "ri", 50.0),
    ("# RI", 1e9, "ri", 50.0),
    ("# R 75", 1e9, "ma", 75.0),
    ("# r 75 mhz", 1e6, "ma", 75.0),
    ("# db KHZ", 1e3, "db", 50.0),
    ("# MA S GHZ R 50", 1e9, "ma", 50.0),
    ("#\tMHz\tS\tDB\tR\t25.5\t", 1e6, "db", 25.5),
    ("# Hz S RI R 50.0 ! trailing comment", 1.0, "ri", 50.0),
    ("#kHz   s   Ma   r   1e2", 1e3, "ma", 100.0),
]


@pytest.mark.parametrize(("line", "scale", "fmt", "z0"), OPTION_FORMS)
def test_option_line_forms(tmp_path, line, scale, fmt, z0):
    path = write(tmp_path / "o.s1p", f"! form\n{line}\n2.5 0.5 30\n3.5 -6 -45\n")
    freq, s11, got_z0 = ts.read_touchstone(path)
    a, b = np.array([0.5, -6.0]), np.deg2rad([30.0, -45.0])
    expected = {"ri": np.array([0.5 + 30j, -6 - 45j]), "ma": a * np.exp(1j * b),
                "db": 10 ** (a / 20) * np.exp(1j * b)}[fmt]
    assert_same(freq, s11, np.array([2.5, 3.5]) * scale, expected)
    assert got_z0 == z0


def test_per_port_reference_on_the_option_line(tmp_path):
    text = "# MHz S RI R 50 50\n1 1 0 2 0 3 0 4 0\n"
    assert ts.read_touchstone_network(write(tmp_path / "p.s2p", text)).z0 == 50.0
    with pytest.raises(ts.TouchstoneError, match=r"p\.s2p:1: per-port references"):
        ts.read_touchstone_network(write(tmp_path / "p.s2p", text.replace("50 50", "50 75")))


# --- Touchstone 2.0 -----------------------------------------------------------------------

V2 = """! version 2 file
[Version] 2.0
# MHz S RI R 50
[Number of Ports] {ports}
{order}[Number of Frequencies] 2
[Reference] {reference}
{info}[Network Data]
100 {row1}
200 {row2}
[End]
"""


@pytest.mark.parametrize("order", ["12_21", "21_12", None])
@pytest.mark.parametrize("info", [False, True])
def test_version_2_files(tmp_path, order, info):
    """scikit-rf reads these except [Begin Information] blocks: those against the truth."""
    ports = 1 if order is None else 2
    rows = np.arange(1, 2 * 2 * ports * ports + 1, dtype=float).reshape(2, -1) / 10
    text = V2.format(
        ports=ports, order=f"[Two-Port Data Order] {order}\n" if order else "",
        reference=" ".join(["75"] * ports), row1=" ".join(map(str, rows[0])),
        row2=" ".join(map(str, rows[1])),
        info="[Begin Information]\n[Manufacturer] X\n[End Information]\n" if info else "",
    )
    got = ts.read_touchstone_network(write(tmp_path / "v2.ts", text))
    pairs = rows[:, 0::2] + 1j * rows[:, 1::2]
    truth = pairs.reshape(2, ports, ports)
    truth = truth.transpose(0, 2, 1) if order == "21_12" else truth
    assert_same(got.freq_hz, got.s, [100e6, 200e6], truth)
    assert got.z0 == 75.0
    if not info:
        assert_same(got.freq_hz, got.s, *skrf_read(tmp_path / "v2.ts")[:2])


# --- corrupt files: file:line: message ---------------------------------------------------

HEAD = "! corrupt\n# Hz S RI R 50\n"
CORRUPT = [
    ("bad.s1p", HEAD + "1 0.1 x\n", 3, r"not a number: 'x'"),
    ("bad.s1p", HEAD + "1 0.1 1_0\n", 3, r"not a number: '1_0'"),
    ("bad.s1p", HEAD + "1 nan 0\n", 3, r"not a number: 'nan'"),
    ("bad.s1p", HEAD + "1 0 1e999\n", 3, r"number out of range"),
    ("bad.s1p", HEAD + "1 0 0\n2 0.1\n", 4, r"expected 'f a b' \(3 numbers\), got 2"),
    ("bad.s1p", HEAD + "1 0 0 0\n", 3, r"expected 'f a b'"),
    ("bad.s2p", HEAD + "1 0 0 0 0\n 0 0\n", 3, r"too few values: lines 3-4 hold 7"),
    ("bad.s2p", HEAD + "1 0 0 0 0 0 0\n2 0 0 0 0 0 0 0 0\n", 3, r"too few values: line 3"),
    ("bad.s2p", HEAD + "1 0 0 0 0 0 0 0\n", 3, r"too few or too many values: 8 numbers"),
    ("bad.s2p", HEAD + "1 0 0 0 0 0 0 0 0 0\n", 3, r"too many values: 10 numbers"),
    ("bad.s2p", HEAD + "1 0 0 0 0 0 0\n 0 0 0 0\n", 4, r"too many values: .* reaches 11"),
    ("bad.s1p", HEAD + "1 0 0\n1 0 0\n", 4, r"frequency 1\.0 does not increase"),
    ("bad.s1p", HEAD + "2 0 0\n1 0 0\n", 4, r"frequency 1\.0 does not increase"),
    ("bad.s1p", HEAD + "-1 0 0\n", 3, r"frequency -1 is negative or out of range"),
    ("bad.s1p", "# GHz S RI\n1e300 0 0\n", 2, r"frequency 1e300 is negative or out of range"),
    ("bad.s2p", HEAD + "1" + " 0" * 8 + "\n0.5 1 2 3 4\n", 4, r"noise parameters are not read"),
    ("bad.s1p", "# Hz S RI Q\n1 0 0\n", 1, r"unknown option token 'Q'"),
    ("bad.s1p", "# Hz S XX R 50\n1 0 0\n", 1, r"unknown option token 'XX'"),
    ("bad.s1p", "# Hz Z RI R 50\n1 0 0\n", 1, r"unsupported option 'Z'"),
    ("bad.s2p", "# Hz Y RI R 50\n1" + " 0" * 8 + "\n", 1, r"unsupported option 'Y'"),
    ("bad.s2p", "# h Hz RI\n1" + " 0" * 8 + "\n", 1, r"unsupported option 'h'"),
    ("bad.s1p", "# Hz S RI R\n1 0 0\n", 1, r"'R' needs a reference impedance"),
    ("bad.s1p", "# Hz S RI R -50\n1 0 0\n", 1, r"reference impedance must be > 0"),
    ("bad.s1p", "# Hz MHz\n1 0 0\n", 1, r"two of frequency unit: 'Hz' and 'MHz'"),
    ("bad.s1p", HEAD + "# MHz S RI R 50\n1 0 0\n", 3, r"differs from the one on line 2"),
    ("bad.s1p", "1 0 0\n# Hz S RI R 50\n", 1, r"data before any option line"),
    ("bad.s1p", "! x\n# Hz S RI R 50\n1 0 0\n# Hz S RI\n2 0 0\n# GHz\n", 6, r"differs"),
    ("bad.s1p", "#Hz,S,RI,R,50\n1 0 0\n", 2, r"option line.*skipped vendor lines \[1\]"),
    ("bad.s1p", HEAD + "1 0 0\nEND\n2 0 0\n", 5, r"'2 0 0' after END on line 4"),
    ("bad.s1p", HEAD + "1 0 0\nBEGIN\n", 4, r"BEGIN after the data began"),
    ("bad.s1p", HEAD + "! only comments\n", 3, r"no data lines"),
    ("bad.txt", HEAD + "1 0 0\n", 3, r"cannot tell the number of ports"),
    ("bad.s3p", HEAD + "1 0 0\n", 3, r"only one- and two-ports are read, not 3"),
    ("bad.s1p", HEAD + "[Number of Ports] 1\n", 3, r"keyword \[Number of Ports\] in a version 1"),
    ("bad.ts", "[Version] 3.0\n", 1, r"unsupported \[Version\] '3\.0'"),
]
V2_HEAD = "[Version] 2.0\n# Hz S RI R 50\n[Number of Ports] 2\n"
V2_ROW = "1" + " 0" * 8 + "\n"
CORRUPT += [
    ("bad.ts", V2_HEAD + "[Number of Frequencies] 1\n[Network Data]\n", 5, r"needs \[Two-Port"),
    ("bad.ts", V2_HEAD + "[Two-Port Data Order] 12_21\n[Network Data]\n", 5,
     r"\[Number of Frequencies\] is required"),
    ("bad.ts", V2_HEAD + "[Two-Port Data Order] 12_21\n[Number of Frequencies] 2\n"
     "[Network Data]\n" + V2_ROW, 5, r"\[Number of Frequencies\] is 2 but the file has 1"),
    ("bad.ts", V2_HEAD + "[Two-Port Data Order] 12_12\n", 4, r"12_21 or 21_12"),
    ("bad.ts", V2_HEAD + "[Matrix Format] Lower\n", 4, r"only Full is read"),
    ("bad.ts", V2_HEAD + "[Noise Data]\n", 4, r"noise and mixed-mode data are not read"),
    ("bad.ts", V2_HEAD + "[Frobnicate] 1\n", 4, r"unknown keyword \[Frobnicate\]"),
    ("bad.ts", V2_HEAD + V2_ROW, 4, r"network data before \[Network Data\]"),
    ("bad.ts", V2_HEAD + "[Reference] 50\n75\n[Two-Port Data Order] 12_21\n"
     "[Number of Frequencies] 1\n[Network Data]\n", 4, r"\[Reference\] \[50\.0, 75\.0\]"),
    ("bad.s1p", V2_HEAD, 3, r"\[Number of Ports\] 2 but the extension is \.s1p"),
]


@pytest.mark.parametrize(("name", "text", "line", "message"), CORRUPT)
def test_corrupt_files_name_file_and_line(tmp_path, name, text, line, message):
    path = write(tmp_path / name, text)
    with pytest.raises(ts.TouchstoneError, match=rf"^{re.escape(str(path))}:{line}: .*{message}"):
        ts.read_touchstone_network(path)


def test_a_two_port_is_not_a_one_port(tmp_path):
    path = write(tmp_path / "two.s2p", "# Hz S RI\n" + V2_ROW)
    with pytest.raises(ts.TouchstoneError, match=r"two\.s2p: a 2-port file, not a one-port"):
        ts.read_touchstone(path)


# --- writing --------------------------------------------------------------------------------


@pytest.mark.parametrize("ports", [1, 2])
@pytest.mark.parametrize("fmt", ["RI", "MA", "db"])
@pytest.mark.parametrize("unit", ["Hz", "kHz", "MHz", "ghz"])
def test_write_read_round_trip(tmp_path, ports, fmt, unit):
    rng = np.random.default_rng(ports * 100 + len(fmt) + len(unit))
    n = 40
    freq = np.sort(rng.uniform(40e6, 180e6, n))
    s = (rng.normal(size=(n, ports, ports)) + 1j * rng.normal(size=(n, ports, ports))) * 0.3
    network = ts.TouchstoneData(freq, s, 75.25, ("test load", "MS2 port"))
    path = tmp_path / f"net.s{ports}p"
    ts.write_touchstone_network(path, network, fmt=fmt, unit=unit)
    back = ts.read_touchstone_network(path)
    np.testing.assert_array_equal(back.freq_hz, freq)  # exact in every unit
    if fmt == "RI":
        np.testing.assert_array_equal(back.s, s)
    else:
        np.testing.assert_allclose(back.s, s, rtol=1e-14, atol=0)
    assert back.z0 == 75.25
    assert back.comments[:2] == ("test load", "MS2 port")
    assert_same(back.freq_hz, back.s, *skrf_read(path)[:2])
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary file left


def test_one_port_writer_keeps_its_signature(tmp_path):
    freq, s11 = np.array([1e6, 2e6]), np.array([0.1 + 0.2j, -0.3j])
    ts.write_touchstone(tmp_path / "a.s1p", freq, s11, 50.0, "line one\nline two")
    assert (tmp_path / "a.s1p").read_text().startswith("! line one\n! line two\n")
    got_f, got_s, z0 = ts.read_touchstone(tmp_path / "a.s1p")
    np.testing.assert_array_equal(got_f, freq)
    np.testing.assert_array_equal(got_s, s11)
    assert z0 == 50.0


def test_written_frequencies_are_shortest_decimals(tmp_path):
    ts.write_touchstone(tmp_path / "a.s1p", [123456780.0, 1.5e9], [0.1, 0.2], unit="MHz")
    lines = (tmp_path / "a.s1p").read_text().splitlines()
    assert lines[-3] == "# MHz S RI R 50.0"
    assert [line.split()[0] for line in lines[-2:]] == ["123.4567800", "1500.0000000"]


def test_writing_is_atomic(tmp_path, monkeypatch):
    path = tmp_path / "ref.s1p"
    ts.write_touchstone(path, [1.0, 2.0], [0.1, 0.2])
    before = path.read_bytes()
    with pytest.raises(ValueError, match="strictly increase"):
        ts.write_touchstone(path, [2.0, 1.0], [0.1, 0.2])
    with pytest.raises(ValueError, match="ASCII"):
        ts.write_touchstone(path, [1.0, 2.0], [0.1, 0.2], comment="50 \u03a9 load")

    def fail(*args):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OSError, match="disk full"):
        ts.write_touchstone(path, [1.0, 2.0], [0.3, 0.4])
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["ref.s1p"]


def test_written_file_has_the_umasks_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        ts.write_touchstone(tmp_path / "a.s1p", [1.0], [0.1])
    finally:
        os.umask(old)
    assert (tmp_path / "a.s1p").stat().st_mode & 0o777 == 0o644


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"name": "a.s2p"}, r"a 1-port file must be named \*\.s1p"),
        ({"fmt": "XY"}, r"format 'XY'"),
        ({"unit": "THz"}, r"unit 'THz'"),
        ({"s11": [0.0, 0.1], "fmt": "DB"}, r"\|S\| = 0 has no dB value"),
    ],
)
def test_writer_refuses(tmp_path, kwargs, message):
    kwargs = {"name": "a.s1p", "s11": [0.1, 0.2], **kwargs}
    with pytest.raises(ValueError, match=message):
        ts.write_touchstone(tmp_path / kwargs.pop("name"), [1.0, 2.0], **kwargs)


def test_touchstone_data_checks_its_arrays():
    with pytest.raises(ValueError, match="shape"):
        ts.TouchstoneData(np.array([1.0, 2.0]), np.zeros((2, 1, 2)))
    with pytest.raises(ValueError, match="only one- and two-ports"):
        ts.TouchstoneData(np.array([1.0]), np.zeros((1, 3, 3)))
    with pytest.raises(ValueError, match="reference impedance"):
        ts.TouchstoneData(np.array([1.0]), np.zeros((1, 1, 1)), z0=0.0)


# --- the receiver side and real files ---------------------------------------------------


def test_the_store_re_exports_the_engine_module():
    for name in ts.__all__:
        assert getattr(store_touchstone, name) is getattr(ts, name)


def test_real_edges3_s11_in_a_vna_styled_file(tmp_path):
    """The EDGES-3 VNA S11s (CSV), written as a PNA writes them, read back to 1e-12."""
    data = DATA_ROOT / "edges3-2022-316"
    if not data.is_dir():
        pytest.skip(f"the shared EDGES-3 data set is absent ({data})")
    for name in ("s11open.csv", "s11short.csv", "s11lna.csv"):
        freq, s11 = et.read_s11_csv(data / name)
        rows = [f"{Decimal(repr(float(f))).scaleb(-6)} {float(20 * np.log10(abs(g)))!r} "
                f"{float(np.degrees(np.angle(g)))!r}" for f, g in zip(freq, s11, strict=True)]
        head = "#48212!Keysight Technologies,N9923A\n! EDGES-3 2022-316\n# MHz S DB R 50\n"
        path = write(tmp_path / "real.s1p", "BEGIN\n" + head + "\n".join(rows) + "\nEND\n")
        got_f, got_s, _ = ts.read_touchstone(path)
        assert_same(got_f, got_s, freq, s11)
        twin = write(tmp_path / "twin.s1p", head.replace("#48212", "") + "\n".join(rows))
        ref_f, ref_s, _ = skrf_read(twin)
        assert_same(got_f, got_s, ref_f, ref_s[:, 0, 0])
