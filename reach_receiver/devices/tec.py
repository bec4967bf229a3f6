"""Driver of the Electron Dynamics TC-M-U-10A Peltier (TEC) controller.

The controller holds the front-end baseplate at a setpoint (thesis sec. 2.1: a Laird
UT6-24-F1-5555 module driven by the TC-M-U-10A from a 22 V supply). Its serial protocol
is in :mod:`reach_receiver.devices.tec_frames`. The driver talks through a
:class:`TecLink`, a one-method exchange of frames, so that a direct serial port
(:class:`SerialTecLink`) and the Teensy's ``tec query <hex>`` passthrough can carry it.

Reliability rules:

* A get whose reply times out, is garbled or fails its checksum is re-sent up to
  ``retries`` times; then :class:`~reach_receiver.errors.DeviceTimeout` (nothing came)
  or :class:`~reach_receiver.errors.ProtocolError` (something bad came) names the
  command. A value from a frame that failed its check is never returned.
* Sets get no reply, so each set the driver relies on is read back with its get and
  re-sent while they disagree (sets are idempotent).

Switching the controller on and off (:meth:`Tec.enable`) uses the control type of the
``a`` command (0 = none; 1 on/off, 2 P, 3 PI, 4 PID), read back with ``b``, because
MSL documents those values; the output-drive command ``m`` (mode;value;) is not used:
whether its value forces a manual drive percentage is not documented.
"""

from __future__ import annotations

import logging
import math
import termios
from collections.abc import Callable, Sequence
from types import TracebackType
from typing import Protocol, TypeVar

import serial

from reach_receiver.clock import Clock
from reach_receiver.devices.tec_frames import (
    SET_TO_GET,
    TERMINATOR,
    Field,
    FrameError,
    TecFaults,
    TecStatus,
    build_frame,
    format_fields,
    integer_field,
    number_field,
    parse_frame,
)
from reach_receiver.errors import ConnectionLost, DeviceError, DeviceTimeout, ProtocolError
from reach_receiver.transports.serial_port import SerialTransport

__all__ = ["SerialTecLink", "Tec", "TecFaults", "TecLink", "TecStatus"]

logger = logging.getLogger(__name__)
T = TypeVar("T")

#: Line speed of the TC series (MSL ``tc_series.py``).
TEC_BAUDRATE = 19200
#: Control types of the ``a`` command.
CONTROL_NONE, CONTROL_ON_OFF, CONTROL_P, CONTROL_PI, CONTROL_PID = range(5)
#: Setpoint method of the ``i`` command that makes the software value count.
SETPOINT_SOFTWARE = 1


class TecLink(Protocol):
    """A channel that carries TEC frames to the controller and replies back."""

    def open(self) -> None:
        """Make the channel usable."""
        ...

    def close(self) -> None:
        """Release the channel."""
        ...

    def exchange(self, frame: bytes, expect_reply: bool, timeout_s: float) -> bytes:
        """Send ``frame``; return the reply frame without its ``CR LF`` (or ``b""``)."""
        ...


class SerialTecLink(SerialTransport):
    """A :class:`TecLink` over a serial port (RS-232 adapter or a simulator's pty)."""

    def __init__(
        self, port: str, device: str = "tec", baudrate: int = TEC_BAUDRATE, timeout_s: float = 1.0
    ) -> None:
        super().__init__(port, device, baudrate=baudrate, timeout_s=timeout_s)

    def exchange(self, frame: bytes, expect_reply: bool, timeout_s: float) -> bytes:
        """Write ``frame``; when a reply is expected, read it up to ``CR LF``.

        Input waiting before the request (a late reply to an earlier, timed-out request)
        is dropped first so that it cannot be taken for this request's reply.
        """
        if expect_reply:
            try:
                self._port().reset_input_buffer()
            except (serial.SerialException, OSError, termios.error) as err:
                raise ConnectionLost(self.device, f"flush of {self.port} failed: {err}") from err
        self.write(frame)
        if not expect_reply:
            return b""
        return self.read_until(TERMINATOR, timeout_s)[: -len(TERMINATOR)]


