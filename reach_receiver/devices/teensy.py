"""Driver of the front-end microcontroller (Teensy 3.5), protocol v1 of ``firmware/PROTOCOL.md``.

Every request is one tagged line, ``#<tag> <command>``; the reply ``OK 00 #<tag> <payload>``
or ``ERR <code> #<tag> <reason>`` must carry the same tag, so a late reply to an earlier,
timed-out request is recognised and dropped. All commands set absolute states, so after a
timeout or a garbled reply the driver resynchronises (a lone LF, then a tagged ``ping``)
and repeats the request; error replies are never retried, they are the board's answer.
Interlock refusals (codes 20-22) raise :class:`~reach_receiver.errors.InterlockError`.
"""

from __future__ import annotations

import itertools
import logging
import re

from reach_receiver.devices.board import (
    DEVICE,
    FIXED_RAILS,
    MTS_STATES,
    SWITCH_POSITIONS,
    SWITCHABLE_RAILS,
    FrontEndState,
)
from reach_receiver.errors import (
    DeviceError,
    DeviceTimeout,
    InterlockError,
    ProtocolError,
)
from reach_receiver.transports.serial_port import SerialTransport

log = logging.getLogger(__name__)

PROTOCOL_VERSION = 1

#: Interlock refusals (PROTOCOL.md, "Interlocks"): the board said no on safety grounds.
INTERLOCK_CODES = frozenset({20, 21, 22})

_REPLY = re.compile(r"^(OK|ERR) (\d\d) #([A-Za-z0-9]{1,8})(?: (.*))?$")


class TeensyError(DeviceError):
    """An ``ERR`` reply from the board, with its protocol error code."""

    def __init__(self, code: int, reason: str, command: str) -> None:
        self.code = code
        self.reason = reason
        super().__init__(DEVICE, f"ERR {code:02d} {reason}", command)


