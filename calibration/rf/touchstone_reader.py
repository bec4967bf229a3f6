"""The Touchstone reader behind :func:`calibration.rf.touchstone.read_touchstone_network`.

Sections cited are those of the Touchstone File Format Specification 1.1 ("TS 1.1") and 2.0
("TS 2.0"). Every error is a :class:`TouchstoneError` reading ``file:line: message``.

Lines
    ``!`` starts a comment, to the end of the line ("Comment Lines"); blank lines are
    skipped. ``BEGIN`` or ``END`` alone on a line (any case) are instrument markers, not
    Touchstone: ``BEGIN`` is skipped before the data, ``END`` ends the file (only comments
    may follow). On line 1 an IEEE 488.2 definite-length block header (``#``, a digit
    ``n``, ``n`` digits: ``#48212``, what a file fetched over SCPI starts with) is removed
    and the rest of the line read as usual.

Which ``#`` line is the option line ("Option Line"; the rule for what the specification
does not foresee is ours)
    A ``#`` line whose first token is an option word (``Hz kHz MHz GHz S Y Z G H MA DB RI
    R``), or that has none, is an option line and must be valid throughout: an unknown
    token, a repeated kind, ``R`` without a value or a parameter other than ``S`` is an
    error, never a reason to skip it. Any other ``#`` line (``#48212``, ``#Agilent ...``)
    is a vendor line, skipped. The first option line counts; the specification says to
    ignore later ones, and we do if they say the same, but refuse a file whose option lines
    disagree (which did the writer mean?). Every file has one, before the data (TS 1.1:
    "Each Touchstone data file must contain an option line"); if it is missing, the
    message lists the vendor lines skipped, in case one of them was meant.

Option line
    ``# [unit] [parameter] [format] [R n]``: tokens in any order and case, each optional,
    defaults ``GHz S MA R 50``. ``R`` may take one value per port (TS 2.1's reading of
    TS 1.1 files) if they are all equal.

Network data (TS 1.1 "Data Lines"; TS 2.0 "[Network Data]", "1-port and 2-port Networks")
    A frequency, then complex pairs: ``RI`` real, imaginary; ``MA`` magnitude, angle
    (degrees); ``DB`` ``20 log10 |S|``, angle. A one-port frequency is one line ``f a b``.
    A two-port's is ``f S11 S21 S12 S22`` (version 1, and TS 2.0 ``[Two-Port Data Order]
    21_12``; ``12_21`` is ``S11 S12 S21 S22``), possibly wrapped over lines; a pair is never
    split, so a line with an odd count of numbers starts a frequency and an even count
    continues one. Numbers are decimal (``1``, ``-.5``, ``1.0E+06``); frequencies are >= 0
    and strictly increase (TS 1.1 "Data Lines", rule 4); a frequency is scaled to Hz by
    moving its decimal point (``123.45678`` MHz is the double nearest 123456780 Hz).
    Two-port noise parameters are refused.

Ports
    Version 1: the extension, ``.s1p`` or ``.s2p`` in any case (TS 1.1 "General Syntax
    Rules and Guidelines"). TS 2.0: ``[Number of Ports]``; an ``.sNp`` extension must agree.

TS 2.0 keywords
    Read: ``[Version] 2.0`` (before the option line), ``[Number of Ports]``, ``[Two-Port
    Data Order]`` (required for two-ports), ``[Number of Frequencies]`` (required, checked),
    ``[Reference]`` (one value per port, all equal; replaces ``R``), ``[Matrix Format]
    Full``, ``[Begin Information]`` to ``[End Information]`` (skipped), ``[Network Data]``,
    ``[End]``. Refused: ``[Noise Data]``, ``[Number of Noise Frequencies]``, ``[Mixed-Mode
    Order]``, two-port ``Lower``/``Upper`` matrices, unknown keywords.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..core.errors import FileFormatError

_UNITS = {"hz": 0, "khz": 3, "mhz": 6, "ghz": 9}  # decimal exponent to Hz
_FORMATS = ("ri", "ma", "db")
_PARAMETERS = ("s", "y", "z", "g", "h")
_OPTION_WORDS = frozenset((*_UNITS, *_FORMATS, *_PARAMETERS, "r"))
_NUMBER = re.compile(r"([+-]?(?:\d+\.?\d*|\.\d+))(?:[eE]([+-]?\d+))?")
_KEYWORD = re.compile(r"\[([^\]]*)\](.*)")


class TouchstoneError(FileFormatError):
    """A Touchstone file that cannot be read; the message names the file and line."""


@dataclass(frozen=True)
class Options:
    """The option line: frequency unit (as a power of ten of Hz), format, reference."""

    exponent: int = 9
    fmt: str = "ma"
    z0: float = 50.0


Parsed = tuple[NDArray[np.float64], NDArray[np.complex128], float, tuple[str, ...]]


def parse_touchstone(path: Path) -> Parsed:
    """Frequencies (Hz), S ``(n_freq, n, n)``, reference (ohm) and comments of ``path``."""
    return _Reader(path).read()


def parse_options(tokens: list[str], where: str) -> Options:
    """The option line's tokens (after ``#``) as :class:`Options`; raise on anything wrong."""
    seen: dict[str, str] = {}
    exponent, fmt, z0 = 9, "ma", 50.0
    i = 0
    while i < len(tokens):
        token, word = tokens[i], tokens[i].lower()
        if word in _UNITS:
            kind, exponent = "frequency unit", _UNITS[word]
        elif word in _FORMATS:
            kind, fmt = "format", word
        elif word in _PARAMETERS:
            kind = "parameter"
            if word != "s":
                raise TouchstoneError(f"{where}: unsupported option {token!r}: only "
                                      "S-parameters are read (Y, Z, G, H are refused)")
        elif word == "r":
            kind, values = "reference", list[float]()
            while i + 1 < len(tokens) and _NUMBER.fullmatch(tokens[i + 1]):
                values.append(float(tokens[i + 1]))
                i += 1
            if not values:
                raise TouchstoneError(f"{where}: 'R' needs a reference impedance")
            if len(set(values)) > 1:
                raise TouchstoneError(f"{where}: per-port references {values} differ; "
                                      "only one reference impedance for all ports is read")
            z0 = values[0]
        else:
            raise TouchstoneError(f"{where}: unknown option token {token!r} "
                                  "(option line: # [Hz|kHz|MHz|GHz] [S] [MA|DB|RI] [R n])")
        if kind in seen:
            raise TouchstoneError(f"{where}: two of {kind}: {seen[kind]!r} and {token!r}")
        seen[kind] = token
        i += 1
    if not (np.isfinite(z0) and z0 > 0):
        raise TouchstoneError(f"{where}: reference impedance must be > 0, got {z0}")
    return Options(exponent, fmt, z0)