class Tec:
    """The TC-M-U-10A over a :class:`TecLink`.

    Parameters
    ----------
    link
        The frame channel; opened by :meth:`connect`.
    clock
        Time source for :meth:`wait_until_stable` and the pause after a set.
    retries
        Extra attempts after a failed exchange or a disagreeing read-back.
    timeout_s
        Deadline of one reply.
    settle_s
        Pause (clock time) after a set before it is read back.
    control_type
        Control type that :meth:`enable` switches on (4 = PID) unless the controller
        was using another non-zero type when it was last switched off.
    strict_replies
        Whether a reply must carry the letter of the get it answers and a length field
        equal to its data's length (neither is confirmed for the real controller).
    name
        Device name used in errors.
    """

    def __init__(
        self,
        link: TecLink,
        clock: Clock,
        retries: int = 2,
        timeout_s: float = 1.0,
        settle_s: float = 0.05,
        control_type: int = CONTROL_PID,
        strict_replies: bool = True,
        name: str = "tec",
    ) -> None:
        if retries < 0 or timeout_s <= 0:
            raise ValueError("retries must be >= 0 and timeout_s > 0")
        if control_type not in range(1, 5):
            raise ValueError(f"control_type must be 1..4, got {control_type}")
        self.link = link
        self.clock = clock
        self.retries = retries
        self.timeout_s = timeout_s
        self.settle_s = settle_s
        self.control_type = control_type
        self.strict_replies = strict_replies
        self.name = name

    # -- connection -------------------------------------------------------------------

    def connect(self) -> None:
        """Open the link and check that the controller answers a status request."""
        self.link.open()
        try:
            self.status()
        except Exception:
            self.link.close()
            raise

    def close(self) -> None:
        """Close the link (the controller keeps regulating on its own)."""
        self.link.close()

    def __enter__(self) -> Tec:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- raw parameter access ---------------------------------------------------------

    def get_parameters(self, command: str) -> tuple[str, ...]:
        """The fields of get ``command`` (``b``, ``d``, ``f``, ``h``, ``q``, ``j``) as text."""
        return self._query(command, tuple)

    def set_parameters(self, command: str, values: Sequence[Field]) -> None:
        """Send set ``command`` (``a``, ``c``, ``e``, ``g``, ``i``, ``m``); no read-back."""
        try:
            frame = build_frame(command, format_fields(values))
        except ValueError as err:
            raise DeviceError(self.name, f"cannot encode {values!r}: {err}", command) from err
        self.link.exchange(frame, expect_reply=False, timeout_s=self.timeout_s)
        self.clock.sleep(self.settle_s)

    # -- typed operations -------------------------------------------------------------

    def status(self) -> TecStatus:
        """Read the status ``j``."""
        return self._query("j", TecStatus.from_fields)

    def setpoint(self) -> float:
        """The setpoint value read with ``q``."""
        return self._query("q", lambda fields: number_field(fields[1]))

    def set_setpoint(self, celsius: float) -> None:
        """Set the software setpoint with ``i``, read it back with ``q``, retry on mismatch.

        The potentiometer range and offset already in the controller are kept. The
        value is in the controller's unit, which the site configures as degrees C.
        """
        if not math.isfinite(celsius):
            raise ValueError(f"setpoint must be finite, got {celsius}")
        current = self.get_parameters("q")
        if len(current) < 4:
            raise ProtocolError(self.name, f"setpoint reply has fields {current!r}", "q")
        pot_range, pot_offset = number_field(current[2]), number_field(current[3])
        wanted = (SETPOINT_SOFTWARE, float(celsius), pot_range, pot_offset)

        def agrees(fields: tuple[str, ...]) -> bool:
            return (
                integer_field(fields[0]) == SETPOINT_SOFTWARE
                and abs(number_field(fields[1]) - celsius) <= 0.0006
            )

        self._set_and_verify("i", wanted, agrees)

    def enable(self, on: bool) -> None:
        """Switch temperature control on or off through the control type of ``a``.

        Off sets control type 0 (none), remembering the type in use; on restores it
        (or ``control_type``). The PID terms are read with ``b`` and sent back unchanged.
        """
        fields = self.get_parameters("b")
        if len(fields) < 7:
            raise ProtocolError(self.name, f"control reply has fields {fields!r}", "b")
        current = integer_field(fields[0])
        if not on and current != CONTROL_NONE:
            self.control_type = current
        target = self.control_type if on else CONTROL_NONE
        terms = [number_field(text) for text in fields[1:6]]
        values: tuple[Field, ...] = (target, *terms, integer_field(fields[6]))
        self._set_and_verify("a", values, lambda reply: integer_field(reply[0]) == target)

    def wait_until_stable(
        self,
        tolerance_c: float,
        hold_s: float,
        timeout_s: float,
        poll_s: float = 10.0,
        on_poll: Callable[[TecStatus], None] | None = None,
    ) -> TecStatus:
        """Poll the status until ``|temperature - setpoint| <= tolerance_c`` for ``hold_s``.

        All durations are in the injected clock's time. The temperature must stay
        within tolerance, with control on, at every poll of the hold period.
        ``on_poll(status)`` is called after each poll (progress, or a caller's stop by
        raising).

        Returns
        -------
        TecStatus
            The status that completed the hold.

        Raises
        ------
        DeviceTimeout
            If the hold is not completed within ``timeout_s``.
        DeviceError
            At once if the controller reports a fault.
        """
        if tolerance_c <= 0 or hold_s < 0 or timeout_s <= 0 or poll_s <= 0:
            raise ValueError("tolerance_c, timeout_s and poll_s must be > 0, hold_s >= 0")
        deadline = self.clock.now() + timeout_s
        stable_since: float | None = None
        while True:
            now = self.clock.now()
            status = self.status()
            if status.faults.raw:
                faults = ", ".join(status.faults.active)
                raise DeviceError(self.name, f"fault while waiting to stabilise: {faults}", "j")
            error = abs(status.temperature - status.setpoint)
            # 1e-9 K of slack: the wire's 3-decimal values are not exact binary floats
            if status.controlled and error <= tolerance_c + 1e-9:
                stable_since = now if stable_since is None else stable_since
                if now - stable_since >= hold_s:
                    return status
            else:
                stable_since = None
            if now >= deadline:
                message = (
                    f"not stable within {tolerance_c} of {status.setpoint} for {hold_s} s "
                    f"after {timeout_s} s (temperature {status.temperature}, "
                    f"controlled {status.controlled})"
                )
                raise DeviceTimeout(self.name, message, "j")
            if on_poll is not None:
                on_poll(status)
            self.clock.sleep(min(poll_s, max(deadline - now, 0.0)))

    # -- exchanges with retries -------------------------------------------------------

    def _query(self, command: str, decode: Callable[[tuple[str, ...]], T]) -> T:
        """Send get ``command`` and decode its reply, re-sending while the reply is bad."""
        frame = build_frame(command)
        attempts = self.retries + 1
        last: Exception | None = None
        for attempt in range(attempts):
            try:
                reply = self.link.exchange(frame, expect_reply=True, timeout_s=self.timeout_s)
                parsed = parse_frame(reply, check_length=self.strict_replies)
                if self.strict_replies and parsed.command != command:
                    raise FrameError(f"reply is for command {parsed.command!r}")
                return decode(parsed.fields)
            except DeviceTimeout as err:
                last = err
            except (FrameError, ValueError, IndexError, ProtocolError) as err:
                last = err
            logger.warning("%s: attempt %d of %r failed: %s", self.name, attempt + 1, command, last)
        if isinstance(last, DeviceTimeout):
            message = f"no reply after {attempts} attempts"
            raise DeviceTimeout(self.name, message, command) from last
        message = f"bad reply after {attempts} attempts: {last}"
        raise ProtocolError(self.name, message, command) from last

    def _set_and_verify(
        self, command: str, values: Sequence[Field], agrees: Callable[[tuple[str, ...]], bool]
    ) -> None:
        getter = SET_TO_GET[command]
        readback: tuple[str, ...] = ()
        for attempt in range(self.retries + 1):
            self.set_parameters(command, values)
            readback = self.get_parameters(getter)
            try:
                if agrees(readback):
                    return
            except (ValueError, IndexError):
                pass
            logger.warning(
                "%s: %r read back %r after set %d", self.name, getter, readback, attempt + 1
            )
        message = f"read-back {readback!r} disagrees with {values!r} after {self.retries + 1} sets"
        raise DeviceError(self.name, message, command)
