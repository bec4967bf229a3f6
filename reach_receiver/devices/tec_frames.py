r"""Frames of the Electron Dynamics TC-series (TC-M-U-10A) serial protocol.

Pure functions and values: build a request, check and split a reply, decode the status
reply into :class:`TecStatus`. No I/O.

Wire format (19200 baud, 8N1), as implemented by MSL's ``msl-equipment``
(``msl/equipment/resources/electron_dynamics/tc_series.py``)::

    request  = SOH letter LL data CC
    reply    = SOH letter LL data CC CR LF

``SOH`` is ``\x01``; ``letter`` the command; ``LL`` the length of ``data`` as two decimal
digits; ``data`` a run of fields, each ended by ``;`` (empty in a get request); ``CC`` two
hexadecimal digits (upper case when we send) of the checksum::

    CC = (sum of the character codes of letter + LL + data  +  1)  &  0xFF

The leading SOH and the trailing CR LF are not summed. Commands come in set/get pairs
(:data:`SET_TO_GET`); a set gets no reply, a get is sent with empty data. Numbers are
sent with three decimals (``%.3f``), integer selectors as plain integers.

Status ``j`` fields: setpoint; temperature; controlled (0/1); output (-100..100 %);
alarm type; fault bits (0 ADC, 1 ADCR, 2 VDC limit, 3 temperature limit, 4 inhibited);
temperature OK (0/1); supply voltage; version; test cycles; test mode completed.

Not confirmed by the source: that ``LL`` of a reply equals the length of its data (MSL
never checks it), and that a reply carries the letter of the get it answers. Both are
checked here because they catch truncated and stale replies; :func:`parse_frame` takes
``check_length=False`` and the driver ``strict_replies=False`` should a real controller
disagree.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

#: Start of a frame (ASCII SOH).
START = b"\x01"
#: End of a reply.
TERMINATOR = b"\r\n"
#: Set command -> the get command that reads the same parameters back.
SET_TO_GET: dict[str, str] = {
    "a": "b",  # control: type;p;i;d;d_filter;dead_band;power_up_state;
    "c": "d",  # alarm: type;min;max;ok_min;ok_max;limit_min;limit_max;
    "e": "f",  # sensor: sensor;x2;x;c;unit;averaging;[rl;]
    "g": "h",  # output: polarity;min;max;frequency;
    "i": "q",  # setpoint: method;value;pot_range;pot_offset;
}
#: Set commands without a get partner: output drive ``m`` (mode;value;).
SET_ONLY = frozenset({"m"})
#: Get commands without a set partner: status ``j``.
GET_ONLY = frozenset({"j"})
#: Largest data that the two-digit length field can describe.
MAX_DATA_LENGTH = 99
#: Bit of the status fault word -> name of the :class:`TecFaults` field.
FAULT_BITS = {0: "adc", 1: "adcr", 2: "vdc_limit", 3: "temperature_limit", 4: "inhibited"}

Field = int | float | str


class FrameError(ValueError):
    """A frame that is malformed, truncated or fails its checksum."""


@dataclass(frozen=True)
class TecFrame:
    """A checked frame: its command letter and data fields (without the ``;``)."""

    command: str
    fields: tuple[str, ...]


def checksum(body: str) -> int:
    """Checksum of ``letter + LL + data``: ``(sum of char codes + 1) & 0xFF``."""
    return (sum(map(ord, body)) + 1) & 0xFF


def format_fields(values: Sequence[Field]) -> str:
    """Join ``values`` as the controller expects: each ended by ``;``.

    Integers (and booleans) are written as ``%d``, floats as ``%.3f``, strings as given.
    """
    parts = []
    for value in values:
        if isinstance(value, bool | int):
            parts.append(f"{int(value)};")
        elif isinstance(value, float):
            parts.append(f"{value:.3f};")
        else:
            if ";" in value or not value.isascii():
                raise ValueError(f"field {value!r} is not a plain ASCII field")
            parts.append(f"{value};")
    return "".join(parts)


def _body(command: str, data: str) -> str:
    if len(command) != 1 or not command.isascii() or not command.isalpha():
        raise ValueError(f"command must be one ASCII letter, got {command!r}")
    if len(data) > MAX_DATA_LENGTH or not data.isascii():
        raise ValueError(f"data must be ASCII of at most {MAX_DATA_LENGTH} chars: {data!r}")
    return f"{command}{len(data):02d}{data}"


def build_frame(command: str, data: str = "") -> bytes:
    """A request frame: ``SOH letter LL data CC`` (no terminator is sent)."""
    body = _body(command, data)
    return START + f"{body}{checksum(body):02X}".encode("ascii")


def build_reply(command: str, data: str) -> bytes:
    """A reply frame as the controller sends it, with its ``CR LF``."""
    return build_frame(command, data) + TERMINATOR


def parse_frame(frame: bytes, check_length: bool = True) -> TecFrame:
    """Check a frame (request, or reply with or without its ``CR LF``) and split it.

    Raises
    ------
    FrameError
        If the frame does not start with SOH, is shorter than a frame can be, is not
        ASCII, has a length field that is not two digits or (``check_length``) disagrees
        with the data, or fails its checksum.
    """
    if frame.endswith(TERMINATOR):
        frame = frame[: -len(TERMINATOR)]
    if not frame.startswith(START):
        raise FrameError(f"frame does not start with SOH: {frame[:40]!r}")
    if len(frame) < 6:
        raise FrameError(f"frame too short ({len(frame)} bytes): {frame!r}")
    try:
        text = frame[1:].decode("ascii")
    except UnicodeDecodeError as err:
        raise FrameError(f"frame is not ASCII: {frame[:40]!r}") from err
    body, sent = text[:-2], text[-2:]
    command, length, data = body[0], body[1:3], body[3:]
    if not length.isdigit():
        raise FrameError(f"length field {length!r} is not two decimal digits")
    if check_length and int(length) != len(data):
        raise FrameError(f"length field says {int(length)} bytes, data has {len(data)}")
    try:
        received = int(sent, 16)
    except ValueError as err:
        raise FrameError(f"checksum field {sent!r} is not hexadecimal") from err
    expected = checksum(body)
    if received != expected:
        raise FrameError(f"checksum mismatch: got {sent!r}, expected {expected:02X}")
    fields = data.split(";")
    if fields[-1] == "":
        fields.pop()
    return TecFrame(command=command, fields=tuple(fields))


def split_requests(buffer: bytearray) -> list[bytes]:
    """Cut complete request frames off the front of ``buffer`` (which is consumed).

    Bytes before a SOH are dropped; an incomplete frame stays in the buffer. Used by
    the simulator, which has to find frame boundaries from the length field because a
    request carries no terminator.
    """
    frames: list[bytes] = []
    while True:
        start = buffer.find(START)
        if start < 0:
            buffer.clear()
            return frames
        del buffer[:start]
        if len(buffer) < 4:
            return frames
        length = bytes(buffer[2:4])
        if not length.isdigit():
            del buffer[:1]  # not a frame start after all; resynchronise on the next SOH
            continue
        total = 4 + int(length) + 2
        if len(buffer) < total:
            return frames
        frames.append(bytes(buffer[:total]))
        del buffer[:total]


@dataclass(frozen=True)
class TecFaults:
    """The fault word of the status reply, bit by bit."""

    adc: bool
    adcr: bool
    vdc_limit: bool
    temperature_limit: bool
    inhibited: bool
    raw: int

    @classmethod
    def from_bits(cls, bits: int) -> TecFaults:
        """Decode bits 0 (ADC), 1 (ADCR), 2 (VDC limit), 3 (temperature limit), 4 (inhibited)."""
        flags = {name: bool(bits >> bit & 1) for bit, name in FAULT_BITS.items()}
        return cls(raw=bits, **flags)

    @property
    def active(self) -> tuple[str, ...]:
        """Names of the faults that are set (unknown bits as ``bitN``)."""
        names = [name for bit, name in FAULT_BITS.items() if self.raw >> bit & 1]
        unknown = self.raw & ~sum(1 << bit for bit in FAULT_BITS)
        names += [f"bit{bit}" for bit in range(unknown.bit_length()) if unknown >> bit & 1]
        return tuple(names)


@dataclass(frozen=True)
class TecStatus:
    """The status reply ``j``; temperatures are in the controller's configured unit."""

    setpoint: float
    temperature: float
    controlled: bool
    output_percent: float
    alarm_type: int
    faults: TecFaults
    temperature_ok: bool
    supply_v: float
    version: str
    test_cycles: int
    test_mode_completed: bool

    @classmethod
    def from_fields(cls, fields: Sequence[str]) -> TecStatus:
        """Decode the eleven fields; :class:`ValueError` if any is missing or malformed."""
        if len(fields) < 11:
            raise ValueError(f"status has {len(fields)} fields, expected 11")
        return cls(
            setpoint=number_field(fields[0]),
            temperature=number_field(fields[1]),
            controlled=flag_field(fields[2]),
            output_percent=number_field(fields[3]),
            alarm_type=integer_field(fields[4]),
            faults=TecFaults.from_bits(integer_field(fields[5])),
            temperature_ok=flag_field(fields[6]),
            supply_v=number_field(fields[7]),
            version=fields[8],
            test_cycles=integer_field(fields[9]),
            test_mode_completed=flag_field(fields[10]),
        )


def number_field(text: str) -> float:
    """A finite number field; :class:`ValueError` otherwise."""
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"not a finite number: {text!r}")
    return value


def integer_field(text: str) -> int:
    """An integer field (``1`` or ``1.000``); :class:`ValueError` otherwise."""
    value = number_field(text)
    if value != int(value):
        raise ValueError(f"not an integer: {text!r}")
    return int(value)


def flag_field(text: str) -> bool:
    """A 0/1 field as a bool; :class:`ValueError` otherwise."""
    value = integer_field(text)
    if value not in (0, 1):
        raise ValueError(f"not a 0/1 flag: {text!r}")
    return bool(value)
