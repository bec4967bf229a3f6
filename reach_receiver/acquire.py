"""Measurement procedures: a Dicke cycle, an S11, temperatures, and their hand-over to the engine.

These are the building blocks the scheduler runs and the loop test drives. They depend
on small protocols, not on driver classes, so anything that integrates spectra, measures
a reflection or reads thermocouples can stand in.

A Dicke cycle (thesis 2.1.1, eq. 3.1) integrates three positions in turn: the source, the
reference load (the ambient 50 ohm calibrator, as deployed) and the noise source with its
diode powered. The calibration engine takes their ratio ``Q = (P_src - P_L) / (P_NS - P_L)``,
which cancels the receiver's gain as long as it is steady over one cycle. The first
spectrum after each switch change is discarded: it may straddle the change.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline

from calibration.data import Integration, SourceData
from reach_receiver.clock import Clock
from reach_receiver.devices.spectrometer import AccumulatedSpectrum
from reach_receiver.devices.tc08 import Tc08Reading
from reach_receiver.devices.vna import S11Measurement
from reach_receiver.errors import DeviceError, ReceiverError
from reach_receiver.frontend.layout import NOISE_SOURCE, REFERENCE_LOAD, SOURCE_THERMOCOUPLE
from reach_receiver.frontend.paths import FrontEnd

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: Dicke positions in the order they are taken, and the source each one connects.
DICKE_POSITIONS = ("source", "load", "ns")

#: Noise of one thermocouple reading when too few readings exist to measure it (K).
THERMOCOUPLE_NOISE_K = 0.1


class SpectraSource(Protocol):
    """What a Dicke cycle needs of the spectrometer."""

    @property
    def period(self) -> float | None:
        """Integration time of one spectrum (clock seconds), once known."""
        ...

    def integrate(
        self, n_spectra: int, *, discard: int = 1, timeout_s: float | None = None
    ) -> AccumulatedSpectrum:
        """Average ``n_spectra`` complete spectra after dropping ``discard``."""
        ...


class Thermometer(Protocol):
    """What a Dicke cycle needs of the thermocouple logger."""

    def read(self) -> Tc08Reading:
        """Read every channel once."""
        ...


class ReflectionMeter(Protocol):
    """What an S11 measurement needs of the VNA."""

    def measure_s11(self) -> S11Measurement:
        """One corrected sweep."""
        ...


class TemperatureLogger:
    """Reads the thermocouples every ``period_s`` of clock time on a background thread.

    Measurements then take the readings that fall inside their own integration, so a
    source whose temperature wanders (the heated load) is assigned the mean over the
    spectra that saw it, not a reading taken minutes apart. A failed reading is logged
    and skipped; the readings already taken stay.
    """

    def __init__(self, thermometer: Thermometer, clock: Clock, period_s: float = 10.0) -> None:
        self.thermometer = thermometer
        self.clock = clock
        self.period_s = period_s
        self._readings: list[Tc08Reading] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.failures = 0

    def start(self) -> None:
        """Start logging."""
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="temperature-log", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop logging and wait for the thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10.0)
            self._thread = None

    def __enter__(self) -> TemperatureLogger:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                reading = self.thermometer.read()
            except ReceiverError as err:
                self.failures += 1
                log.warning("temperature log: %s", err)
            else:
                with self._lock:
                    self._readings.append(reading)
            self.clock.sleep(self.period_s)

    def readings(self, start: float = -math.inf, stop: float = math.inf) -> tuple[Tc08Reading, ...]:
        """Readings taken in ``[start, stop]`` (clock time)."""
        with self._lock:
            return tuple(r for r in self._readings if start <= r.timestamp <= stop)


@dataclass(frozen=True)
class DickeCycle:
    """The three integrations of one Dicke cycle and the temperatures read during them.

    ``temperatures`` maps each position to the readings taken while it integrated.
    """

    source: str
    spectra: Mapping[str, AccumulatedSpectrum]
    integration_s: Mapping[str, float]
    temperatures: Mapping[str, tuple[Tc08Reading, ...]]
    switch_states: Mapping[str, Mapping[str, str]] = field(default_factory=dict)

    def temperature_k(self, port: int, position: str = "source") -> float:
        """Mean of the port's good readings during one position's integration, kelvin."""
        return mean_temperature_k(self.temperatures[position], port)

    def temperature_std_k(self, port: int, position: str = "source") -> float:
        """Standard error of :meth:`temperature_k`: the readings' scatter over sqrt(n).

        With fewer than three readings the scatter is not estimable and a single
        reading's noise is taken as :data:`THERMOCOUPLE_NOISE_K`. The scatter includes any
        real change of the temperature during the integration, which errs on the safe
        side. A thermocouple's systematic error (a calibration offset of the logger) is
        not in it.
        """
        values = good_values(self.temperatures[position], port)
        if len(values) < 3:
            return THERMOCOUPLE_NOISE_K / np.sqrt(max(len(values), 1))
        return float(np.std(values, ddof=1) / np.sqrt(len(values)))


def take_dicke_cycle(
    frontend: FrontEnd,
    spectrometer: SpectraSource,
    source: str,
    n_spectra: int,
    temperatures: TemperatureLogger | None = None,
    discard: int = 1,
) -> DickeCycle:
    """Integrate ``source``, the reference load and the noise source, ``n_spectra`` each.

    With a running :class:`TemperatureLogger`, each position keeps the readings taken
    between the start of its first averaged spectrum and the end of its last.
    """
    connects = {"source": source, "load": REFERENCE_LOAD, "ns": NOISE_SOURCE}
    spectra: dict[str, AccumulatedSpectrum] = {}
    seconds: dict[str, float] = {}
    readings: dict[str, tuple[Tc08Reading, ...]] = {}
    states: dict[str, Mapping[str, str]] = {}
    for position in DICKE_POSITIONS:
        states[position] = frontend.connect(connects[position], "lna").as_pins()
        accumulated = spectrometer.integrate(n_spectra, discard=discard)
        spectra[position] = accumulated
        seconds[position] = integration_seconds(accumulated, spectrometer.period)
        end = accumulated.stop_time + (spectrometer.period or 0.0)
        if temperatures is not None:
            readings[position] = temperatures.readings(accumulated.start_time, end)
        log.info("%s: %s position, %d spectra", source, position, accumulated.n_spectra)
    return DickeCycle(source, spectra, seconds, readings, states)


def integration_seconds(accumulated: AccumulatedSpectrum, period_s: float | None) -> float:
    """Total integration time: spectra averaged times the spectrometer's period."""
    if period_s is None or not period_s > 0:
        raise DeviceError("spectrometer", "integration period unknown (fewer than 2 spectra)")
    return accumulated.n_spectra * period_s