class Teensy:
    """The front-end switch matrix and power rails.

    Parameters
    ----------
    transport
        The USB serial port (a :class:`SerialTransport`, or a path to make one).
    timeout_s
        Deadline of one reply. ``tec query`` waits longer (the board's own 300 ms).
    retries
        How often a request is repeated after a timeout or a garbled reply.
    """

    def __init__(
        self, transport: SerialTransport | str, timeout_s: float = 1.0, retries: int = 2
    ) -> None:
        if isinstance(transport, str):
            transport = SerialTransport(transport, DEVICE, timeout_s=timeout_s)
        self.transport = transport
        self.timeout_s = timeout_s
        self.retries = retries
        self._tags = (f"{n % 0xFFFFFF:x}" for n in itertools.count(1))
        self.identity = ""
        self.firmware = ""

    # ----------------------------------------------------------------- life cycle
    def connect(self) -> None:
        """Open the port, resynchronise and check identity and protocol version."""
        self.transport.open()
        self.resync()
        self.identity = self.command("id")
        version = dict(f.split("=", 1) for f in self.command("version").split() if "=" in f)
        if version.get("protocol") != str(PROTOCOL_VERSION):
            self.close()
            raise DeviceError(
                DEVICE, f"speaks protocol {version.get('protocol')}, need {PROTOCOL_VERSION}"
            )
        self.firmware = version.get("firmware", "?")

    def close(self) -> None:
        """Close the port (the board keeps its state)."""
        self.transport.close()

    def __enter__(self) -> Teensy:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----------------------------------------------------------------- requests
    def resync(self) -> None:
        """End any partial line on the board and drop replies up to a fresh tagged ``pong``."""
        self.transport.write(b"\n")
        self.transport.discard_input(quiet_s=0.02)
        tag = next(self._tags)
        self.transport.write(f"#{tag} ping\n".encode())
        self._read_reply(tag, "ping", self.timeout_s)

    def _read_reply(self, tag: str, command: str, timeout_s: float) -> str:
        while True:
            raw = self.transport.read_until(b"\n", timeout_s=timeout_s)
            line = raw.decode("ascii", errors="replace").rstrip("\r\n")
            match = _REPLY.match(line)
            if match is None:
                raise ProtocolError(DEVICE, f"garbled reply {line!r}", command)
            kind, code, reply_tag, text = match.groups()
            if reply_tag != tag:
                log.info("teensy: dropping stale reply %r", line)
                continue
            if kind == "ERR":
                raise TeensyError(int(code), text or "", command)
            return text or ""

    def command(self, command: str, timeout_s: float | None = None) -> str:
        """Send one request and return the payload of its ``OK`` reply.

        Raises
        ------
        InterlockError
            The board refused on safety grounds (codes 20-22).
        TeensyError
            Any other ``ERR`` reply.
        DeviceTimeout, ProtocolError
            No usable reply after ``retries`` resynchronised repeats.
        """
        wait = self.timeout_s if timeout_s is None else timeout_s
        last: DeviceError = DeviceTimeout(DEVICE, "no attempt made", command)
        for attempt in range(self.retries + 1):
            if attempt:
                log.warning("teensy: %s; resynchronising and repeating %r", last, command)
                try:
                    self.resync()
                except (DeviceTimeout, ProtocolError) as err:
                    last = err
                    continue
            tag = next(self._tags)
            self.transport.write(f"#{tag} {command}\n".encode())
            try:
                return self._read_reply(tag, command, wait)
            except TeensyError as err:
                if err.code in INTERLOCK_CODES:
                    raise InterlockError(f"teensy refused {command!r}: {err.reason}") from err
                raise
            except (DeviceTimeout, ProtocolError) as err:
                last = err
        kind = DeviceTimeout if isinstance(last, DeviceTimeout) else ProtocolError
        message = f"no valid reply after {self.retries + 1} attempts: {last}"
        raise kind(DEVICE, message, command) from last

    # ----------------------------------------------------------------- operations
    def select(self, switch: str, position: int | str) -> None:
        """Drive ``switch`` (``ms1``-``ms4``, ``mts``) to ``position`` (0 releases it)."""
        check_position(switch, position)
        payload = self.command(f"select {switch} {position}")
        if payload != f"{switch}={position}":
            raise ProtocolError(DEVICE, f"unexpected reply {payload!r}", f"select {switch}")

    def set_rail(self, rail: str, on: bool) -> None:
        """Switch a power rail; ``3v3`` and ``5v`` are refused here, before any I/O."""
        check_rail(rail)
        payload = self.command(f"rail {rail} {'on' if on else 'off'}")
        if payload != f"{rail}={int(on)}":
            raise ProtocolError(DEVICE, f"unexpected reply {payload!r}", f"rail {rail}")

    def rail(self, rail: str) -> bool:
        """Whether a rail is on."""
        check_rail(rail)
        return self.command(f"rail {rail}").endswith("=1")

    def read_state(self) -> FrontEndState:
        """Every output, read back from the board."""
        return FrontEndState.parse(self.command("state"))

    def safe(self) -> FrontEndState:
        """Put the front-end in its safe state (PROTOCOL.md) and return the state."""
        return FrontEndState.parse(self.command("safe"))

    def temperatures(self) -> dict[int, float]:
        """The MCP9808 sensors found on the I2C bus, address -> degrees C."""
        out: dict[int, float] = {}
        for item in self.command("temps").split():
            address, _, value = item.partition("=")
            try:
                out[int(address, 16)] = float(value)
            except ValueError as err:
                raise ProtocolError(DEVICE, f"malformed temperature {item!r}", "temps") from err
        return out

    def tec_send(self, frame: bytes) -> None:
        """Pass a frame to the TEC controller's UART without waiting for an answer."""
        self.command(f"tec send {frame.hex()}")

    def tec_query(self, frame: bytes, timeout_s: float = 1.0) -> bytes:
        """Pass a frame to the TEC controller and return its reply, line ending removed."""
        payload = self.command(f"tec query {frame.hex()}", timeout_s=timeout_s)
        try:
            return bytes.fromhex(payload).rstrip(b"\r\n")
        except ValueError as err:
            raise ProtocolError(DEVICE, f"reply is not hex: {payload!r}", "tec query") from err


def check_position(switch: str, position: int | str) -> None:
    """Refuse an unknown switch or an out-of-range position before anything is sent."""
    if switch == "mts":
        if position not in MTS_STATES:
            raise ValueError(f"mts position must be one of {MTS_STATES}, got {position!r}")
        return
    if switch not in SWITCH_POSITIONS:
        known = ", ".join([*SWITCH_POSITIONS, "mts"])
        raise ValueError(f"unknown switch {switch!r}; known: {known}")
    if not isinstance(position, int) or not 0 <= position <= SWITCH_POSITIONS[switch]:
        top = SWITCH_POSITIONS[switch]
        raise ValueError(f"{switch} position must be 0-{top}, got {position!r}")


def check_rail(rail: str) -> None:
    """Refuse the never-switched rails and unknown names before anything is sent."""
    if rail in FIXED_RAILS:
        raise InterlockError(f"rail {rail} is never switched (thesis table A.3)")
    if rail not in SWITCHABLE_RAILS:
        raise ValueError(f"unknown rail {rail!r}; known: {', '.join(SWITCHABLE_RAILS)}")
