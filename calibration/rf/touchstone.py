"""Touchstone S-parameter files (``.s1p``, ``.s2p``) as real VNAs write them; pure numpy.

References: *Touchstone File Format Specification*, version 1.1 (EIA/IBIS, 2002) and
version 2.0 (IBIS Open Forum, 2009); sections are named as in those documents ("TS 1.1",
"TS 2.0"). Reading (:func:`read_touchstone_network`, rules in :mod:`.touchstone_reader`):

* comments start at ``!`` anywhere on a line (TS 1.1/2.0 "Comment Lines");
* the option line ``# [unit] [parameter] [format] [R n]``: tokens in any order, case
  insensitive, each optional, defaults ``GHz S MA R 50`` (TS 1.1/2.0 "Option Line"); units
  ``Hz kHz MHz GHz``, formats ``RI MA DB``; parameter ``S`` only (``Y Z G H`` are refused);
* version 1.x data (TS 1.1 "Data Lines"; TS 2.0 "[Network Data]", "1-port and 2-port
  Networks"): a frequency, then complex pairs, two-ports in the order ``S11 S21 S12 S22``;
  frequencies strictly increase; angles are in degrees; ``DB`` is ``20 log10 |S|``;
* version 2.0 keyword files: ``[Version]``, ``[Number of Ports]``, ``[Two-Port Data
  Order]``, ``[Number of Frequencies]``, ``[Reference]``, ``[Matrix Format] Full``,
  ``[Begin Information]``/``[End Information]``, ``[Network Data]``, ``[End]``;
* the number of ports is the extension's (``.s1p``/``.s2p``, any case; TS 1.1
  "General Syntax Rules and Guidelines") or ``[Number of Ports]``; one- and two-ports only;
* what real instruments add: ``BEGIN``/``END`` lines, and ``#`` lines that are not
  option lines (an IEEE 488.2 block header such as ``#48212`` glued to the first line of a
  file fetched over SCPI, ``#48212!Agilent Technologies,...``): see the reader's module.

Every error is a :class:`TouchstoneError` whose message starts ``file:line:``.

Writing (:func:`write_touchstone_network`, :func:`write_touchstone`): version 1.1, one line
per frequency, ``RI``, ``MA`` or ``DB`` in a chosen unit, written to a temporary file in the
same directory and renamed over the target (atomic). Frequencies are the shortest decimal
that round-trips the Hz value, with the decimal point moved for the unit, so they read back
bit for bit in every unit; ``RI`` values read back bit for bit, ``MA``/``DB`` to the
rounding of the polar conversion (about 1e-15 relative).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from decimal import Decimal
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.atomic_file import write_atomically
from .touchstone_reader import TouchstoneError, parse_touchstone

__all__ = [
    "TouchstoneData",
    "TouchstoneError",
    "read_touchstone",
    "read_touchstone_network",
    "write_touchstone",
    "write_touchstone_network",
]

_UNIT_EXPONENTS = {"Hz": 0, "kHz": 3, "MHz": 6, "GHz": 9}
_FORMATS = ("RI", "MA", "DB")


@dataclass(frozen=True, eq=False)
class TouchstoneData:
    """An S-parameter network as read from (or to be written to) a Touchstone file.

    Attributes
    ----------
    freq_hz
        Frequencies in Hz, strictly increasing, shape ``(n_freq,)``.
    s
        S-parameters, shape ``(n_freq, n_ports, n_ports)``, ``s[:, i, j]`` is
        ``S(i+1)(j+1)`` whatever order the file stored them in.
    z0
        Reference impedance (ohm), the same for every port.
    comments
        The text after each ``!`` in the file, in order (empty comments left out).
    """

    freq_hz: NDArray[np.float64]
    s: NDArray[np.complex128]
    z0: float = 50.0
    comments: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        freq = np.asarray(self.freq_hz, dtype=float)
        s = np.asarray(self.s, dtype=complex)
        if freq.ndim != 1 or freq.size == 0:
            raise ValueError(f"freq_hz must be a non-empty 1-D array, got shape {freq.shape}")
        if s.ndim != 3 or s.shape[0] != freq.size or s.shape[1] != s.shape[2]:
            raise ValueError(f"s must have shape ({freq.size}, n, n), got {s.shape}")
        if s.shape[1] not in (1, 2):
            raise ValueError(f"only one- and two-ports, got {s.shape[1]} ports")
        if not (np.all(np.isfinite(freq)) and np.all(np.isfinite(s))):
            raise ValueError("frequencies and S-parameters must be finite")
        if freq[0] < 0 or np.any(np.diff(freq) <= 0):
            raise ValueError("frequencies must be >= 0 and strictly increase")
        if not (np.isfinite(self.z0) and self.z0 > 0):
            raise ValueError(f"reference impedance must be > 0, got {self.z0}")
        object.__setattr__(self, "freq_hz", freq)
        object.__setattr__(self, "s", s)
        object.__setattr__(self, "z0", float(self.z0))
        object.__setattr__(self, "comments", tuple(self.comments))

    @property
    def n_ports(self) -> int:
        """Number of ports (1 or 2)."""
        return int(self.s.shape[1])


def read_touchstone_network(path: str | Path) -> TouchstoneData:
    """Read a one- or two-port Touchstone file (version 1.x or 2.0).

    Raises
    ------
    TouchstoneError
        For anything the file does not say clearly; the message starts ``file:line:``.
    """
    return TouchstoneData(*parse_touchstone(Path(path)))


def read_touchstone(
    path: str | Path,
) -> tuple[NDArray[np.float64], NDArray[np.complex128], float]:
    """Read a one-port Touchstone file.

    Returns
    -------
    freq_hz, s11, z0
        Frequencies (Hz), complex reflection coefficients, reference impedance (ohm).

    Raises
    ------
    TouchstoneError
        As :func:`read_touchstone_network`, and for a file of more than one port.
    """
    network = read_touchstone_network(path)
    if network.n_ports != 1:
        raise TouchstoneError(
            f"{path}: a {network.n_ports}-port file, not a one-port; "
            "read it with read_touchstone_network"
        )
    return network.freq_hz, network.s[:, 0, 0], network.z0


def write_touchstone(
    path: str | Path,
    freq_hz: ArrayLike,
    s11: ArrayLike,
    z0: float = 50.0,
    comment: str = "",
    *,
    fmt: str = "RI",
    unit: str = "Hz",
) -> None:
    """Write a one-port Touchstone file (see :func:`write_touchstone_network`)."""
    gamma = np.asarray(s11, dtype=complex)
    freq = np.asarray(freq_hz, dtype=float)
    if gamma.ndim != 1 or gamma.shape != freq.shape:
        raise ValueError(f"{path}: {gamma.shape} reflections for {freq.shape} frequencies")
    comments = tuple(comment.splitlines()) if comment else ()
    try:
        network = TouchstoneData(freq, gamma[:, None, None], z0, comments)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from err
    write_touchstone_network(path, network, fmt=fmt, unit=unit)


def write_touchstone_network(
    path: str | Path, network: TouchstoneData, *, fmt: str = "RI", unit: str = "Hz"
) -> None:
    """Write ``network`` as a Touchstone 1.1 file, atomically.

    Parameters
    ----------
    path
        Target file; its extension must be ``.s1p`` or ``.s2p`` (any case) to match the
        number of ports, so that the file can be read back.
    network
        Frequencies, S-parameters, reference impedance; its ``comments`` become the
        leading ``!`` lines (ASCII only: TS 1.1/2.0 "General Syntax Rules").
    fmt
        ``"RI"`` (default, exact), ``"MA"`` or ``"DB"`` (angles in degrees).
    unit
        Frequency unit of the file: ``"Hz"`` (default), ``"kHz"``, ``"MHz"`` or ``"GHz"``.
    """
    path = Path(path)
    fmt_key = fmt.upper()
    units = {name.lower(): name for name in _UNIT_EXPONENTS}
    if fmt_key not in _FORMATS or unit.lower() not in units:
        raise ValueError(f"{path}: format {fmt!r} or unit {unit!r} not one of {_FORMATS}, "
                         f"{tuple(_UNIT_EXPONENTS)}")
    unit_name = units[unit.lower()]
    ports = network.n_ports
    if path.suffix.lower() != f".s{ports}p":
        raise ValueError(f"{path}: a {ports}-port file must be named *.s{ports}p")
    pairs = network.s.transpose(0, 2, 1).reshape(len(network.freq_hz), -1)  # S11 S21 S12 S22
    if fmt_key == "DB" and np.any(pairs == 0):
        raise ValueError(f"{path}: |S| = 0 has no dB value; write it as RI or MA")
    what = "one-port" if ports == 1 else "two-port (S11 S21 S12 S22)"
    lines = [f"! {text}" for text in network.comments]
    lines += [f"! {what} S-parameters written by reach-receiver",
              f"# {unit_name} S {fmt_key} R {network.z0!r}"]
    exponent = _UNIT_EXPONENTS[unit_name]
    for f, row in zip(network.freq_hz, pairs, strict=True):
        fields = [_frequency_text(float(f), exponent)]
        for value in row:
            fields += _pair_text(complex(value), fmt_key)
        lines.append(" ".join(fields))
    text = "\n".join(lines) + "\n"
    try:
        data = text.encode("ascii")
    except UnicodeEncodeError as err:
        raise ValueError(f"{path}: Touchstone files are ASCII; a comment is not") from err
    write_atomically(path, data)


def _frequency_text(freq_hz: float, exponent: int) -> str:
    """The shortest decimal of ``freq_hz`` with its point moved ``exponent`` places left."""
    return format(Decimal(repr(freq_hz)).scaleb(-exponent), "f")


def _pair_text(value: complex, fmt: str) -> list[str]:
    if fmt == "RI":
        a, b = value.real, value.imag
    else:
        magnitude = abs(value)
        a = magnitude if fmt == "MA" else 20.0 * float(np.log10(magnitude))
        b = float(np.degrees(np.angle(value)))
    return [repr(float(a)), repr(float(b))]


