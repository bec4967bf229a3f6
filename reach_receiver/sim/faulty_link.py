"""A faulty serial link between a driver and a simulated instrument, for fault tests.

The front-end's USB runs over 100 m of fibre through a USB-to-fibre extender; bytes can
be lost or mangled, and a board can stop answering. :class:`FaultyLink` sits between a
driver and a line-based simulator (the Teensy firmware's pty): the driver opens
:attr:`FaultyLink.port`, the link forwards each request line to the instrument's port and
its reply line back, and on demand garbles, truncates, delays or swallows the next replies.
Nothing of the driver is touched; it sees exactly what a bad cable would show it.
"""

from __future__ import annotations

import enum
import logging
import threading
import time

import serial

from reach_receiver.sim.pty_device import PtyDevice

log = logging.getLogger(__name__)


class LinkFault(enum.Enum):
    """What happens to a reply."""

    GARBLE = "garble"  # bytes flipped: the reply no longer parses
    TRUNCATE = "truncate"  # the reply stops half-way, no line end
    DROP = "drop"  # no reply at all
    DELAY = "delay"  # the reply arrives DELAY_S late, intact (a busy host or board)


#: How late a delayed reply arrives (s): past a resync's wait for quiet, within a timeout.
DELAY_S = 0.1


class FaultyLink:
    """Forwards lines between a new pty and ``upstream_port``, injecting faults.

    Parameters
    ----------
    upstream_port
        The instrument's own serial port (a simulator's pty).
    reply_timeout_s
        How long to wait for the instrument's reply to one line.
    """

    def __init__(self, upstream_port: str, reply_timeout_s: float = 1.0) -> None:
        self._upstream = serial.Serial(upstream_port, timeout=reply_timeout_s)
        self._pending = bytearray()
        self._faults: list[LinkFault] = []
        self._lock = threading.Lock()
        self._pty = PtyDevice(self, name="faulty-link")
        self.forwarded = 0

    @property
    def port(self) -> str:
        """The port the driver opens."""
        return self._pty.port

    def start(self) -> FaultyLink:
        """Start forwarding."""
        self._pty.start()
        return self

    def close(self) -> None:
        """Stop forwarding and close both ends."""
        self._pty.stop()
        self._upstream.close()

    def __enter__(self) -> FaultyLink:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def inject(self, fault: LinkFault, count: int = 1) -> None:
        """Apply ``fault`` to the next ``count`` replies."""
        with self._lock:
            self._faults.extend([fault] * count)

    def feed(self, data: bytes) -> bytes:
        """Forward complete lines upstream; return their (possibly damaged) replies."""
        self._pending += data
        out = bytearray()
        while b"\n" in self._pending:
            line, _, rest = bytes(self._pending).partition(b"\n")
            self._pending = bytearray(rest)
            self._upstream.write(line + b"\n")
            reply = self._upstream.read_until(b"\n")
            self.forwarded += 1
            out += self._damage(reply)
        return bytes(out)

    def _damage(self, reply: bytes) -> bytes:
        with self._lock:
            fault = self._faults.pop(0) if self._faults else None
        if fault is None or not reply:
            return reply
        log.info("faulty link: %s on %r", fault.value, reply)
        if fault is LinkFault.DROP:
            return b""
        if fault is LinkFault.DELAY:
            time.sleep(DELAY_S)
            return reply
        if fault is LinkFault.TRUNCATE:
            return reply[: len(reply) // 2]
        flipped = bytes(b ^ 0x20 if 0x41 <= b <= 0x7A else b for b in reply[:-2])
        return flipped + reply[-2:]
