"""A stand-in for Pico's ``libusbtc08``: the TC-08 without the USB.

:class:`SimulatedTc08Library` implements the functions of
:class:`~reach_receiver.transports.tc08_library.Tc08Library` with the C calling
convention: it fills the ctypes buffers the driver passes (``temp``, ``overflow_flags``,
``string``), returns the C return codes and keeps a last error per handle for
``usb_tc08_get_last_error``. The driver thus runs unchanged against it.

Temperatures come from ``temperatures_c(t)`` (9 values, index 0 the cold junction, at
clock time ``t``) plus Gaussian thermocouple noise (0.05 K by default, seeded). A
conversion takes ``conversion_s`` of clock time per enabled channel (about 100 ms on the
real unit). Faults: no unit found, an open that fails, overflow or NaN on a channel,
stuck readings, failing or hanging conversions.
"""

from __future__ import annotations

import ctypes
import math
import threading
from collections.abc import Callable, Sequence

import numpy as np

from reach_receiver.clock import Clock
from reach_receiver.transports.tc08_library import (
    USBTC08_UNITS_FAHRENHEIT,
    USBTC08_UNITS_KELVIN,
    USBTC08_UNITS_RANKINE,
    USBTC08LINE_BATCH_AND_SERIAL,
    CharArray,
    FloatArray,
    Int16Array,
)

ERROR_OK, ERROR_NO_CHANNELS_SET, ERROR_INVALID_PARAMETER = 0, 2, 3
ERROR_NOT_RESPONDING, ERROR_NOT_FOUND = 7, 10
_TYPES = frozenset(b"BEJKNRSTX ")


def _convert(celsius: float, units: int) -> float:
    if units == USBTC08_UNITS_FAHRENHEIT:
        return celsius * 9.0 / 5.0 + 32.0
    if units == USBTC08_UNITS_KELVIN:
        return celsius + 273.15
    if units == USBTC08_UNITS_RANKINE:
        return (celsius + 273.15) * 9.0 / 5.0
    return celsius


