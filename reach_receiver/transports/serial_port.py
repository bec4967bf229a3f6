"""Serial transport over pyserial: USB CDC devices (the Teensy) and RS-232 (the TEC).

A thin, timed wrapper: open and close explicitly, write bytes, read up to a terminator
within a deadline. The deadline is the caller's, not pyserial's per-read timeout, so a
device that trickles bytes cannot hold a caller longer than asked. The same class serves
real ports (``/dev/ttyACM0``) and the simulators' pseudo-terminals (``/dev/pts/N``).

A port is opened for one program at a time (pyserial's ``exclusive``, an advisory
``flock``): a second driver on the same line would interleave its requests with ours and
could take our replies, so it is refused with a clear error instead.

Nor is a port opened that is some process's controlling terminal (:func:`terminal_owner`):
a simulator's pseudo-terminal that went away leaves its number (``/dev/pts/N``) to the
next terminal the kernel opens, an operator's ssh or tmux session among them, and a
driver retrying the old path would put that terminal in raw mode and write its
commands into it. An instrument's line (a USB CDC device, a simulator's pty) is nobody's
controlling terminal.
"""

from __future__ import annotations

import contextlib
import os
import termios
import time
from pathlib import Path

import serial

from reach_receiver.errors import ConnectionLost, DeviceTimeout, ProtocolError, ReceiverError

#: What a port that went away raises: pyserial's own error, the OS's (EIO on a vanished
#: USB device or pty), and termios's, which is not an OSError (``tcflush``, ``TIOCINQ``).
LINK_ERRORS = (serial.SerialException, OSError, termios.error)


def terminal_owner(port: str, proc: Path = Path("/proc")) -> int | None:
    """A process whose controlling terminal ``port`` is, or None (none, or not a device).

    Read from each process's ``stat`` (field 7, ``tty_nr``: the controlling terminal's
    device number, proc(5)) against the port's ``st_rdev``; processes that end while
    being read are passed over.
    """
    try:
        device = os.stat(port).st_rdev
    except OSError:
        return None
    if device == 0:
        return None
    for entry in proc.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rfind(")") + 2 :].split()  # after the command's name
        if len(fields) > 4 and fields[4].lstrip("-").isdigit() and int(fields[4]) == device:
            return int(entry.name)
    return None


class SerialTransport:
    """A byte channel over a serial port.

    Parameters
    ----------
    port
        Device path (``/dev/ttyACM0``, ``/dev/serial/by-id/...``, a pty path).
    device
        The instrument's name, used in error messages.
    baudrate
        Line speed; USB CDC devices such as the Teensy ignore it.
    timeout_s
        Default deadline of one read.
    """

    def __init__(
        self, port: str, device: str, baudrate: int = 115200, timeout_s: float = 1.0
    ) -> None:
        self.port = port
        self.device = device
        self.baudrate = baudrate
        self.timeout_s = timeout_s
        self._serial: serial.Serial | None = None

    @property
    def is_open(self) -> bool:
        """Whether the port is open."""
        return self._serial is not None and self._serial.is_open

    def open(self) -> None:
        """Open the port (no bytes are exchanged)."""
        if self.is_open:
            return
        owner = terminal_owner(self.port)
        if owner is not None:
            raise ConnectionLost(
                self.device,
                f"will not open {self.port}: it is the terminal of process {owner}, not an "
                "instrument (a simulator's old pseudo-terminal number, taken by a login?)",
            )
        try:
            self._serial = serial.Serial(
                self.port,
                baudrate=self.baudrate,
                timeout=0.05,
                write_timeout=self.timeout_s,
                exclusive=True,
            )
        except LINK_ERRORS as err:
            message = f"cannot open serial port {self.port}: {err}"
            raise ConnectionLost(self.device, message) from err

    def close(self) -> None:
        """Close the port; closing a closed port (or one that went away) does nothing."""
        if self._serial is not None:
            with contextlib.suppress(*LINK_ERRORS):  # a device that went away: nothing to close
                self._serial.close()
            self._serial = None

    def _port(self) -> serial.Serial:
        if self._serial is None or not self._serial.is_open:
            raise ReceiverError(f"{self.device}: serial port {self.port} is not open")
        return self._serial

    def write(self, data: bytes) -> None:
        """Write all of ``data``."""
        port = self._port()
        try:
            port.write(data)
            port.flush()
        except LINK_ERRORS as err:
            raise ConnectionLost(self.device, f"write to {self.port} failed: {err}") from err

    def read_until(
        self, terminator: bytes, timeout_s: float | None = None, limit: int = 4096
    ) -> bytes:
        """Read up to and including ``terminator``, within ``timeout_s``.

        Raises
        ------
        DeviceTimeout
            If the terminator has not arrived by the deadline; the partial bytes are in
            the message so that a garbled reply can be diagnosed.
        ProtocolError
            If ``limit`` bytes arrive without the terminator.
        """
        port = self._port()
        deadline = time.monotonic() + (self.timeout_s if timeout_s is None else timeout_s)
        buffer = bytearray()
        while True:
            try:
                chunk = port.read_until(terminator, limit - len(buffer))
            except LINK_ERRORS as err:
                raise ConnectionLost(self.device, f"read from {self.port} failed: {err}") from err
            buffer += chunk
            if buffer.endswith(terminator):
                return bytes(buffer)
            if len(buffer) >= limit:
                message = f"reply longer than {limit} bytes: {bytes(buffer[:80])!r}"
                raise ProtocolError(self.device, message)
            if time.monotonic() >= deadline:
                waited = self.timeout_s if timeout_s is None else timeout_s
                message = f"no complete reply within {waited} s; got {bytes(buffer)!r}"
                raise DeviceTimeout(self.device, message)

    def discard_input(self, quiet_s: float = 0.05) -> bytes:
        """Read and drop whatever arrives until the line has been quiet for ``quiet_s``."""
        port = self._port()
        dropped = bytearray()
        deadline = time.monotonic() + quiet_s
        while time.monotonic() < deadline:
            try:
                waiting = port.in_waiting
                if waiting:
                    dropped += port.read(waiting)
            except LINK_ERRORS as err:
                raise ConnectionLost(self.device, f"read from {self.port} failed: {err}") from err
            if waiting:
                deadline = time.monotonic() + quiet_s
            else:
                time.sleep(0.005)
        return bytes(dropped)
