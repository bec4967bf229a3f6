"""Random Touchstone 1.x files in the forms real VNAs and the specification allow.

:func:`make_variant` draws a one- or two-port network and writes it the way some
instrument might: any unit and format, the option line's tokens in any order and case with
any defaults left out, vendor ``#`` lines, an IEEE 488.2 block header on line 1,
``BEGIN``/``END``, comments anywhere, tabs, CRLF, wrapped two-port lines. It also writes a
*twin*: the same data lines under the canonical option line, nothing scikit-rf cannot
read, and says whether scikit-rf 2.2 reads the variant itself.
"""

from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path

import numpy as np

DATA_ROOT = Path(__file__).resolve().parents[2] / "shared" / "data"
UNITS = {"Hz": 0, "kHz": 3, "MHz": 6, "GHz": 9}


@dataclass(frozen=True)
class Variant:
    name: str
    ports: int
    text: str
    twin_text: str
    freq_hz: np.ndarray
    s: np.ndarray
    z0: float
    skrf_reads_it: bool


def _case(rng, word):
    return "".join(c.upper() if rng.random() < 0.5 else c.lower() for c in word)


def _number(rng, x):
    """A decimal that reads back as ``x`` exactly, in one of the usual spellings."""
    x = float(x)
    text = [repr(x), f"{x:.17e}", f"{x:.17E}", f"{x:.16e}"][rng.integers(4)]
    if float(text) != x:
        text = repr(x)
    return "+" + text if x >= 0 and rng.random() < 0.1 else text


def _frequencies(rng, n, exponent):
    if rng.random() < 0.3:  # integer Hz, as most VNAs write them
        hz = 40e6 + np.cumsum(rng.integers(1, 10_000_000, n)).astype(float)
    else:
        hz = rng.uniform(1e3, 1e9) + np.cumsum(rng.uniform(1.0, 1e7, n))
    tokens = []
    for f in hz:
        d = Decimal(repr(float(f))).scaleb(-exponent)
        tokens.append(format(d, "f") if rng.random() < 0.7 else format(d, "E"))
    # the truth: each token's decimal value, rounded once to the nearest double
    truth = np.array([float(Decimal(t).scaleb(exponent)) for t in tokens])
    assert np.all(np.diff(truth) > 0)
    return tokens, truth


def _pair(rng, value, fmt):
    if fmt == "RI":
        return [_number(rng, value.real), _number(rng, value.imag)]
    angle = float(np.degrees(np.angle(value)))
    if rng.random() < 0.1:
        angle += 360.0  # an angle outside (-180, 180] is still an angle
    magnitude = abs(value) if fmt == "MA" else 20 * np.log10(abs(value))
    return [_number(rng, magnitude), _number(rng, angle)]


def _option_line(rng, unit, fmt, z0, positional_only):
    """(variant's option line, whether scikit-rf reads it: it reads tokens by position)."""
    z0_text = str(int(z0)) if z0 == int(z0) and rng.random() < 0.5 else repr(z0)
    groups = [
        [_case(rng, unit)] if unit != "GHz" or rng.random() < 0.5 else [],
        [_case(rng, "S")] if rng.random() < 0.6 else [],
        [_case(rng, fmt)] if fmt != "MA" or rng.random() < 0.5 else [],
        [_case(rng, "R"), z0_text] if z0 != 50.0 or rng.random() < 0.5 else [],
    ]
    if positional_only:  # canonical order, only trailing defaults left out
        needed = max([i + 1 for i, g in enumerate(groups) if g] or [0])
        full = [[unit], ["S"], [fmt], ["R", z0_text]]
        groups = [full[i] if i < needed else [] for i in range(4)]
    elif rng.random() < 0.5:
        groups = [groups[i] for i in rng.permutation(4)]
    tokens = [t for g in groups for t in g]
    canonical = [unit, "S", fmt, "R", z0_text]
    positional = [t.lower() for t in tokens] == [t.lower() for t in canonical[: len(tokens)]]
    sep = ["\t", " ", "   "][rng.integers(3)]
    line = ("#" if rng.random() < 0.3 else "# ") + sep.join(tokens)
    if rng.random() < 0.2:
        line += " ! options"
    return line, positional


def make_variant(rng) -> Variant:
    ports = int(rng.integers(1, 3))
    unit = str(rng.choice(list(UNITS)))
    fmt = str(rng.choice(["RI", "MA", "DB"]))
    z0 = float(rng.choice([50.0, 50.0, 75.0, 25.5, 100.0]))
    n = int(rng.integers(1, 12))
    f_tokens, freq_hz = _frequencies(rng, n, UNITS[unit])
    magnitude = rng.uniform(1e-3, 1.2, (n, ports, ports))
    s = magnitude * np.exp(1j * rng.uniform(-np.pi, np.pi, (n, ports, ports)))
    data = []
    for k in range(n):
        pairs = [_pair(rng, v, fmt) for v in s[k].T.ravel()]  # S11 S21 S12 S22
        chunks = [len(pairs)]
        if ports == 2 and rng.random() < 0.5:  # wrapped at pair boundaries
            cuts = sorted(set(rng.integers(1, 4, rng.integers(1, 4)).tolist()))
            chunks = np.diff([0, *cuts, 4]).tolist()
        start = 0
        for j, size in enumerate(chunks):
            numbers = [x for p in pairs[start : start + size] for x in p]
            start += size
            lead = (" " * int(rng.integers(0, 3))) if j == 0 else "    "
            line = lead + ("\t" if rng.random() < 0.2 else " ").join(
                ([f_tokens[k]] if j == 0 else []) + numbers)
            if rng.random() < 0.2:
                line += f" ! point {k}"
            data.append(line)
        if rng.random() < 0.1:
            data.append("! a comment between frequencies")
        if rng.random() < 0.1:
            data.append("")
    comments = [c for c in ("! Date: Tuesday, 8 Nov 2022", "! Correction: ON \xb0",
                            "!", "! S-parameter data") if rng.random() < 0.5]
    plain = rng.random() < 0.35  # nothing scikit-rf cannot read
    option, skrf_option = _option_line(rng, unit, fmt, z0, plain)
    block_header = not plain and rng.random() < 0.3
    vendor_before = not plain and rng.random() < 0.25
    vendor_after = rng.random() < 0.2
    markers = not plain and rng.random() < 0.3
    lines = (["#48212!Agilent Technologies,N5225A,MY51451234,A.09.90.02"] if block_header
             else [])
    lines += comments + (["#Keysight PNA-X export"] if vendor_before else []) + [option]
    lines += (["#Trace 1 of 1"] if vendor_after else []) + data
    if markers:
        lines = ["BEGIN", *lines, "END"]
    newline = "\r\n" if rng.random() < 0.2 else "\n"
    text = newline.join(lines) + (newline if rng.random() < 0.8 else "")
    twin = "\n".join([*comments, f"# {unit} S {fmt} R {z0!r}", *data]) + "\n"
    name = "variant" + str(rng.choice([f".s{ports}p", f".S{ports}P", f".s{ports}P"]))
    skrf_ok = skrf_option and not (block_header or vendor_before or markers)
    return Variant(name, ports, text, twin, freq_hz, s, z0, skrf_ok)
