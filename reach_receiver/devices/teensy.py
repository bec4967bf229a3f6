"""Driver of the front-end microcontroller (Teensy 3.5), protocol v2 of ``firmware/PROTOCOL.md``.

Every request is one tagged line, ``#<tag> <command>``; the reply ``OK 00 #<tag> <payload>``
or ``ERR <code> #<tag> <reason>`` must carry the same tag, so a late reply to an earlier,
timed-out request is recognised and dropped. Each driver starts its tags at a random
point, so a reply to another driver that shares the line (another program that opened the
port where the exclusive lock is not honoured) is dropped as stale too, not taken for the
answer of a request of the same number. All commands set absolute states, so after a
timeout or a garbled reply the driver resynchronises (a lone LF, then a tagged ``ping``)
and repeats the request; error replies are never retried, they are the board's answer.
Interlock refusals (codes 20-22) raise :class:`~reach_receiver.errors.InterlockError`.

The firmware's dead-man switch (PROTOCOL.md, "Dead-man switch") puts the front-end in its
safe state on its own when the host falls silent for the armed timeout
(:meth:`Teensy.arm_deadman`); its report, ``ERR 50``, raises :class:`FrontEndTripped`.
A keep-alive thread (:meth:`Teensy.start_keepalive`) renews it while the run is busy
elsewhere, so the driver serialises its exchanges with a lock: one request and its reply,
retries and resynchronisation included, never interleave with another thread's.
"""

from __future__ import annotations

import itertools
import logging
import re
import secrets
import threading
import time

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

PROTOCOL_VERSION = 2

#: Interlock refusals (PROTOCOL.md, "Interlocks"): the board said no on safety grounds.
INTERLOCK_CODES = frozenset({20, 21, 22})

#: The dead-man switch tripped: the front-end went safe on its own, the request was not run.
TRIPPED_CODE = 50

#: Dead-man timeouts the firmware accepts (ms); 0 disarms it.
DEADMAN_MIN_MS = 100
DEADMAN_MAX_MS = 3_600_000

_REPLY = re.compile(r"^(OK|ERR) (\d\d) #([A-Za-z0-9]{1,8})(?: (.*))?$")
#: A reply without a tag: the board's answer to a line that had none, such as the lone LF
#: of :meth:`Teensy.resync` (``ERR 06 empty line``) or the rest of a garbled line.
_UNTAGGED = re.compile(r"^(OK|ERR) (\d\d)(?: (?!#)(.*))?$")


class TeensyError(DeviceError):
    """An ``ERR`` reply from the board, with its protocol error code."""

    def __init__(self, code: int, reason: str, command: str) -> None:
        self.code = code
        self.reason = reason
        super().__init__(DEVICE, f"ERR {code:02d} {reason}", command)


