"""The whole simulated receiver: one physical model behind five instruments on real transports.

================  =======================================  ===============================
instrument        simulator                                transport the driver uses
================  =======================================  ===============================
Teensy 3.5        the firmware's host build                pseudo-terminal (pyserial)
TEC controller    :class:`~.tec.TecSimulator`              pty on the Teensy's UART1, or
                                                           its own pty
VNA               :class:`~.vna.VnaSimulator`              TCP SCPI socket (pyvisa-py)
spectrometer      :class:`~.itpm.ItpmSimulator`            UDP datagrams
TC-08             :class:`~.tc08_standin.Tc08StandIn`      a stand-in ``libusbtc08.so``
================  =======================================  ===============================

Every simulator reads the same :class:`~.physics.ReceiverPhysics`: the firmware's pin
changes tell it which way the switches point, the TEC's plate is the enclosure's
temperature, and the VNA and the spectrometer see whatever the switches connect. All
share one clock, compressed in dry runs so that hours of integration take seconds while
the spectra carry the radiometer noise of hours. Every simulator listens on, and sends
from, loopback only, and the site names the simulated iTPM's address and port as the
spectra's only source.
"""

from __future__ import annotations

import logging
import socket
import tempfile
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from reach_receiver.clock import Clock, CompressedClock
from reach_receiver.config.corrections import CorrectionSettings
from reach_receiver.config.monitoring import MonitoringSettings
from reach_receiver.config.settings import (
    DeviceSettings,
    SpectrometerSettings,
    Tc08Settings,
    TecSettings,
    TeensySettings,
    VnaSettings,
)
from reach_receiver.config.site import SiteConfig
from reach_receiver.errors import ReceiverError
from reach_receiver.sim.itpm import ItpmSimulator
from reach_receiver.sim.physics import PhysicsConfig, ReceiverPhysics
from reach_receiver.sim.tc08_standin import Tc08StandIn
from reach_receiver.sim.tec import TecSimulator
from reach_receiver.sim.teensy_firmware import FirmwareTeensy
from reach_receiver.sim.vna import VnaSimulator
from reach_receiver.store.touchstone import write_touchstone

log = logging.getLogger(__name__)

#: Simulated seconds per real second of a dry run: an hour of integration in 1.2 s.
DEFAULT_COMPRESSION = 3000.0
#: Where every simulator listens and sends from: nothing of a simulation reaches the network.
LOOPBACK = "127.0.0.1"
#: Spectra a real second the simulated iTPM sends at most (see spectrum_period_for).
MAX_SPECTRA_PER_REAL_S = 100.0

#: The TC-08 stand-in's values file is rewritten at most this often per real second (every
#: simulated second in real time; every 60 s at 3000x, when the heated load, the fastest
#: source, moves 0.02 K, below the readings' 0.05 K noise).
TC08_REWRITES_PER_REAL_S = 50.0

#: Health samples a real second the simulated site asks of ``reachd`` at most (see
#: monitor_cadence_for).
MONITOR_SAMPLES_PER_REAL_S = 4.0


@dataclass(frozen=True)
class SimulationSettings:
    """How the simulated receiver runs.

    ``spectrum_period_s`` is the iTPM's integration per spectrum (simulated seconds): long
    periods keep the packet rate low at high compression without changing the noise of
    an integration, which depends only on its total duration.
    """

    compression: float = DEFAULT_COMPRESSION
    spectrum_period_s: float = 30.0
    seed: int = 0
    ambient_c: float = 25.0
    enclosure_start_c: float | None = None
    tec_tau_s: float = 600.0
    vna_drift_per_hour: float = 0.001
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)


def spectrum_period_for(compression: float) -> float:
    """The simulated iTPM's accumulation period for a time compression (s).

    At most :data:`MAX_SPECTRA_PER_REAL_S` spectra a real second (each 256 UDP packets)
    and never shorter than REACH's own 1 s: 30 s at the default 3000x.
    """
    return max(1.0, compression / MAX_SPECTRA_PER_REAL_S)


