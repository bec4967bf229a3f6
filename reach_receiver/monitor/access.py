"""How the monitor reaches the devices: its own links while idle, the run's during a run.

The daemon owns the hardware; one process, but two users of it: runs, and the monitor.
They never talk to a device at the same time:

* **idle** (no run): :class:`IdleDevices` holds the monitor's own links to the Teensy
  (switches, rails, I2C temperatures, and the TEC behind it) and the TC-08, opened on
  first use and kept open between samples. A link that fails is closed and opened again
  at the next sample (a *reconnect*). The daemon takes the hardware back before a run or
  a safe-state command (:meth:`IdleDevices.close`, under the monitor's device lock).
* **during a run**: the run lends its own drivers (:class:`RunDevices`) and calls the
  monitor at its safe points, between steps and between Dicke positions, never inside
  an integration or a VNA sweep. What the run reads anyway is shared, not read again:
  the board's state as last read back by the driver, the TC-08 reading of the run's
  temperature log, the spectrometer's packet counters.

Both go through :func:`read_devices`, which turns each device's answer into readings and
its failures into link statistics (:class:`Links`). A device that nobody can ask (the
run's drivers before they are connected or after they are closed, the TEC while its
rail is off or while the Teensy it hangs on does not answer) is *unknown*, not down:
``reach_device_up`` is NaN with status ``unknown``, and no alarm is raised for it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from reach_receiver.clock import Clock
from reach_receiver.config.settings import DeviceSettings
from reach_receiver.devices.board import FrontEndState
from reach_receiver.devices.tc08 import Tc08
from reach_receiver.devices.tec import SerialTecLink, Tec, TecLink
from reach_receiver.devices.tec_via_teensy import TeensyTecLink
from reach_receiver.devices.teensy import Teensy
from reach_receiver.errors import ReceiverError
from reach_receiver.transports.tc08_library import load_libusbtc08

from .readings import UNKNOWN, Reading, board_readings, i2c_readings, tc08_readings, tec_readings

log = logging.getLogger(__name__)


@dataclass
class LinkState:
    """One device's link as the monitor saw it."""

    up: bool | None = None
    last_good: float | None = None
    errors: int = 0
    reconnects: int = 0
    last_error: str = ""


class Links:
    """Per-device link statistics: last good reply, errors, reconnects."""

    def __init__(self) -> None:
        self.states: dict[str, LinkState] = {}

    def of(self, device: str) -> LinkState:
        """The state of ``device`` (made on first use)."""
        return self.states.setdefault(device, LinkState())

    def good(self, device: str, t: float) -> None:
        """``device`` answered at ``t``."""
        state = self.of(device)
        state.up, state.last_good = True, t

    def failed(self, device: str, err: BaseException | str) -> None:
        """A read of ``device`` failed."""
        state = self.of(device)
        if state.up is not False:
            log.warning("monitor: %s does not answer: %s", device, err)
        state.up, state.errors, state.last_error = False, state.errors + 1, str(err)

    def unknown(self, device: str) -> None:
        """``device`` cannot be asked now (powered off, not brought up): neither up nor down."""
        state = self.of(device)
        if state.up is not None:
            log.info("monitor: %s not read (powered off or not brought up)", device)
        state.up = None

    def readings(self, t: float) -> list[Reading]:
        """``reach_device_up``, the age of the last good reply, errors and reconnects."""
        out = []
        for device, state in sorted(self.states.items()):
            labels = {"device": device}
            up = math.nan if state.up is None else float(state.up)
            age = math.nan if state.last_good is None else max(t - state.last_good, 0.0)
            unknown = UNKNOWN if state.up is None else "nominal"
            out += [
                Reading("reach_device_up", up, "1", t, unknown, labels),
                Reading("reach_device_last_reply_age_seconds", age, "s", t, unknown, labels),
                Reading("reach_device_errors_total", state.errors, "1", t, labels=labels),
                Reading("reach_device_reconnects_total", state.reconnects, "1", t, labels=labels),
            ]
        return out


@dataclass
class DeviceSet:
    """The drivers one active sample may use.

    ``teensy_state`` gives the board's state when a run has just read it anyway (else
    ``None``: it is read), so the board is not asked twice; ``tec_usable`` says whether
    the TEC's link is open, ``connected`` whether the drivers are (a run's are not yet
    at its first safe point, nor after it closed them). A TC-08 of ``None`` is not read
    (a run's temperature log reads it; the monitor takes that log's readings instead).
    """

    teensy: Teensy | None = None
    tec: Tec | None = None
    tc08: Tc08 | None = None
    ports: Mapping[int, str] = field(default_factory=dict)
    teensy_state: Callable[[], FrontEndState | None] = lambda: None
    tec_usable: Callable[[], bool] = lambda: True
    connected: Callable[[], bool] = lambda: True


