"""Driver of the Pico TC-08 thermocouple logger (eight K-type probes, thesis sec. 2.1).

The TC-08 is read through Pico's C library (:mod:`reach_receiver.transports.tc08_library`):
open the unit, choose the 50/60 Hz mains filter, enable the cold junction (channel 0)
and the thermocouple channels, then take single readings (``usb_tc08_get_single``,
about 100 ms of conversion per enabled channel). REACH logged every 10 s (thesis
sec. 2.1.3); the ports' components are those of thesis table 2.2 (:data:`DEFAULT_PORTS`).

Every C call runs on one worker thread owned by the driver, so that a call that never
returns (a unit gone from the USB) is abandoned after ``timeout_s`` with
:class:`~reach_receiver.errors.DeviceTimeout` instead of blocking the caller; the unit must
then be closed and reconnected.

Values are never silently used when they cannot be trusted: a channel whose overflow
bit is set, whose value is NaN, or whose value has not changed over ``stuck_reads``
consecutive readings (thermocouples always jitter by a few hundredths of a kelvin) is
flagged, and its entry in :attr:`Tc08Reading.temperatures_c` is NaN.
"""

from __future__ import annotations

import ctypes
import logging
import math
from collections import deque
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass, field
from types import TracebackType
from typing import TypeVar

from reach_receiver.clock import Clock
from reach_receiver.errors import ConfigError, DeviceError, DeviceTimeout
from reach_receiver.transports.tc08_library import (
    USBTC08_CHANNEL_CJC,
    USBTC08_UNITS_CENTIGRADE,
    USBTC08LINE_BATCH_AND_SERIAL,
    Tc08Library,
    describe_error,
)

logger = logging.getLogger(__name__)
T = TypeVar("T")

#: Thesis table 2.2: TC-08 port -> component (port 0 is the logger's own cold junction).
DEFAULT_PORTS: dict[int, str] = {
    0: "cold junction",
    1: "MS1 switch",
    2: "heated load thermistor",
    3: "MS3 switch",
    4: "MS4 switch",
    5: "2 m calibration cable",
    6: "10 m calibration cable",
    7: "low noise amplifier",
    8: "antenna (laboratory)",
}
#: Thermocouple type of each channel: K-type probes on all eight (thesis sec. 2.1.3).
DEFAULT_CHANNELS: dict[int, str] = {channel: "K" for channel in range(1, 9)}
#: Types ``usb_tc08_set_channel`` accepts; ``X`` reads millivolts, space disables.
THERMOCOUPLE_TYPES = frozenset("BEJKNRSTX ")


@dataclass(frozen=True)
class Tc08Reading:
    """One reading of every enabled channel.

    Attributes
    ----------
    timestamp
        Clock time at which the conversion was requested.
    temperatures_c
        Channel -> degrees C, channel 0 the cold junction; NaN for flagged channels.
    raw_c
        Channel -> the value the library returned, flagged or not.
    flags
        Channel -> why it is not to be used (``overflow``, ``nan``, ``stuck``).
    overflow_bits
        The library's overflow word (bit ``n`` for channel ``n``).
    units
        Unit of the temperatures.
    """

    timestamp: float
    temperatures_c: Mapping[int, float]
    raw_c: Mapping[int, float]
    flags: Mapping[int, tuple[str, ...]] = field(default_factory=dict)
    overflow_bits: int = 0
    units: str = "degC"

    @property
    def flagged(self) -> frozenset[int]:
        """Channels that must not be used."""
        return frozenset(self.flags)

    def good(self) -> dict[int, float]:
        """Channel -> temperature for the channels that are not flagged."""
        return {ch: t for ch, t in self.temperatures_c.items() if ch not in self.flags}


