"""Simulated Electron Dynamics TC-M-U-10A behind a pseudo-terminal.

Protocol: that of :mod:`reach_receiver.devices.tec_frames`. Sets (``a c e g i m``) are
stored verbatim and returned by their gets (``b d f h q``); status ``j`` reports the
thermal model. Requests that fail their checksum, and unknown commands, get no reply.

Thermal model (first order, exact between requests). The plate temperature ``T`` obeys::

    dT/dt = (T_amb - T) / tau  +  u * dT_max / tau,        u in [out_min, out_max] / 100

where ``u`` is the drive (+1 = full heating) and ``dT_max`` the largest offset from
ambient the module can hold. With control on, the ideal controller picks the constant
``u = (T_set - T_amb) / dT_max`` that makes ``T`` relax to ``T_set`` with time constant
``tau``; clipped to the output limits, ``T`` relaxes instead to the reachable
``T_amb + u dT_max``. With control off ``u = 0`` and ``T`` relaxes to ambient. Since
``u`` is constant between requests, the solution ``T(t) = T_inf + (T0 - T_inf)
exp(-t / tau)`` is applied for the clock time since the previous request.

Faults settable at run time: corrupt checksums, garbled data, no reply, truncated
replies (each for the next N replies), lost sets, forced fault bits, a stuck temperature
reading, an ambient beyond what the module can hold against.
"""

from __future__ import annotations

import logging
import math
import threading

from reach_receiver.clock import Clock
from reach_receiver.devices.tec_frames import (
    SET_TO_GET,
    TERMINATOR,
    FrameError,
    build_reply,
    format_fields,
    parse_frame,
    split_requests,
)
from reach_receiver.sim.pty_device import PtyDevice

logger = logging.getLogger(__name__)

#: Power-on parameters of the simulated controller, per set command.
DEFAULTS: dict[str, tuple[int | float | str, ...]] = {
    "a": (4, 10.0, 60.0, 0.0, 0.5, 0.2, 2),  # PID; p, i, d, d_filter, dead_band; last state
    "c": (0, -40.0, 85.0, 0.5, 0.5, -40.0, 85.0),  # no alarm; temperature OK within 0.5
    "e": (1, 0.0, 0.0, 0.0, "C", 1),  # PT100, degrees C, averaging on
    "g": (1, -100.0, 100.0, 500.0),  # positive polarity, +-100 %, 500 Hz PWM
    "i": (1, 25.0, 10.0, 0.0),  # software setpoint 25 C
    "m": (1, 0),  # output drive on
}