class SimulatedTc08Library:
    """One simulated TC-08 behind the ``libusbtc08`` function surface.

    Parameters
    ----------
    temperatures_c
        Clock time -> 9 true temperatures in degrees C (index 0 the cold junction).
    clock
        Time of the temperatures; conversions advance it by ``conversion_s`` per channel.
    noise_k
        Standard deviation of the thermocouple noise.
    seed
        Seed of the noise.
    conversion_s
        Clock time one channel's conversion takes.
    serial
        Batch and serial string of the unit.
    """

    def __init__(
        self,
        temperatures_c: Callable[[float], Sequence[float]],
        clock: Clock,
        noise_k: float = 0.05,
        seed: int = 0,
        conversion_s: float = 0.1,
        serial: str = "A0042/123",
    ) -> None:
        self.temperatures_c = temperatures_c
        self.clock = clock
        self.noise_k = noise_k
        self.conversion_s = conversion_s
        self.serial = serial
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._units: dict[int, dict[int, int]] = {}  # open handle -> channel -> type
        self._mains: dict[int, int] = {}
        self._last_error: dict[int, int] = {0: ERROR_OK}
        self._next_handle = 1
        self._open_failure: tuple[int, int] | None = None
        self._overflow: set[int] = set()
        self._nan: set[int] = set()
        self._stuck = False
        self._last_values: list[float] | None = None
        self._failures = 0
        self._failure_error = ERROR_NOT_RESPONDING
        self._hang = threading.Event()
        self._released = threading.Event()
        self.calls: list[str] = []

    # -- inspection ------------------------------------------------------------------------

    def channel_types(self, handle: int) -> dict[int, str]:
        """Channel -> type letter set on the open unit ``handle``."""
        with self._lock:
            return {ch: chr(kind) for ch, kind in self._units.get(handle, {}).items()}

    def sixty_hertz(self, handle: int) -> int | None:
        """The mains filter chosen for ``handle`` (0 = 50 Hz, 1 = 60 Hz), if any."""
        with self._lock:
            return self._mains.get(handle)

    @property
    def open_handles(self) -> tuple[int, ...]:
        """Handles of the units open now."""
        with self._lock:
            return tuple(self._units)

    # -- faults -----------------------------------------------------------------------------

    def fail_open(self, result: int = 0, error: int = ERROR_NOT_FOUND) -> None:
        """Make ``open_unit`` return ``result`` (0 none found, -1 error) with ``error``."""
        self._open_failure = (result, error)

    def set_overflow(self, channel: int, on: bool = True) -> None:
        """Set or clear the overflow flag of ``channel``."""
        (self._overflow.add if on else self._overflow.discard)(channel)

    def set_nan(self, channel: int, on: bool = True) -> None:
        """Make ``channel`` read NaN (as a broken conversion would)."""
        (self._nan.add if on else self._nan.discard)(channel)

    def stick(self, on: bool = True) -> None:
        """Repeat the last values exactly (a frozen unit), or resume."""
        self._stuck = on

    def fail_get_single(self, n: int, error: int = ERROR_NOT_RESPONDING) -> None:
        """Make the next ``n`` ``get_single`` calls return 0 with ``error``."""
        self._failures, self._failure_error = n, error

    def hang_get_single(self) -> None:
        """Make ``get_single`` block (a unit gone from the bus) until :meth:`release`."""
        self._released.clear()
        self._hang.set()

    def release(self) -> None:
        """Let a hung ``get_single`` return (with a failure) and stop hanging."""
        self._hang.clear()
        self._released.set()

    # -- the C functions -------------------------------------------------------------------

    def usb_tc08_open_unit(self) -> int:
        """Handle > 0, or the configured failure."""
        with self._lock:
            self.calls.append("open_unit")
            if self._open_failure is not None:
                result, self._last_error[0] = self._open_failure
                return result
            if self._units:  # one simulated unit: a second open finds no more
                return 0
            handle, self._next_handle = self._next_handle, self._next_handle + 1
            self._units[handle] = {}
            self._last_error[handle] = ERROR_OK
            return handle

    def usb_tc08_close_unit(self, handle: int) -> int:
        """1 if ``handle`` was open."""
        with self._lock:
            self.calls.append("close_unit")
            return int(self._units.pop(handle, None) is not None)

    def usb_tc08_set_mains(self, handle: int, sixty_hertz: int) -> int:
        """Remember the filter choice (0 = 50 Hz, 1 = 60 Hz)."""
        with self._lock:
            self.calls.append("set_mains")
            if handle not in self._units or sixty_hertz not in (0, 1):
                return self._fail(handle, ERROR_INVALID_PARAMETER)
            self._mains[handle] = sixty_hertz
            return 1

    def usb_tc08_set_channel(self, handle: int, channel: int, tc_type: int) -> int:
        """Enable ``channel`` with type ``tc_type`` (an ASCII code; space disables)."""
        with self._lock:
            self.calls.append("set_channel")
            if handle not in self._units or channel not in range(9) or tc_type not in _TYPES:
                return self._fail(handle, ERROR_INVALID_PARAMETER)
            self._units[handle][channel] = tc_type
            return 1

    def usb_tc08_get_single(
        self, handle: int, temp: FloatArray, overflow_flags: Int16Array, units: int
    ) -> int:
        """Convert the enabled channels into ``temp`` and ``overflow_flags[0]``."""
        with self._lock:
            self.calls.append("get_single")
            channels = self._units.get(handle)
            if channels is None or len(temp) < 9 or units not in range(4):
                return self._fail(handle, ERROR_INVALID_PARAMETER)
            enabled = [ch for ch, kind in sorted(channels.items()) if kind != ord(" ")]
            if not enabled:
                return self._fail(handle, ERROR_NO_CHANNELS_SET)
            hang, failing = self._hang.is_set(), self._failures > 0
            if failing:
                self._failures -= 1
        if hang:
            self._released.wait(timeout=30.0)
            return self._fail(handle, ERROR_NOT_RESPONDING)
        if failing:
            return self._fail(handle, self._failure_error)
        started = self.clock.now()
        self.clock.sleep(self.conversion_s * len(enabled))
        values = self._values(started)
        bits = 0
        for channel in range(9):
            value = values[channel] if channel in enabled else math.nan
            temp[channel] = _convert(value, units)
            if channel in enabled and channel in self._overflow:
                bits |= 1 << channel
        overflow_flags[0] = bits
        return 1

    def usb_tc08_get_last_error(self, handle: int) -> int:
        """The last error of ``handle``; handle 0 holds the errors of ``open_unit``."""
        with self._lock:
            return self._last_error.get(handle, ERROR_INVALID_PARAMETER)

    def usb_tc08_get_unit_info2(
        self, handle: int, string: CharArray, string_length: int, line: int
    ) -> int:
        """Copy the batch and serial line; other lines read as empty."""
        with self._lock:
            if handle not in self._units:
                return self._fail(handle, ERROR_INVALID_PARAMETER)
            text = self.serial.encode("ascii") if line == USBTC08LINE_BATCH_AND_SERIAL else b""
            text = text[: max(min(string_length, len(string)) - 1, 0)]
            ctypes.memmove(string, text + b"\0", len(text) + 1)
            return len(text)

    # -- internals -----------------------------------------------------------------------------

    def _fail(self, handle: int, error: int) -> int:
        self._last_error[handle] = error
        return 0

    def _values(self, t: float) -> list[float]:
        if self._stuck and self._last_values is not None:
            return list(self._last_values)
        truth = [float(x) for x in self.temperatures_c(t)]
        if len(truth) != 9:
            raise ValueError(f"temperatures_c must give 9 values, gave {len(truth)}")
        noise = self._rng.normal(0.0, self.noise_k, size=9)
        values = [x + float(dx) for x, dx in zip(truth, noise, strict=True)]
        for channel in self._nan:
            values[channel] = math.nan
        self._last_values = values
        return values
