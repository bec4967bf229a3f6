"""One-port Touchstone v1 files (``.s1p``): the reference S11s of the test load and standards.

Format (Touchstone File Format Specification, version 1.1, EIA/IBIS):

* ``!`` starts a comment, to the end of the line;
* the option line ``# <unit> <parameter> <format> R <z0>`` (tokens in any order, case
  insensitive; defaults ``GHz S MA R 50``) comes before the data; only the first counts;
* a one-port data line is ``f a b``: the frequency in ``unit`` (Hz, kHz, MHz, GHz), then
  the reflection as ``RI`` (real, imaginary), ``MA`` (magnitude, angle in degrees) or
  ``DB`` (``20 log10 |S|``, angle in degrees); frequencies strictly increase.

Only S-parameters are read. :func:`write_touchstone` writes ``# Hz S RI R <z0>`` with a
header comment and 17 significant digits, so a round trip is exact.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from calibration.errors import FileFormatError

_UNITS = {"hz": 1.0, "khz": 1e3, "mhz": 1e6, "ghz": 1e9}
_FORMATS = ("ri", "ma", "db")


class TouchstoneError(FileFormatError):
    """A Touchstone file that cannot be read; the message names the file and line."""


def _options(tokens: Sequence[str], where: str) -> tuple[float, str, float]:
    scale, fmt, z0 = 1e9, "ma", 50.0
    i = 0
    while i < len(tokens):
        token = tokens[i].lower()
        if token in _UNITS:
            scale = _UNITS[token]
        elif token in _FORMATS:
            fmt = token
        elif token == "r":
            try:
                z0 = float(tokens[i + 1])
            except (IndexError, ValueError) as err:
                raise TouchstoneError(f"{where}: 'R' needs a reference impedance") from err
            i += 1
        elif token != "s":
            raise TouchstoneError(f"{where}: unsupported option {tokens[i]!r} (S-parameters only)")
        i += 1
    if not (np.isfinite(z0) and z0 > 0):
        raise TouchstoneError(f"{where}: reference impedance must be > 0, got {z0}")
    return scale, fmt, z0


def _complex(a: NDArray[np.float64], b: NDArray[np.float64], fmt: str) -> NDArray[np.complex128]:
    if fmt == "ri":
        return np.asarray(a + 1j * b, dtype=complex)
    magnitude = a if fmt == "ma" else 10.0 ** (a / 20.0)
    return np.asarray(magnitude * np.exp(1j * np.deg2rad(b)), dtype=complex)


def read_touchstone(
    path: str | Path,
) -> tuple[NDArray[np.float64], NDArray[np.complex128], float]:
    """Read a one-port Touchstone v1 file.

    Returns
    -------
    freq_hz, s11, z0
        Frequencies (Hz), complex reflection coefficients, reference impedance (ohm).
    """
    path = Path(path)
    options: tuple[float, str, float] | None = None
    rows: list[tuple[float, float, float]] = []
    for number, raw in enumerate(path.read_text(encoding="ascii").splitlines(), start=1):
        where = f"{path}:{number}"
        line = raw.split("!", 1)[0].strip()
        if not line:
            continue
        if line.startswith("#"):
            if options is None:
                options = _options(line[1:].split(), where)
            continue
        fields = line.split()
        if len(fields) != 3:
            raise TouchstoneError(f"{where}: expected 'f a b' (3 numbers), got {len(fields)}")
        try:
            f, a, b = (float(x) for x in fields)
        except ValueError as err:
            raise TouchstoneError(f"{where}: not a number in {line!r}") from err
        if not all(np.isfinite((f, a, b))):
            raise TouchstoneError(f"{where}: non-finite value in {line!r}")
        if rows and f <= rows[-1][0]:
            raise TouchstoneError(f"{where}: frequency {f} does not increase")
        rows.append((f, a, b))
    if not rows:
        raise TouchstoneError(f"{path}: no data lines")
    scale, fmt, z0 = options or _options([], str(path))
    data = np.array(rows, dtype=float)
    return data[:, 0] * scale, _complex(data[:, 1], data[:, 2], fmt), z0


def write_touchstone(
    path: str | Path, freq_hz: ArrayLike, s11: ArrayLike, z0: float = 50.0, comment: str = ""
) -> None:
    """Write a one-port Touchstone v1 file in Hz and real/imaginary format."""
    freq = np.asarray(freq_hz, dtype=float)
    gamma = np.asarray(s11, dtype=complex)
    if freq.ndim != 1 or gamma.shape != freq.shape or freq.size == 0:
        raise ValueError(f"{path}: {gamma.shape} reflections for {freq.shape} frequencies")
    if np.any(np.diff(freq) <= 0):
        raise ValueError(f"{path}: frequencies must strictly increase")
    lines = [f"! {text}" for text in (comment.splitlines() if comment else [])]
    lines += ["! one-port S-parameters written by reach-receiver", f"# Hz S RI R {z0:.17g}"]
    lines += [f"{f:.17g} {g.real:.17g} {g.imag:.17g}" for f, g in zip(freq, gamma, strict=True)]
    Path(path).write_text("\n".join(lines) + "\n", encoding="ascii")