def _decode(raw: bytes) -> str:
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:  # a degree sign or an ohm in a vendor's comment
        return raw.decode("latin-1")


def _strip_block_header(line: str) -> str:
    match = re.match(r"#([1-9])(\d*)", line)
    if match and len(match[2]) >= int(match[1]):
        return line[2 + int(match[1]) :]
    return line


class _Reader:
    """One pass over a file's lines; state is what has been seen so far."""

    def __init__(self, path: Path) -> None:
        self.path = path
        suffix = re.fullmatch(r"\.s(\d+)p", path.suffix.lower())
        self.ext_ports = int(suffix[1]) if suffix else None
        self.ports: int | None = None
        self.version: str | None = None
        self.options: Options | None = None
        self.option_line = 0
        self.vendor_lines: list[int] = []
        self.began = False
        self.ended: tuple[str, int] | None = None
        self.section = "header"  # version 2: header, info, network
        self.order_21_12, self.order_given = True, False  # version 1: S11 S21 S12 S22
        self.n_freq: tuple[int, int] | None = None  # (count, line)
        self.reference: list[float] | None = None  # [Reference], on reference_line
        self.reference_line = 0
        self.freq_hz: list[float] = []
        self.rows: list[list[float]] = []
        self.current: list[float] | None = None
        self.current_lines = (0, 0)
        self.comments: list[str] = []
        self.number = 0

    def error(self, message: str, line: int | None = None) -> TouchstoneError:
        return TouchstoneError(f"{self.path}:{self.number if line is None else line}: {message}")

    def read(self) -> Parsed:
        text = _decode(self.path.read_bytes())
        for self.number, raw in enumerate(text.splitlines(), start=1):
            if self.number == 1:
                raw = _strip_block_header(raw)
            body, _, comment = raw.partition("!")
            if comment.strip():
                self.comments.append(comment.strip())
            line = body.strip()
            if line:
                self.line(line)
        return self.finish()

    def line(self, line: str) -> None:
        if self.ended is not None:
            raise self.error(f"{line!r} after {self.ended[0]} on line {self.ended[1]}")
        if self.section == "info":
            if " ".join(line.lower().split()) == "[end information]":
                self.section = "header"
            return
        word = line.upper()
        if word == "BEGIN":
            if self.began or self.freq_hz or self.current is not None:
                raise self.error("BEGIN after the data began")
            self.began = True
        elif word == "END":
            self.ended = ("END", self.number)
        elif line.startswith("["):
            self.keyword(line)
        elif line.startswith("#"):
            self.option_line_or_vendor(line[1:].split())
        else:
            self.data(line.split())

    def need_ports(self) -> int:
        if self.ports is None:
            if self.version is not None:
                raise self.error("[Number of Ports] must come before the data")
            if self.ext_ports is None:
                raise self.error("cannot tell the number of ports: a version 1 file is named "
                                 "*.s1p or *.s2p (or starts with [Version] 2.0)")
            if self.ext_ports not in (1, 2):
                raise self.error(f"only one- and two-ports are read, not {self.ext_ports}")
            self.ports = self.ext_ports
        return self.ports

    def option_line_or_vendor(self, tokens: list[str]) -> None:
        if tokens and tokens[0].lower() not in _OPTION_WORDS:
            self.vendor_lines.append(self.number)
            return
        where = f"{self.path}:{self.number}"
        options = parse_options(tokens, where)
        if self.options is None:
            if self.freq_hz or self.current is not None:
                raise self.error("option line after the data; it must come before them")
            self.options, self.option_line = options, self.number
        elif options != self.options:
            raise self.error(f"option line differs from the one on line {self.option_line}: "
                             "which one holds? (the specification ignores the second)")

    def keyword(self, line: str) -> None:
        match = _KEYWORD.fullmatch(line)
        if match is None:
            raise self.error(f"unterminated keyword {line!r}")
        name, args = " ".join(match[1].lower().split()), match[2].split()
        if name == "version":
            if self.version is not None or self.options is not None or self.freq_hz:
                raise self.error("[Version] must be the first keyword, before the option line")
            if args not in (["2.0"], ["2.1"]):
                raise self.error(f"unsupported [Version] {' '.join(args)!r} (2.0 is read)")
            self.version = args[0]
            return
        if self.version is None:
            raise self.error(f"keyword [{match[1]}] in a version 1 file (no [Version] 2.0)")
        if name == "number of ports":
            n = self.count(args, name)
            if n not in (1, 2):
                raise self.error(f"only one- and two-ports are read, not {n}")
            if self.ext_ports is not None and self.ext_ports != n:
                raise self.error(f"[Number of Ports] {n} but the extension is .s{self.ext_ports}p")
            self.ports = n
        elif name == "two-port data order":
            if args not in (["12_21"], ["21_12"]):
                raise self.error(f"[Two-Port Data Order] is 12_21 or 21_12, not {args}")
            self.order_21_12, self.order_given = args == ["21_12"], True
        elif name == "number of frequencies":
            self.n_freq = (self.count(args, name), self.number)
        elif name == "reference":
            self.reference, self.reference_line = [], self.number
            self.add_reference(args)
        elif name == "matrix format":
            shape = " ".join(args).lower()
            if shape != "full" and not (shape in ("lower", "upper") and self.need_ports() == 1):
                raise self.error(f"[Matrix Format] {' '.join(args)!r}: only Full is read")
        elif name == "begin information":
            self.section = "info"
        elif name == "network data":
            self.start_network_data()
        elif name == "end":
            self.ended = ("[End]", self.number)
        elif name in ("noise data", "number of noise frequencies", "mixed-mode order"):
            raise self.error(f"[{match[1]}]: noise and mixed-mode data are not read")
        else:
            raise self.error(f"unknown keyword [{match[1]}]")

    def count(self, args: list[str], name: str) -> int:
        if len(args) != 1 or not args[0].isdigit() or int(args[0]) < 1:
            raise self.error(f"[{name}] needs a positive integer, got {' '.join(args)!r}")
        return int(args[0])

    def add_reference(self, tokens: list[str]) -> None:
        assert self.reference is not None
        self.reference += [self.number_of(token) for token in tokens]
        if self.ports is not None and len(self.reference) > self.ports:
            raise self.error(f"[Reference] has {len(self.reference)} values for {self.ports} ports")

    def start_network_data(self) -> None:
        ports = self.need_ports()
        if self.options is None:
            raise self.error("[Network Data] before any option line")
        if ports == 2 and not self.order_given:
            raise self.error("a two-port needs [Two-Port Data Order] before [Network Data]")
        if self.n_freq is None:
            raise self.error("[Number of Frequencies] is required before [Network Data]")
        if self.reference is not None:
            if len(self.reference) != ports:
                raise self.error(f"[Reference] on line {self.reference_line} has "
                                 f"{len(self.reference)} values for {ports} ports")
            if len(set(self.reference)) > 1 or not self.reference[0] > 0:
                raise self.error(f"[Reference] {self.reference}: one impedance > 0 for all "
                                 "ports is read", self.reference_line)
        self.section = "network"

    def number_of(self, token: str) -> float:
        if not _NUMBER.fullmatch(token):
            raise self.error(f"not a number: {token!r}")
        value = float(token)
        if not np.isfinite(value):
            raise self.error(f"number out of range: {token!r}")
        return value

    def data(self, tokens: list[str]) -> None:
        if self.version is not None and self.section != "network":
            if self.section == "header" and self.reference is not None and self.ports:
                self.add_reference(tokens)  # [Reference] values wrapped onto more lines
                return
            raise self.error("network data before [Network Data]")
        ports = self.need_ports()
        if self.options is None:
            skipped = f"; skipped vendor lines {self.vendor_lines}" if self.vendor_lines else ""
            raise self.error(f"data before any option line ('# <unit> S <format> R <z0>')"
                             f"{skipped}")
        values = [self.number_of(token) for token in tokens]
        width = 1 + 2 * ports * ports
        if ports == 1 and len(values) != 3:
            raise self.error(f"expected 'f a b' (3 numbers), got {len(values)}")
        if len(values) > width:
            raise self.error(f"too many values: {len(values)} numbers on a line; a two-port "
                             "frequency has 9 (f, then S11 S21 S12 S22 as pairs)")
        if len(values) % 2:  # starts a frequency
            self.close()
            self.start(tokens[0], len(values))
            self.current, self.current_lines = values[1:], (self.number, self.number)
        else:
            if self.current is None or len(self.current) == width - 1:
                raise self.error(f"too few or too many values: {len(values)} numbers neither start"
                                 " a frequency (f and pairs) nor continue an unfinished one")
            self.current += values
            self.current_lines = (self.current_lines[0], self.number)
            if len(self.current) > width - 1:
                raise self.error(f"too many values: the frequency of line "
                                 f"{self.current_lines[0]} reaches {len(self.current) + 1} "
                                 "numbers; a two-port frequency has 9")

    def start(self, token: str, count: int) -> None:
        assert self.options is not None
        match = _NUMBER.fullmatch(token)
        assert match is not None
        freq = float(f"{match[1]}e{int(match[2] or 0) + self.options.exponent}")
        if not 0 <= freq < np.inf:
            raise self.error(f"frequency {token} is negative or out of range")
        if self.freq_hz and freq <= self.freq_hz[-1]:
            noise = self.ports == 2 and self.version is None and count == 5
            previous = self.freq_hz[-1] / 10.0**self.options.exponent
            raise self.error(f"frequency {float(token)} does not increase (previous {previous})"
                             + ("; two-port noise parameters are not read" if noise else ""))
        self.freq_hz.append(freq)

    def close(self) -> None:
        if self.current is None:
            return
        width = 2 * self.need_ports() ** 2
        first, last = self.current_lines
        if len(self.current) < width:
            span = f"line {first}" if first == last else f"lines {first}-{last}"
            raise self.error(f"too few values: {span} hold {len(self.current) + 1} numbers; a "
                             "two-port frequency has 9 (f, then S11 S21 S12 S22 as pairs)", first)
        self.rows.append(self.current)
        self.current = None

    def finish(self) -> Parsed:
        self.close()
        if self.section == "info":
            raise self.error("[Begin Information] without [End Information]")
        if not self.rows:
            raise self.error("no data lines")
        assert self.options is not None
        assert self.ports is not None
        if self.n_freq is not None and self.n_freq[0] != len(self.rows):
            raise self.error(f"[Number of Frequencies] is {self.n_freq[0]} but the file has "
                             f"{len(self.rows)}", self.n_freq[1])
        raw = np.array(self.rows, dtype=float)
        flat = raw.view(np.complex128)  # (n_freq, pairs): exact for RI
        if self.options.fmt != "ri":
            magnitude = flat.real if self.options.fmt == "ma" else 10.0 ** (flat.real / 20.0)
            flat = np.asarray(magnitude * np.exp(1j * np.deg2rad(flat.imag)), dtype=complex)
        s = flat.reshape(len(self.rows), self.ports, self.ports)
        if self.order_21_12:  # S11 S21 S12 S22: the reshape put S21 at [0, 1]
            s = s.transpose(0, 2, 1)
        z0 = self.reference[0] if self.reference else self.options.z0
        freq = np.array(self.freq_hz, dtype=float)
        return freq, np.ascontiguousarray(s), z0, tuple(self.comments)