def monitor_cadence_for(compression: float) -> float:
    """The simulated site's health cadence (s): a minute, or longer at high compression.

    A sample asks the board, the TEC and the TC-08 and commits a transaction; one a
    simulated minute at 3000x would be 50 a real second, half a core for an idle
    ``reachd --sim``. At most :data:`MONITOR_SAMPLES_PER_REAL_S` a real second instead
    (750 s at 3000x; REACH's minute from 240x down).
    """
    return max(60.0, compression / MONITOR_SAMPLES_PER_REAL_S)


def simulated_site(
    settings: SimulationSettings,
    devices: DeviceSettings | None = None,
    **fields: Any,
) -> SiteConfig:
    """The site file of the simulated receiver (REACH's place in the Karoo).

    Without ``devices``, the instruments' addresses are placeholders: the site for
    checking and timing a schedule before the simulators start.
    """
    if devices is None:
        devices = DeviceSettings(
            teensy=TeensySettings(port="<simulated>"),
            vna=VnaSettings(resource="<simulated>"),
            tec=TecSettings(via="teensy"),
            tc08=Tc08Settings(),
            spectrometer=SpectrometerSettings(
                period_s=settings.spectrum_period_s, host=LOOPBACK, source=LOOPBACK
            ),
        )
    return SiteConfig(
        devices=devices,
        name="simulated receiver",
        longitude_deg=21.52,
        latitude_deg=-30.97,
        source="reach-sim",
        **fields,
    )


