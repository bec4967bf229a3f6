"""Every instrument of a site, built from its site file, connected and closed together.

The run layer works with one :class:`Instruments`; whether the addresses point at the
deployed hardware or at ``reach-sim``'s simulators makes no difference to it. The
drivers are built here, from the site's typed settings
(:mod:`reach_receiver.config.settings`); everything else sees them through the device
protocols (:mod:`reach_receiver.devices.protocols`). Connecting is explicit
(:meth:`Instruments.connect`) and idempotent; a failure part-way closes whatever was
already open and names the device that failed.
"""

from __future__ import annotations

import logging
from contextlib import ExitStack
from dataclasses import dataclass, field

from reach_receiver.clock import Clock
from reach_receiver.config.site import SiteConfig
from reach_receiver.devices.protocols import (
    Device,
    ReflectionMeter,
    SpectraSource,
    SwitchMatrix,
    TemperatureController,
    Thermometer,
)
from reach_receiver.devices.spectrometer import Spectrometer
from reach_receiver.devices.tc08 import Tc08
from reach_receiver.devices.tec import SerialTecLink, Tec, TecLink
from reach_receiver.devices.tec_via_teensy import TeensyTecLink
from reach_receiver.devices.teensy import Teensy
from reach_receiver.devices.vna import Vna
from reach_receiver.frontend.paths import FrontEnd
from reach_receiver.transports.tc08_library import load_libusbtc08

log = logging.getLogger(__name__)


@dataclass
class Instruments:
    """The drivers of one site, not yet connected.

    ``links`` lists the devices :meth:`connect` opens, in order; the TEC behind the
    Teensy is opened separately (:meth:`connect_tec`), once its rail is on.
    """

    site: SiteConfig
    clock: Clock
    teensy: SwitchMatrix
    vna: ReflectionMeter
    spectrometer: SpectraSource
    tc08: Thermometer
    tec: TemperatureController
    frontend: FrontEnd
    links: tuple[tuple[str, Device], ...]
    tec_link: Device
    _stack: ExitStack = field(default_factory=ExitStack)
    connected: bool = False
    tec_connected: bool = False

    @classmethod
    def from_site(cls, site: SiteConfig, clock: Clock) -> Instruments:
        """Build every driver from the site file (no I/O)."""
        settings = site.devices
        teensy = Teensy(settings.teensy.port, timeout_s=settings.teensy.timeout_s)
        vna = Vna(settings.vna.resource, timeout_s=settings.vna.timeout_s, clock=clock)
        itpm = settings.spectrometer
        spectrometer = Spectrometer(
            (itpm.host, itpm.port), timeout_s=itpm.timeout_s, clock=clock, period_s=itpm.period_s
        )
        library = _LazyLibrary(settings.tc08.library)
        tc08 = Tc08(library, clock, mains_hz=settings.tc08.mains_hz)  # type: ignore[arg-type]
        link: TecLink
        if settings.tec.via == "teensy":
            link = TeensyTecLink(teensy)
        else:
            link = SerialTecLink(str(settings.tec.port), timeout_s=settings.tec.timeout_s)
        tec = Tec(link, clock)
        frontend = FrontEnd(teensy, site.sources)
        links: tuple[tuple[str, Device], ...] = (
            ("teensy", teensy),
            ("vna", vna),
            ("spectrometer", spectrometer),
            ("tc08", tc08),
        )
        return cls(site, clock, teensy, vna, spectrometer, tc08, tec, frontend, links, tec)

    def connect(self) -> None:
        """Connect every instrument (once); on a failure, close those already connected."""
        if self.connected:
            return
        with ExitStack() as stack:
            for name, device in self.links:
                log.info("connecting %s", name)
                device.connect()
                stack.callback(device.close)
            self._stack = stack.pop_all()
        self.connected = True

    def connect_tec(self) -> None:
        """Connect the TEC controller once (behind the Teensy, its rail must be on)."""
        if self.tec_connected:
            return
        self.tec_link.connect()
        self._stack.callback(self.tec_link.close)
        self.tec_connected = True

    def close(self) -> None:
        """Close every connected instrument (the front-end keeps its state)."""
        self._stack.close()
        self.connected = self.tec_connected = False


class _LazyLibrary:
    """Loads ``libusbtc08`` on first use, so building the drivers does no I/O."""

    def __init__(self, path: str | None) -> None:
        self._path = path
        self._library: object | None = None

    def __getattr__(self, name: str) -> object:
        if name.startswith("usb_tc08_"):
            if self._library is None:
                self._library = load_libusbtc08(self._path)
            return getattr(self._library, name)
        raise AttributeError(name)
