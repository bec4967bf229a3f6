"""Every instrument of a site, built from its site file, connected and closed together.

The scheduler's runner works with one :class:`Instruments`; whether the addresses point
at the deployed hardware or at ``reach-sim``'s simulators makes no difference to it.
Connecting is explicit (:meth:`Instruments.connect`); a failure part-way closes whatever
was already open and names the device that failed.
"""

from __future__ import annotations

import logging
from contextlib import ExitStack
from dataclasses import dataclass, field

from reach_receiver.clock import Clock
from reach_receiver.devices.spectrometer import Spectrometer
from reach_receiver.devices.tc08 import Tc08
from reach_receiver.devices.tec import SerialTecLink, Tec, TecLink
from reach_receiver.devices.tec_via_teensy import TeensyTecLink
from reach_receiver.devices.teensy import Teensy
from reach_receiver.devices.vna import Vna
from reach_receiver.errors import ConfigError
from reach_receiver.frontend.paths import FrontEnd
from reach_receiver.site import SiteConfig
from reach_receiver.transports.tc08_library import load_libusbtc08

log = logging.getLogger(__name__)


@dataclass
class Instruments:
    """The drivers of one site, not yet connected."""

    site: SiteConfig
    clock: Clock
    teensy: Teensy
    vna: Vna
    spectrometer: Spectrometer
    tc08: Tc08
    tec_link: TecLink
    tec: Tec
    frontend: FrontEnd
    _stack: ExitStack = field(default_factory=ExitStack)
    connected: bool = False
    tec_connected: bool = False

    @classmethod
    def from_site(cls, site: SiteConfig, clock: Clock) -> Instruments:
        """Build every driver from the site file (no I/O)."""
        teensy_cfg = site.device("teensy")
        teensy = Teensy(str(teensy_cfg["port"]), timeout_s=float(teensy_cfg.get("timeout_s", 1.0)))
        vna_cfg = site.device("vna")
        vna = Vna(
            str(vna_cfg["resource"]), timeout_s=float(vna_cfg.get("timeout_s", 10.0)), clock=clock
        )
        itpm_cfg = site.device("spectrometer")
        spectrometer = Spectrometer(
            (str(itpm_cfg.get("host", "0.0.0.0")), int(itpm_cfg.get("port", 4660))),
            timeout_s=float(itpm_cfg.get("timeout_s", 5.0)),
            clock=clock,
            period_s=float(itpm_cfg["period_s"]) if "period_s" in itpm_cfg else None,
        )
        tc08_cfg = site.device("tc08")
        library_path = tc08_cfg.get("library")
        tc08 = Tc08(
            _LazyLibrary(None if library_path is None else str(library_path)),  # type: ignore[arg-type]
            clock,
            mains_hz=int(tc08_cfg.get("mains_hz", 50)),
        )
        tec_cfg = site.device("tec")
        link: TecLink
        if tec_cfg.get("via") == "teensy":
            link = TeensyTecLink(teensy)
        elif "port" in tec_cfg:
            timeout_s = float(tec_cfg.get("timeout_s", 1.0))
            link = SerialTecLink(str(tec_cfg["port"]), timeout_s=timeout_s)
        else:
            raise ConfigError(f"{site.source}: devices.tec needs 'via: teensy' or a 'port'")
        tec = Tec(link, clock)
        frontend = FrontEnd(teensy, site.sources)
        return cls(site, clock, teensy, vna, spectrometer, tc08, link, tec, frontend)

    def connect(self) -> None:
        """Connect every instrument (once); on a failure, close those already connected."""
        if self.connected:
            return
        with ExitStack() as stack:
            for name, device in (
                ("teensy", self.teensy),
                ("vna", self.vna),
                ("spectrometer", self.spectrometer),
                ("tc08", self.tc08),
            ):
                log.info("connecting %s", name)
                device.connect()
                stack.callback(device.close)
            self._stack = stack.pop_all()
        self.connected = True

    def connect_tec(self) -> None:
        """Connect the TEC controller once (behind the Teensy, its rail must be on)."""
        if self.tec_connected:
            return
        self.tec.connect()
        self._stack.callback(self.tec.close)
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