class TecSimulator:
    """The controller's protocol and the enclosure's thermal response.

    Parameters
    ----------
    clock
        Time of the thermal model (read on each request).
    ambient_c
        Ambient temperature outside the enclosure.
    tau_s
        Thermal time constant of the enclosure.
    max_delta_k
        Largest ``|T - T_amb|`` that the module at 100 % output can hold.
    initial_c
        Plate temperature at start; ambient by default.
    supply_v, version
        Reported in the status.
    """

    def __init__(
        self,
        clock: Clock,
        ambient_c: float = 25.0,
        tau_s: float = 600.0,
        max_delta_k: float = 20.0,
        initial_c: float | None = None,
        supply_v: float = 22.0,
        version: str = "1.0",
    ) -> None:
        self.clock = clock
        self.ambient_c = ambient_c
        self.tau_s = tau_s
        self.max_delta_k = max_delta_k
        self.supply_v = supply_v
        self.version = version
        self._lock = threading.Lock()
        self._buffer = bytearray()
        self._params = {key: format_fields(values) for key, values in DEFAULTS.items()}
        self._temperature = ambient_c if initial_c is None else initial_c
        self._t = clock.now()
        self._corrupt = self._silent = self._truncate = self._garble = self._lost_sets = 0
        self._fault_bits = 0
        self._stuck_at: float | None = None
        self.received: list[str] = []
        self._pty: PtyDevice | None = None

    # -- pty ---------------------------------------------------------------------------

    def start(self) -> str:
        """Serve on a new pty; return its port path."""
        if self._pty is None:
            self._pty = PtyDevice(self, name="tec-sim")
            self._pty.start()
        return self._pty.port

    def stop(self) -> None:
        """Stop serving and close the pty."""
        if self._pty is not None:
            self._pty.stop()
            self._pty = None

    @property
    def port(self) -> str:
        """Path of the pty for pyserial."""
        if self._pty is None:
            raise RuntimeError("TEC simulator not started")
        return self._pty.port

    # -- model -------------------------------------------------------------------------

    def temperature_c(self) -> float:
        """True plate temperature now (not affected by a stuck reading)."""
        with self._lock:
            self._advance()
            return self._temperature

    def drive(self) -> float:
        """Present drive ``u`` in [-1, 1] (fraction of full output, + = heating)."""
        with self._lock:
            return self._drive()

    def _fields(self, command: str) -> list[str]:
        return self._params[command].split(";")[:-1]

    def _controlled(self) -> bool:
        control = self._fields("a")[0]
        return float(control) != 0 and float(self._fields("m")[0]) == 1

    def _drive(self) -> float:
        if not self._controlled():
            return 0.0
        setpoint = float(self._fields("i")[1])
        low, high = (float(x) / 100.0 for x in self._fields("g")[1:3])
        return min(max((setpoint - self.ambient_c) / self.max_delta_k, low), high)

    def _advance(self) -> None:
        now = self.clock.now()
        elapsed = now - self._t
        if elapsed > 0:
            target = self.ambient_c + self._drive() * self.max_delta_k
            decay = math.exp(-elapsed / self.tau_s)
            self._temperature = target + (self._temperature - target) * decay
        self._t = max(now, self._t)

    # -- faults --------------------------------------------------------------------------

    def corrupt_next_replies(self, n: int) -> None:
        """Send the next ``n`` replies with a wrong checksum."""
        with self._lock:
            self._corrupt = n

    def drop_next_replies(self, n: int) -> None:
        """Do not answer the next ``n`` gets."""
        with self._lock:
            self._silent = n

    def truncate_next_replies(self, n: int) -> None:
        """Cut the next ``n`` replies short (the line loses bytes; the CR LF still comes)."""
        with self._lock:
            self._truncate = n

    def garble_next_replies(self, n: int) -> None:
        """Change a digit of the data of the next ``n`` replies, keeping the old checksum."""
        with self._lock:
            self._garble = n

    def ignore_next_sets(self, n: int) -> None:
        """Lose the next ``n`` set commands (as if dropped on the line)."""
        with self._lock:
            self._lost_sets = n

    def set_fault_bits(self, bits: int) -> None:
        """Force bits of the status fault word (3 = temperature limit); 0 clears."""
        with self._lock:
            self._fault_bits = bits

    def set_ambient(self, celsius: float) -> None:
        """Change the ambient from now on (a hot afternoon, a heat sink whose fan stopped)."""
        with self._lock:
            self._advance()
            self.ambient_c = celsius

    def stick_temperature(self, stuck: bool) -> None:
        """Freeze the reported temperature at its present value (the model runs on)."""
        with self._lock:
            self._advance()
            self._stuck_at = self._temperature if stuck else None

    # -- protocol ------------------------------------------------------------------------

    def feed(self, data: bytes) -> bytes:
        """Consume request bytes; return the replies (see :class:`PtyDevice`)."""
        with self._lock:
            self._buffer += data
            replies = [self._serve(frame) for frame in split_requests(self._buffer)]
        return b"".join(replies)

    def _serve(self, raw: bytes) -> bytes:
        try:
            frame = parse_frame(raw)
        except FrameError as err:
            logger.warning("TEC simulator: ignoring bad request %r: %s", raw, err)
            return b""
        command = frame.command
        self.received.append(command)
        self._advance()
        if command in self._params:
            if self._lost_sets > 0:
                self._lost_sets -= 1
            else:
                self._store(command, frame.fields)
            return b""  # a set is never answered
        getters = {get: set_ for set_, get in SET_TO_GET.items()}
        if command in getters:
            return self._reply(command, self._params[getters[command]])
        if command == "j":
            return self._reply(command, self._status())
        logger.warning("TEC simulator: unknown command %r", command)
        return b""

    def _store(self, command: str, fields: tuple[str, ...]) -> bool:
        expected = len(self._fields(command))
        if len(fields) < min(expected, 2):
            logger.warning("TEC simulator: short set %r %r", command, fields)
            return False
        try:
            numbers = [float(x) for i, x in enumerate(fields) if not (command == "e" and i == 4)]
        except ValueError:
            logger.warning("TEC simulator: non-numeric set %r %r", command, fields)
            return False
        if not all(math.isfinite(x) for x in numbers):
            return False
        self._params[command] = "".join(f"{x};" for x in fields)
        return True

    def _status(self) -> str:
        setpoint = float(self._fields("i")[1])
        alarm = self._fields("c")
        ok_low, ok_high, limit_low, limit_high = (float(x) for x in alarm[3:7])
        temperature = self._temperature if self._stuck_at is None else self._stuck_at
        bits = self._fault_bits
        if not limit_low <= self._temperature <= limit_high:
            bits |= 1 << 3
        temp_ok = setpoint - ok_low <= temperature <= setpoint + ok_high
        values = (
            setpoint,
            temperature,
            int(self._controlled()),
            100.0 * self._drive(),
            int(float(alarm[0])),
            bits,
            int(temp_ok),
            self.supply_v,
            self.version,
            0,
            0,
        )
        return format_fields(values)

    def _reply(self, command: str, data: str) -> bytes:
        if self._silent > 0:
            self._silent -= 1
            return b""
        reply = build_reply(command, data)
        if self._corrupt > 0:
            self._corrupt -= 1
            body = reply[: -len(TERMINATOR) - 2]
            wrong = (int(reply[-4:-2], 16) + 1) & 0xFF
            reply = body + f"{wrong:02X}".encode("ascii") + TERMINATOR
        if self._garble > 0:
            self._garble -= 1
            digit = next(i for i in range(4, len(reply)) if reply[i : i + 1].isdigit())
            flipped = str((int(reply[digit : digit + 1]) + 1) % 10).encode("ascii")
            reply = reply[:digit] + flipped + reply[digit + 1 :]
        if self._truncate > 0:
            self._truncate -= 1
            reply = reply[: len(reply) // 2] + TERMINATOR
        return reply