class Tc08:
    """A TC-08 reached through a :class:`Tc08Library`.

    Parameters
    ----------
    library
        The C library (real binding or stand-in); the driver holds no other handle.
    clock
        Time source of timestamps and of the logging period.
    channels
        Channel (1-8) -> thermocouple type letter; the cold junction is always enabled.
    mains_hz
        Mains frequency to reject, 50 or 60.
    period_s
        Default period of :meth:`log`.
    timeout_s
        Longest wait for one library call (real seconds).
    ports
        Port -> component names overriding :data:`DEFAULT_PORTS` (from a site file).
    stuck_reads
        Number of identical consecutive values that mark a channel as stuck.
    name
        Device name used in errors.
    """

    def __init__(
        self,
        library: Tc08Library,
        clock: Clock,
        channels: Mapping[int, str] | None = None,
        mains_hz: int = 50,
        period_s: float = 10.0,
        timeout_s: float = 5.0,
        ports: Mapping[int, str] | None = None,
        stuck_reads: int = 5,
        name: str = "tc08",
    ) -> None:
        channels = dict(DEFAULT_CHANNELS if channels is None else channels)
        for channel, kind in channels.items():
            if channel not in range(1, 9) or kind not in THERMOCOUPLE_TYPES or len(kind) != 1:
                raise ConfigError(f"{name}: channel {channel} type {kind!r} is not valid")
        if mains_hz not in (50, 60):
            raise ConfigError(f"{name}: mains_hz must be 50 or 60, got {mains_hz}")
        if period_s <= 0 or timeout_s <= 0 or stuck_reads < 2:
            raise ConfigError(f"{name}: need period_s > 0, timeout_s > 0 and stuck_reads >= 2")
        self.library = library
        self.clock = clock
        self.channels = channels
        self.mains_hz = mains_hz
        self.period_s = period_s
        self.timeout_s = timeout_s
        self.ports = {**DEFAULT_PORTS, **(ports or {})}
        self.stuck_reads = stuck_reads
        self.name = name
        self.serial: str | None = None
        self._handle = 0
        self._worker: ThreadPoolExecutor | None = None
        self._wedged = False
        self._history: dict[int, deque[float]] = {}

    @property
    def enabled_channels(self) -> tuple[int, ...]:
        """The cold junction and the thermocouple channels not disabled with a space."""
        live = [ch for ch, kind in sorted(self.channels.items()) if kind != " "]
        return (USBTC08_CHANNEL_CJC, *live)

    # -- connection ---------------------------------------------------------------------

    def connect(self) -> None:
        """Open the unit, set the mains filter and the channels, read its serial number."""
        if self._handle > 0:
            return
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix=self.name)
        self._wedged = False
        self._history.clear()
        try:
            handle = self._call("usb_tc08_open_unit", self.library.usb_tc08_open_unit)
            if handle == 0:
                raise DeviceError(self.name, "no TC-08 found on the USB", "usb_tc08_open_unit")
            if handle < 0:
                last_error = self.library.usb_tc08_get_last_error
                code = self._call("usb_tc08_get_last_error", last_error, 0)
                message = f"cannot open the unit: {describe_error(code)}"
                raise DeviceError(self.name, message, "usb_tc08_open_unit")
            self._handle = handle
            sixty = 1 if self.mains_hz == 60 else 0
            self._checked("usb_tc08_set_mains", self.library.usb_tc08_set_mains, handle, sixty)
            # The cold junction takes any type letter but a space; K like its neighbours.
            kinds = {USBTC08_CHANNEL_CJC: "K", **self.channels}
            for channel, kind in sorted(kinds.items()):
                set_channel = self.library.usb_tc08_set_channel
                self._checked("usb_tc08_set_channel", set_channel, handle, channel, ord(kind))
            self.serial = self._read_serial()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Close the unit and stop the worker thread; safe to call twice."""
        worker, handle = self._worker, self._handle
        self._handle = 0
        if worker is None:
            return
        if handle > 0 and not self._wedged:
            try:
                self._call("usb_tc08_close_unit", self.library.usb_tc08_close_unit, handle)
            except DeviceError as err:
                logger.warning("%s: close failed: %s", self.name, err)
        worker.shutdown(wait=not self._wedged, cancel_futures=True)
        self._worker = None

    def __enter__(self) -> Tc08:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- readings -------------------------------------------------------------------------

    def read(self) -> Tc08Reading:
        """One conversion of every enabled channel, checked and flagged."""
        if self._handle <= 0:
            raise DeviceError(self.name, "not connected", "usb_tc08_get_single")
        temp = (ctypes.c_float * 9)()
        overflow = (ctypes.c_int16 * 1)()
        timestamp = self.clock.now()
        get_single = self.library.usb_tc08_get_single
        units = USBTC08_UNITS_CENTIGRADE
        self._checked("usb_tc08_get_single", get_single, self._handle, temp, overflow, units)
        bits = int(overflow[0])
        raw, good, flags = {}, {}, {}
        for channel in self.enabled_channels:
            value = float(temp[channel])
            reasons = []
            if bits >> channel & 1:
                reasons.append("overflow")
            if not math.isfinite(value):
                reasons.append("nan")
            if self._stuck(channel, value):
                reasons.append("stuck")
            raw[channel] = value
            good[channel] = math.nan if reasons else value
            if reasons:
                flags[channel] = tuple(reasons)
                logger.warning("%s: channel %d flagged %s (%r)", self.name, channel, reasons, value)
        return Tc08Reading(timestamp, good, raw, flags, bits)

    def log(self, n: int, period_s: float | None = None) -> list[Tc08Reading]:
        """``n`` readings started every ``period_s`` (default :attr:`period_s`) of clock time.

        The schedule is anchored at the first reading, so the timestamps do not drift
        by the conversion time; a reading that overruns its slot delays only the next.
        """
        period = self.period_s if period_s is None else period_s
        if period <= 0:
            raise ValueError(f"period_s must be positive, got {period}")
        start = self.clock.now()
        readings = []
        for index in range(n):
            wait = start + index * period - self.clock.now()
            if wait > 0:
                self.clock.sleep(wait)
            elif index:
                logger.warning("%s: reading %d late by %.3f s", self.name, index, -wait)
            readings.append(self.read())
        return readings

    def components(self, reading: Tc08Reading) -> dict[str, float]:
        """Component name (:attr:`ports`) -> temperature, for the unflagged channels."""
        return {self.ports.get(ch, f"port {ch}"): t for ch, t in reading.good().items()}

    # -- helpers ----------------------------------------------------------------------------

    def _stuck(self, channel: int, value: float) -> bool:
        history = self._history.setdefault(channel, deque(maxlen=self.stuck_reads))
        if not math.isfinite(value):
            history.clear()
            return False
        history.append(value)
        return len(history) == self.stuck_reads and len(set(history)) == 1

    def _read_serial(self) -> str | None:
        buffer = ctypes.create_string_buffer(256)
        info = self.library.usb_tc08_get_unit_info2
        length = self._call(
            "usb_tc08_get_unit_info2",
            info,
            self._handle,
            buffer,
            len(buffer),
            USBTC08LINE_BATCH_AND_SERIAL,
        )
        return buffer.value.decode("ascii", "replace") if length > 0 else None

    def _checked(self, command: str, function: Callable[..., int], *args: object) -> int:
        """Call ``function``; a 0 return becomes a DeviceError with the library's reason."""
        result = self._call(command, function, *args)
        if result == 0:
            get_last_error = self.library.usb_tc08_get_last_error
            code = self._call("usb_tc08_get_last_error", get_last_error, self._handle)
            raise DeviceError(self.name, describe_error(code), command)
        return result

    def _call(self, command: str, function: Callable[..., T], *args: object) -> T:
        if self._worker is None:
            raise DeviceError(self.name, "not connected", command)
        if self._wedged:
            raise DeviceError(self.name, "an earlier call never returned; reconnect", command)
        future = self._worker.submit(function, *args)
        try:
            return future.result(timeout=self.timeout_s)
        except FutureTimeout as err:
            self._wedged = True
            message = f"no return within {self.timeout_s} s"
            raise DeviceTimeout(self.name, message, command) from err