class FrontEndTripped(TeensyError):
    """The firmware's dead-man switch put the front-end in its safe state on its own.

    Raised for ``ERR 50``. The request that received the report was not run; every
    switch has been released and the noise source, ``6v`` and ``12v`` are off. A run
    must not go on as if its signal path were still set.
    """

    def __init__(self, reason: str, command: str, seen_by: str = "") -> None:
        self.code = TRIPPED_CODE
        self.reason = reason
        via = f", reported to the {seen_by}" if seen_by else ""
        message = f"the front-end went to its safe state on its own ({reason}{via})"
        DeviceError.__init__(self, DEVICE, message, command)


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
        first_tag = secrets.randbelow(0xFFFFFF)
        self._tags = (f"{n % 0xFFFFFF:x}" for n in itertools.count(first_tag))
        self.identity = ""
        self.firmware = ""
        # Re-entrant: a request's retries resynchronise while holding it.
        self._lock = threading.RLock()
        self._deadman_ms = 0
        self._last_reply = time.monotonic()
        self._tripped: FrontEndTripped | None = None  # seen by the keep-alive, not yet told
        self._keepalive: threading.Thread | None = None
        self._keepalive_stop = threading.Event()
        self.keepalive_failures = 0
        #: The last state read back (``time.monotonic()`` of the read, the state), so that
        #: a monitor can use the read a run made instead of asking the board again.
        self.last_state: tuple[float, FrontEndState] | None = None

    # ----------------------------------------------------------------- life cycle
    def connect(self) -> None:
        """Open the port, resynchronise and check identity and protocol version.

        A dead-man trip left over from an earlier session is logged, not raised: it
        happened before this session moved anything.
        """
        with self._lock:
            self.transport.open()
            try:
                self.resync()
            except FrontEndTripped as err:
                log.warning("teensy: on connecting: %s", err)
            self.identity = self.command("id")
            version = dict(f.split("=", 1) for f in self.command("version").split() if "=" in f)
            if version.get("protocol") != str(PROTOCOL_VERSION):
                self.close()
                raise DeviceError(
                    DEVICE, f"speaks protocol {version.get('protocol')}, need {PROTOCOL_VERSION}"
                )
            self.firmware = version.get("firmware", "?")

    def close(self) -> None:
        """Stop the keep-alive and close the port (the board keeps its state).

        An armed dead-man switch stays armed: without :meth:`disarm_deadman` first, the
        front-end goes safe once the timeout has passed.
        """
        self.stop_keepalive()
        with self._lock:
            self.transport.close()

    def __enter__(self) -> Teensy:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----------------------------------------------------------------- requests
    def resync(self) -> None:
        """End any partial line on the board and drop replies up to a fresh tagged ``pong``.

        Raises
        ------
        FrontEndTripped
            A dead-man report was among the dropped replies, or answered the ``ping``.
        """
        with self._lock:
            self.transport.write(b"\n")
            dropped = self.transport.discard_input(quiet_s=0.02).decode("ascii", errors="replace")
            reports = [_trip_report(line.strip(), "resync") for line in dropped.splitlines()]
            tag = next(self._tags)
            self.transport.write(f"#{tag} ping\n".encode())
            self._read_reply(tag, "ping", self.timeout_s)
            for report in reports:
                if report is not None:
                    raise report

    def _read_reply(self, tag: str, command: str, timeout_s: float) -> str:
        while True:
            raw = self.transport.read_until(b"\n", timeout_s=timeout_s)
            line = raw.decode("ascii", errors="replace").rstrip("\r\n")
            match = _REPLY.match(line)
            if match is None and _UNTAGGED.match(line):
                # Late under load, after resync's wait for quiet: not this request's.
                report = _trip_report(line, command)
                if report is not None:
                    raise report
                log.info("teensy: dropping untagged reply %r", line)
                continue
            if match is None:
                raise ProtocolError(DEVICE, f"garbled reply {line!r}", command)
            kind, code, reply_tag, text = match.groups()
            if reply_tag != tag:
                # A timed-out request's late reply; a dead-man report must not be lost.
                report = _trip_report(line, command)
                if report is not None:
                    raise report
                log.info("teensy: dropping stale reply %r", line)
                continue
            self._last_reply = time.monotonic()
            if kind == "ERR" and int(code) == TRIPPED_CODE:
                raise FrontEndTripped(text or "", command)
            if kind == "ERR":
                raise TeensyError(int(code), text or "", command)
            return text or ""

    def command(self, command: str, timeout_s: float | None = None) -> str:
        """Send one request and return the payload of its ``OK`` reply.

        Safe to call from several threads: each request and its reply, retries included,
        is one exchange under the driver's lock.

        Raises
        ------
        FrontEndTripped
            The dead-man switch had tripped (``ERR 50``, this request was not run), or the
            keep-alive received that report since the last request.
        InterlockError
            The board refused on safety grounds (codes 20-22).
        TeensyError
            Any other ``ERR`` reply.
        DeviceTimeout, ProtocolError
            No usable reply after ``retries`` resynchronised repeats.
        """
        with self._lock:
            tripped, self._tripped = self._tripped, None
            if tripped is not None:
                raise FrontEndTripped(tripped.reason, command, "keep-alive") from tripped
            return self._exchange(command, timeout_s)

    def _exchange(self, command: str, timeout_s: float | None) -> str:
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

    # ----------------------------------------------------------------- dead-man switch
    def arm_deadman(self, timeout_s: float) -> None:
        """Arm the firmware's dead-man switch: safe state after ``timeout_s`` of silence.

        Every request renews it; :meth:`start_keepalive` keeps it renewed. ``0`` disarms.

        Raises
        ------
        ValueError
            A timeout outside 0.1-3600 s (and not 0).
        """
        ms = round(timeout_s * 1000)
        if ms == 0:
            self.disarm_deadman()
            return
        if not DEADMAN_MIN_MS <= ms <= DEADMAN_MAX_MS:
            raise ValueError(
                f"dead-man timeout must be 0 (off) or {DEADMAN_MIN_MS / 1000:g}-"
                f"{DEADMAN_MAX_MS / 1000:g} s, got {timeout_s!r}"
            )
        with self._lock:
            self._expect(f"deadman {ms}", f"deadman={ms}")
            self._deadman_ms = ms
        log.info("teensy: dead-man switch armed, %g s", ms / 1000)

    def disarm_deadman(self) -> None:
        """Disarm the dead-man switch (the front-end then stays as it is left)."""
        with self._lock:
            self._deadman_ms = 0  # first: the keep-alive must not re-arm it
            self._expect("deadman 0", "deadman=0")

    def _expect(self, command: str, payload: str) -> None:
        reply = self.command(command)
        if reply != payload:
            raise ProtocolError(DEVICE, f"unexpected reply {reply!r}", command)

    def start_keepalive(self, period_s: float) -> None:
        """Renew the dead-man switch from a daemon thread whenever ``period_s`` passed quietly.

        The thread sends a request only when no reply has arrived for ``period_s``: while
        armed ``deadman <timeout>`` (which also re-arms it after a watchdog reset of the
        board), else ``ping``. Failures are logged and counted
        (:attr:`keepalive_failures`), never raised; a dead-man report it receives is
        raised by the next :meth:`command` of the run instead.
        """
        if not period_s > 0:
            raise ValueError(f"keep-alive period must be positive, got {period_s!r}")
        self.stop_keepalive()
        self._keepalive_stop = threading.Event()
        self._keepalive = threading.Thread(
            target=self._keep_alive,
            args=(period_s, self._keepalive_stop),
            name="teensy-keepalive",
            daemon=True,
        )
        self._keepalive.start()

    def stop_keepalive(self, timeout_s: float | None = None) -> None:
        """Stop the keep-alive thread and wait for it, at most ``timeout_s``.

        By default the wait covers one exchange with all its retries.
        """
        thread, self._keepalive = self._keepalive, None
        if thread is None:
            return
        self._keepalive_stop.set()
        if timeout_s is None:
            timeout_s = 2 * (self.retries + 1) * self.timeout_s + 1.0
        thread.join(timeout_s)
        if thread.is_alive():
            log.warning("teensy: keep-alive thread still busy after %.1f s; left behind", timeout_s)

    def _keep_alive(self, period_s: float, stop: threading.Event) -> None:
        while not stop.is_set():
            quiet = time.monotonic() - self._last_reply
            if quiet < period_s:
                stop.wait(period_s - quiet)
            elif not self._renew(period_s, stop):
                stop.wait(period_s)

    def _renew(self, period_s: float, stop: threading.Event) -> bool:
        """One keep-alive request, unless the run talked meanwhile; False if it failed."""
        if not self._lock.acquire(timeout=0.1):  # the run is talking: that renews too
            return True
        try:
            if stop.is_set() or time.monotonic() - self._last_reply < period_s:
                return True
            if self._deadman_ms:
                self._exchange(f"deadman {self._deadman_ms}", None)
            else:
                self._exchange("ping", None)
            return True
        except FrontEndTripped as err:
            log.error("teensy: keep-alive: %s", err)
            self._tripped = err
            return True
        except Exception as err:  # never into the run: logged, counted, tried again
            self.keepalive_failures += 1
            log.warning("teensy: keep-alive failed: %s", err)
            return False
        finally:
            self._lock.release()

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
        return self._remember(FrontEndState.parse(self.command("state")))

    def safe(self) -> FrontEndState:
        """Put the front-end in its safe state (PROTOCOL.md) and return the state."""
        return self._remember(FrontEndState.parse(self.command("safe")))

    @classmethod
    def command_safe(cls, port: str, timeout_s: float) -> FrontEndState:
        """Open ``port``, command the safe state, close it: nothing else of the receiver.

        The daemon's first act at start, before it imports the rest of itself: the
        front-end a crash left powered goes safe within a second of the process starting.
        """
        teensy = cls(port, timeout_s=timeout_s)
        teensy.connect()
        try:
            return teensy.safe()
        finally:
            teensy.close()

    def _remember(self, state: FrontEndState) -> FrontEndState:
        self.last_state = (time.monotonic(), state)
        return state

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


def _trip_report(line: str, command: str) -> FrontEndTripped | None:
    """The :class:`FrontEndTripped` a reply line reports (``ERR 50``, tagged or not), or None."""
    match = _REPLY.match(line)
    if match is not None:
        if match.group(1) == "ERR" and int(match.group(2)) == TRIPPED_CODE:
            return FrontEndTripped(match.group(4) or "", command)
        return None
    prefix = f"ERR {TRIPPED_CODE} "
    return FrontEndTripped(line[len(prefix) :], command) if line.startswith(prefix) else None


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