def take_s11(frontend: FrontEnd, vna: ReflectionMeter, target: str) -> S11Measurement:
    """Connect ``target`` (a source, ``lna`` or a standard) to the VNA and sweep once."""
    frontend.connect(target, "vna")
    return vna.measure_s11()


def good_values(readings: Sequence[Tc08Reading], port: int) -> list[float]:
    """A port's unflagged, finite readings (degrees C)."""
    values = [r.temperatures_c[port] for r in readings if port in r.good()]
    return [v for v in values if math.isfinite(v)]


def mean_temperature_k(readings: Sequence[Tc08Reading], port: int) -> float:
    """Mean of a port's unflagged readings, kelvin; an error when none is usable."""
    values = good_values(readings, port)
    if not values:
        raise ReceiverError(f"no usable thermocouple reading on TC-08 port {port}")
    return float(np.mean(values)) + 273.15


def interpolate_s11(measurement: S11Measurement, freq_hz: FloatArray) -> ComplexArray:
    """The reflection at ``freq_hz``: cubic splines through the real and imaginary parts.

    The VNA's sweep is coarser than the spectrometer's channels; reflections of the
    REACH sources are smooth on the sweep's 100 kHz grid (the 10 m cable's ripple has a
    period of about 10 MHz), so a spline loses nothing. Extrapolation is refused.
    """
    f = np.asarray(freq_hz, dtype=float)
    lo, hi = measurement.freq_hz[0], measurement.freq_hz[-1]
    if f.min() < lo or f.max() > hi:
        raise ReceiverError(
            f"S11 sweep {lo / 1e6:.3f}-{hi / 1e6:.3f} MHz does not cover "
            f"{f.min() / 1e6:.3f}-{f.max() / 1e6:.3f} MHz"
        )
    real = CubicSpline(measurement.freq_hz, measurement.s11.real)(f)
    imag = CubicSpline(measurement.freq_hz, measurement.s11.imag)(f)
    return np.asarray(real + 1j * imag, dtype=complex)


def source_data(
    cycle: DickeCycle,
    s11: S11Measurement,
    freq_hz: FloatArray,
    channels: slice,
    spectrometer_input: int = 0,
    known_temperature: bool = True,
    thermocouple: int | None = None,
) -> SourceData:
    """The engine's view of one source: S11 at the channels, Dicke powers, temperature.

    The temperature is the mean of TC-08 port ``thermocouple`` (table 2.2's port of the
    source by default) during the source's own integration.
    """
    spectra = {k: v.mean[spectrometer_input, channels] for k, v in cycle.spectra.items()}
    temperature, temperature_std = None, 0.0
    if known_temperature:
        port = SOURCE_THERMOCOUPLE[cycle.source] if thermocouple is None else thermocouple
        temperature = np.full(freq_hz.shape, cycle.temperature_k(port))
        temperature_std = cycle.temperature_std_k(port)
    return SourceData(
        name=cycle.source,
        gamma=interpolate_s11(s11, freq_hz),
        p_source=spectra["source"],
        p_load=spectra["load"],
        p_ns=spectra["ns"],
        integration=Integration(
            cycle.integration_s["source"], cycle.integration_s["load"], cycle.integration_s["ns"]
        ),
        temperature_k=temperature,
        temperature_std_k=temperature_std,
    )


def band_channels(
    channel_width_hz: float, f_lo_hz: float, f_hi_hz: float
) -> tuple[slice, FloatArray]:
    """Channels whose centres ``k * width`` lie in ``[f_lo, f_hi]``, and those centres."""
    first = math.ceil(f_lo_hz / channel_width_hz - 1e-9)
    last = math.floor(f_hi_hz / channel_width_hz + 1e-9)
    channels = slice(first, last + 1)
    return channels, channel_width_hz * np.arange(first, last + 1, dtype=float)
