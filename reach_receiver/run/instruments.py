"""Every instrument of a site, built from its site file, connected and closed together.

The run layer works with one :class:`Instruments`; whether the addresses point at the
deployed hardware or at ``reach-sim``'s simulators makes no difference to it. The
drivers are built here, from the site's typed settings
(:mod:`reach_receiver.config.settings`); everything else sees them through the device
protocols (:mod:`reach_receiver.devices.protocols`). Connecting is explicit
(:meth:`Instruments.connect`) and idempotent; a failure part-way closes whatever was
already open and names the device that failed.

Once the Teensy is connected, its firmware's dead-man switch is armed
(``devices.teensy.deadman_s``) and the driver's keep-alive renews it every third of the
timeout, so a host that dies or loses the link leaves the front-end safe; closing stops
the keep-alive and disarms it.
"""

from __future__ import annotations

import logging
from contextlib import ExitStack
from dataclasses import dataclass, field

from reach_receiver.clock import Clock
from reach_receiver.config.site import SiteConfig
from reach_receiver.devices.board import FrontEndState
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
from reach_receiver.errors import ReceiverError
from reach_receiver.frontend.paths import FrontEnd
from reach_receiver.transports.tc08_library import load_libusbtc08

log = logging.getLogger(__name__)


@dataclass
class Instruments:
    """The drivers of one site, not yet connected.

    ``links`` lists the devices :meth:`connect` opens, in order; the TEC behind the
    Teensy is opened separately (:meth:`connect_tec`), once its rail is on. ``deadman_s``
    is the Teensy's dead-man timeout (0 = off), armed when it connects.
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
    deadman_s: float = 0.0

    @classmethod
    def from_site(cls, site: SiteConfig, clock: Clock) -> Instruments:
        """Build every driver from the site file (no I/O)."""
        settings = site.devices
        teensy = Teensy(settings.teensy.port, timeout_s=settings.teensy.timeout_s)
        vna = Vna(settings.vna.resource, timeout_s=settings.vna.timeout_s, clock=clock)
        itpm = settings.spectrometer
        spectrometer = Spectrometer(
            (itpm.host, itpm.port), source=itpm.source, source_port=itpm.source_port,
            timeout_s=itpm.timeout_s, clock=clock, period_s=itpm.period_s,
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
        return cls(
            site,
            clock,
            teensy,
            vna,
            spectrometer,
            tc08,
            tec,
            frontend,
            links,
            tec,
            deadman_s=settings.teensy.deadman_s,
        )

    def connect(self) -> None:
        """Connect every instrument (once); on a failure, close those already connected."""
        if self.connected:
            return
        with ExitStack() as stack:
            for name, device in self.links:
                log.info("connecting %s", name)
                device.connect()
                stack.callback(device.close)
                if isinstance(device, Teensy) and self.deadman_s > 0:
                    self._guard(device, stack)
            self._stack = stack.pop_all()
        self.connected = True

    def _guard(self, teensy: Teensy, stack: ExitStack) -> None:
        """Arm the dead-man switch and keep it alive; undone before the port closes."""
        stack.callback(_release_deadman, teensy)
        teensy.arm_deadman(self.deadman_s)
        teensy.start_keepalive(self.deadman_s / 3)

    def connect_tec(self) -> None:
        """Connect the TEC controller once (behind the Teensy, its rail must be on)."""
        if self.tec_connected:
            return
        self.tec_link.connect()
        self._stack.callback(self.tec_link.close)
        self.tec_connected = True

    def make_safe(self) -> FrontEndState:
        """The front-end's safe state, whatever became of the run's link to the Teensy.

        Through the open link when the instruments are connected, and if that fails (the
        port was lost), or they never were (a stop before ``initialise`` finished),
        through a link opened for the purpose and closed again.
        """
        if self.connected:
            try:
                return self.frontend.safe()
            except (ReceiverError, OSError) as err:
                log.warning("safe state through the run's link failed (%s); reopening", err)
        teensy = dict(self.links)["teensy"]
        with ExitStack() as stack:
            teensy.close()
            teensy.connect()
            stack.callback(teensy.close)
            return self.frontend.safe()

    def close(self) -> None:
        """Close every connected instrument (the front-end keeps its state)."""
        self._stack.close()
        self.connected = self.tec_connected = False


def _release_deadman(teensy: Teensy) -> None:
    """Stop the keep-alive and disarm; a failure is logged, closing goes on."""
    teensy.stop_keepalive()
    try:
        teensy.disarm_deadman()
    except ReceiverError as err:
        log.warning("teensy: could not disarm the dead-man switch on closing: %s", err)


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
