"""What the layers above need of each instrument: small protocols, not driver classes.

The front-end model and the run layer are written against these; the drivers in this
package satisfy them structurally, and so can anything else (a bench instrument, a
future driver) without inheriting from anything. Each protocol holds only the methods
its users call, so the contract between the layers is this page.

=====================  ===============================  ===================================
protocol               satisfied by                     used by
=====================  ===============================  ===================================
:class:`Device`        every driver                     the run layer's instrument set
:class:`SwitchMatrix`  :class:`~.teensy.Teensy`         the front-end's signal paths
:class:`PowerRails`    :class:`~.teensy.Teensy`         ``initialise`` and ``power`` steps
:class:`SpectraSource` :class:`~.spectrometer.Spectrometer`  Dicke cycles and spectra
:class:`ReflectionMeter` :class:`~.vna.Vna`             S11s, SOL calibration
:class:`Thermometer`   :class:`~.tc08.Tc08`             the temperature log
:class:`TemperatureController` :class:`~.tec.Tec`       the ``tec`` step
=====================  ===============================  ===================================
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Protocol

from reach_receiver.devices.board import FrontEndState
from reach_receiver.devices.spectra import AccumulatedSpectrum
from reach_receiver.devices.tc08 import Tc08Reading
from reach_receiver.devices.tec_frames import TecStatus
from reach_receiver.devices.vna_settings import S11Measurement, SweepSettings


class Device(Protocol):
    """An instrument with an explicit connection: no I/O before :meth:`connect`."""

    def connect(self) -> object:
        """Open the link and check the instrument answers."""
        ...

    def close(self) -> None:
        """Close the link (the instrument keeps its state)."""
        ...


class SwitchMatrix(Protocol):
    """What the front-end model needs of the microcontroller."""

    def select(self, switch: str, position: int | str) -> None:
        """Drive one switch."""
        ...

    def set_rail(self, rail: str, on: bool) -> None:
        """Switch one rail."""
        ...

    def read_state(self) -> FrontEndState:
        """Read every output back."""
        ...

    def safe(self) -> FrontEndState:
        """Go to the safe state."""
        ...


class PowerRails(Protocol):
    """Power rails switched one at a time."""

    def set_rail(self, rail: str, on: bool) -> None:
        """Switch one rail."""
        ...


class SpectraSource(Protocol):
    """What a Dicke cycle needs of the spectrometer."""

    @property
    def period(self) -> float | None:
        """Integration time of one spectrum (clock seconds), once known."""
        ...

    def integrate(
        self,
        n_spectra: int,
        *,
        discard: int = 1,
        timeout_s: float | None = None,
        on_spectrum: Callable[[int, int], None] | None = None,
    ) -> AccumulatedSpectrum:
        """Average ``n_spectra`` complete spectra after dropping ``discard``."""
        ...


class ReflectionMeter(Protocol):
    """What S11 measurements and their calibration need of the VNA."""

    def configure(self, settings: SweepSettings) -> None:
        """Set the sweep and read it back."""
        ...

    def calibrate_sol(self, connect_standard: Callable[[str], None]) -> None:
        """One-port short-open-load calibration; ``connect_standard`` switches MS2."""
        ...

    def measure_s11(self) -> S11Measurement:
        """One corrected sweep."""
        ...


class Thermometer(Protocol):
    """What the temperature log needs of the thermocouple logger."""

    @property
    def ports(self) -> Mapping[int, str]:
        """Channel -> the component it measures (thesis table 2.2)."""
        ...

    def read(self) -> Tc08Reading:
        """Read every channel once."""
        ...


class TemperatureController(Protocol):
    """What the ``tec`` step needs of the enclosure's Peltier controller."""

    def set_setpoint(self, celsius: float) -> None:
        """Set the setpoint and read it back."""
        ...

    def wait_until_stable(
        self,
        tolerance_c: float,
        hold_s: float,
        timeout_s: float,
        poll_s: float = 10.0,
        on_poll: Callable[[TecStatus], None] | None = None,
    ) -> TecStatus:
        """Poll until the temperature holds within tolerance of the setpoint."""
        ...