def free_udp_port(host: str = LOOPBACK) -> int:
    """A UDP port nobody is bound to right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind((host, 0))
        return int(probe.getsockname()[1])


class SimulatedReceiver:
    """Starts, wires and stops every simulated instrument.

    Parameters
    ----------
    settings
        Simulation settings.
    clock
        The shared clock; a :class:`CompressedClock` at ``settings.compression`` by default.
    spectrometer_port
        UDP port the spectra are sent to (where the spectrometer driver listens); a free
        one by default.
    workdir
        Where the TC-08 stand-in library is built; a temporary directory by default.
    """

    def __init__(
        self,
        settings: SimulationSettings | None = None,
        clock: Clock | None = None,
        spectrometer_port: int | None = None,
        workdir: Path | None = None,
    ) -> None:
        self.settings = settings or SimulationSettings()
        self.clock = clock or CompressedClock(self.settings.compression)
        self.spectrometer_address = (LOOPBACK, spectrometer_port or free_udp_port())
        self._tmp = None if workdir else tempfile.TemporaryDirectory(prefix="reach-sim-")
        self.workdir = workdir or Path(self._tmp.name if self._tmp else ".")
        s = self.settings
        self.tec = TecSimulator(
            self.clock,
            ambient_c=s.ambient_c,
            tau_s=s.tec_tau_s,
            initial_c=s.enclosure_start_c,
        )
        self.physics = ReceiverPhysics(self.clock, s.physics, enclosure_c=self.tec.temperature_c)
        self.vna = VnaSimulator(
            self.physics.reflection_at_vna,
            self.clock,
            seed=s.seed,
            drift_rate_per_s=s.vna_drift_per_hour / 3600.0,
        )
        self.itpm = ItpmSimulator(
            self.physics.spectrum,
            self.clock,
            self.spectrometer_address,
            period_s=s.spectrum_period_s,
            sender=(LOOPBACK, 0),
            seed=s.seed,
        )
        self.teensy: FirmwareTeensy | None = None
        self.tc08: Tc08StandIn | None = None
        self.test_load_reference = self.workdir / "test_load_reference.s1p"
        self._two_ports: dict[str, str] = {}
        self._stop = threading.Event()
        self._sensor_thread: threading.Thread | None = None
        self._started = False

    def start(self) -> SiteConfig:
        """Start every simulator; return the site configuration that reaches them."""
        tec_port = self.tec.start()
        self.teensy = FirmwareTeensy(uart1=tec_port)
        self.teensy.start()
        self.teensy.on_change(self.physics.update_pins)
        self.physics.sync_pins = self.teensy.sync
        self.physics.update_pins(self.teensy.state)
        self._refresh_sensors()
        self._stop.clear()
        self._sensor_thread = threading.Thread(
            target=self._follow_enclosure, name="mcp9808-sim", daemon=True
        )
        self._sensor_thread.start()
        self.vna.start()
        self.itpm.start()
        self.tc08 = Tc08StandIn(
            self.workdir / "tc08",
            self.physics.thermocouples_c,
            self.clock,
            update_s=max(1.0, self.settings.compression / TC08_REWRITES_PER_REAL_S),
        )
        self.tc08.start()
        self.test_load_reference = self._write_test_load_reference()
        self._two_ports = self.physics.config.effects.write_two_ports(self.workdir)
        self._started = True
        log.info("simulated receiver started: %s", self.site().devices)
        return self.site()

    def _refresh_sensors(self) -> None:
        if self.teensy is not None:
            for address, celsius in self.physics.mcp9808_c().items():
                self.teensy.set_sensor(address, celsius)

    def _follow_enclosure(self) -> None:
        """Keep the simulated MCP9808s on the enclosure's temperature (every 10 sim minutes)."""
        simulated_s = 600.0
        clock = self.clock
        real_s = simulated_s
        if isinstance(clock, CompressedClock):
            real_s = clock.real_seconds(simulated_s)
        while not self._stop.wait(real_s):
            try:
                self._refresh_sensors()
            except ReceiverError:  # the firmware is shutting down
                return

    def _write_test_load_reference(self) -> Path:
        """The lab (PNA-X) measurement of the MS2-6 test load, as a Touchstone file.

        The simulated lab instrument is ten times quieter than the field VNA at REACH's
        settings: the true reflection plus 2e-5 of complex noise, 40-180 MHz at 0.5 MHz.
        """
        freq = np.arange(40e6, 180e6 + 1.0, 0.5e6)
        rng = np.random.default_rng(self.settings.seed + 7)
        noise = 2e-5 * (rng.standard_normal(freq.size) + 1j * rng.standard_normal(freq.size))
        path = self.workdir / "test_load_reference.s1p"
        s11 = self.physics.reflection("test_load", freq) + noise / np.sqrt(2)
        write_touchstone(path, freq, s11, comment="simulated PNA-X measurement of MS2-6")
        return path

    def site(self) -> SiteConfig:
        """The site configuration of the running simulators."""
        if self.teensy is None or self.tc08 is None:
            raise RuntimeError("the simulated receiver is not started")
        host, port = self.spectrometer_address
        source, source_port = self.itpm.bind()
        return simulated_site(
            self.settings,
            devices=DeviceSettings(
                teensy=TeensySettings(port=self.teensy.port),
                vna=VnaSettings(resource=self.vna.address),
                tec=TecSettings(via="teensy"),
                tc08=Tc08Settings(library=str(self.tc08.library)),
                spectrometer=SpectrometerSettings(
                    period_s=self.settings.spectrum_period_s,
                    host=host,
                    port=port,
                    source=source,
                    source_port=source_port,
                ),
            ),
            references={"test_load": str(self.test_load_reference)},
            corrections=self.corrections(),
            simulation=self.clock.parameters if isinstance(self.clock, CompressedClock) else {},
            monitoring=MonitoringSettings(cadence_s=monitor_cadence_for(self.clock_factor())),
        )

    def clock_factor(self) -> float:
        """How many times faster than real time the simulation's clock runs."""
        return self.clock.factor if isinstance(self.clock, CompressedClock) else 1.0

    def corrections(self) -> CorrectionSettings:
        """What the site file says of the simulated effects' two-ports, cables and RFI."""
        return self.physics.config.effects.site_corrections(self._two_ports)

    def close(self) -> None:
        """Stop every simulator (in reverse order of start) and remove temporary files."""
        self._stop.set()
        if self._sensor_thread is not None:
            self._sensor_thread.join(timeout=5)
            self._sensor_thread = None
        for stop in (
            self.tc08.close if self.tc08 else None,
            self.itpm.stop,
            self.vna.close,
            self.teensy.close if self.teensy else None,
            self.tec.stop,
        ):
            if stop is None:
                continue
            try:
                stop()
            except Exception:  # a stop that fails must not keep the others running
                log.exception("stopping a simulator failed")
        self.physics.sync_pins = lambda: None
        self.teensy = None
        self.tc08 = None
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self) -> SimulatedReceiver:
        try:
            self.start()
        except BaseException:
            # A Ctrl-C or SIGINT mid-start (reachd --sim's first second): what had started
            # is stopped, else its threads keep the interpreter from exiting.
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