def read_devices(devices: DeviceSet, links: Links, now: Callable[[], float]) -> list[Reading]:
    """One active sample: the board, its I2C sensors, the TEC (rail on), the TC-08.

    Each device's failure is recorded in ``links`` and leaves its readings out; the
    others are still read. Drivers not connected are not asked (their devices are
    unknown). The TEC is read only while its rail is on: a TEC without power is not a
    silent TEC, and neither is one behind a Teensy that does not answer.
    """
    out: list[Reading] = []
    connected = devices.connected()
    tec_on = False
    if devices.teensy is not None and not connected:
        links.unknown("teensy")
    elif devices.teensy is not None:
        try:
            t = now()
            state = devices.teensy_state() or devices.teensy.read_state()
            out += board_readings(state, t)
            out += i2c_readings(devices.teensy.temperatures(), now())
            links.good("teensy", now())
            tec_on = state.rails.get("tec", False)
        except (ReceiverError, OSError) as err:
            links.failed("teensy", err)
    if devices.tec is not None and tec_on and devices.tec_usable():
        try:
            status = devices.tec.status()
            out += tec_readings(status, now())
            links.good("tec", now())
        except (ReceiverError, OSError) as err:
            links.failed("tec", err)
    elif "tec" in links.states:
        links.unknown("tec")
    if devices.tc08 is not None and not connected:
        links.unknown("tc08")
    elif devices.tc08 is not None:
        try:
            out += tc08_readings(devices.tc08.read(), devices.ports)
            links.good("tc08", now())
        except (ReceiverError, OSError) as err:
            links.failed("tc08", err)
    return out


class IdleDevices:
    """The monitor's own links while no run holds the hardware (module docstring)."""

    def __init__(self, settings: DeviceSettings, clock: Clock) -> None:
        self.settings = settings
        self.clock = clock
        self.teensy: Teensy | None = None
        self.tec: Tec | None = None
        self.tc08: Tc08 | None = None
        self._library: object | None = None

    def sample(self, links: Links, ports: Mapping[int, str]) -> list[Reading]:
        """Open what is closed, read everything, close what failed."""
        self._open(links)
        before = {name: links.of(name).errors for name in ("teensy", "tec", "tc08")}
        devices = DeviceSet(self.teensy, self.tec, self.tc08, ports)
        out = read_devices(devices, links, self.clock.now)
        if self.teensy is not None and links.of("teensy").errors > before["teensy"]:
            self._close_teensy()
        if self.tc08 is not None and links.of("tc08").errors > before["tc08"]:
            self._close_tc08()
        return out

    def _open(self, links: Links) -> None:
        settings = self.settings
        if self.teensy is None:
            teensy = Teensy(settings.teensy.port, timeout_s=settings.teensy.timeout_s)
            if self._connect("teensy", teensy, links):
                self.teensy = teensy
                link: TecLink
                if settings.tec.via == "teensy":
                    link = TeensyTecLink(teensy)
                else:
                    link = SerialTecLink(str(settings.tec.port), timeout_s=settings.tec.timeout_s)
                # No retries: the next sample is the retry, and a sample stays short.
                self.tec = Tec(link, self.clock, retries=0, timeout_s=settings.tec.timeout_s)
                self.tec.link.open()
        if self.tc08 is None:
            try:
                if self._library is None:
                    self._library = load_libusbtc08(settings.tc08.library)
            except (ReceiverError, OSError) as err:
                links.failed("tc08", err)
                return
            tc08 = Tc08(self._library, self.clock,  # type: ignore[arg-type]
                        mains_hz=settings.tc08.mains_hz)
            if self._connect("tc08", tc08, links):
                self.tc08 = tc08

    @staticmethod
    def _connect(name: str, device: Teensy | Tc08, links: Links) -> bool:
        state = links.of(name)
        try:
            device.connect()
        except (ReceiverError, OSError) as err:
            device.close()
            links.failed(name, err)
            return False
        if state.up is False:
            state.reconnects += 1
            log.warning("monitor: %s answers again", name)
        return True

    def _close_teensy(self) -> None:
        if self.tec is not None:
            self.tec.link.close()
        if self.teensy is not None:
            self.teensy.close()
        self.teensy = self.tec = None

    def _close_tc08(self) -> None:
        if self.tc08 is not None:
            self.tc08.close()
        self.tc08 = None

    def close(self) -> None:
        """Let go of every device (the daemon takes the hardware back)."""
        self._close_teensy()
        self._close_tc08()
