"""Measurement procedures: a Dicke cycle, an S11, and the background temperature log.

These are the building blocks the step kinds run and the loop test drives. They depend
on the device protocols (:mod:`reach_receiver.devices.protocols`), not on driver
classes, so anything that integrates spectra, measures a reflection or reads
thermocouples can stand in. What the engine gets of them is decided in one place, the
store's hand-over (:mod:`reach_receiver.store.handover`).

A Dicke cycle (thesis 2.1.1, eq. 3.1) integrates three positions in turn: the source, the
reference load (the ambient 50 ohm calibrator, as deployed) and the noise source with its
diode powered. The calibration engine takes their ratio ``Q = (P_src - P_L) / (P_NS - P_L)``,
which cancels the receiver's gain as long as it is steady over one cycle. The first
spectrum after each switch change is discarded: it may straddle the change.

Every integration is bracketed by two reads of the board's state
(:func:`integrate_connected`): the one :meth:`FrontEnd.connect` returns, and one right
after. If the board restarted (a watchdog reset releases every switch) or any output
moved in between (the dead-man switch, anything else), the spectra did not all see the
source: the integration is discarded, the path connected again and the integration
repeated, at most :data:`MAX_REPEATS` times.
"""

from __future__ import annotations

import bisect
import logging
import math
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from reach_receiver.clock import Clock
from reach_receiver.devices.board import DEVICE as FRONT_END
from reach_receiver.devices.board import FrontEndState
from reach_receiver.devices.protocols import ReflectionMeter, SpectraSource, Thermometer
from reach_receiver.devices.spectra import AccumulatedSpectrum
from reach_receiver.devices.tc08 import Tc08Reading
from reach_receiver.devices.vna_settings import S11Measurement
from reach_receiver.errors import DeviceError, ReceiverError
from reach_receiver.frontend.layout import NOISE_SOURCE, REFERENCE_LOAD
from reach_receiver.frontend.paths import FrontEnd
from reach_receiver.store.measurements import DICKE_POSITIONS

__all__ = [
    "DICKE_POSITIONS",
    "DICKE_REFERENCES",
    "MAX_REPEATS",
    "DickeCycle",
    "Integration",
    "TemperatureLogger",
    "integrate_connected",
    "source_temperature",
    "take_dicke_cycle",
    "take_s11",
]
log = logging.getLogger(__name__)

#: What each Dicke position connects to the LNA, the source itself aside.
DICKE_REFERENCES = {"load": REFERENCE_LOAD, "ns": NOISE_SOURCE}

#: ``progress(position, averaged, n_spectra)`` after each spectrum of a Dicke cycle.
CycleProgress = Callable[[str, int, int], None]

#: Noise of one thermocouple reading when too few readings exist to measure it (K).
THERMOCOUPLE_NOISE_K = 0.1

#: Integrations of one position repeated at most after the front-end moved during them.
MAX_REPEATS = 2


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
        self._reading = threading.Lock()
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
            self.read_now()
            self.clock.wait(self._stop, self.period_s)

    def read_now(self) -> Tc08Reading | None:
        """Take one reading at once and log it (None, and a warning, if it failed)."""
        with self._reading:  # one conversion at a time: the logger's and a measurement's
            try:
                reading = self.thermometer.read()
            except ReceiverError as err:
                self.failures += 1
                log.warning("temperature log: %s", err)
                return None
        with self._lock:
            self._readings.append(reading)
        return reading

    def readings(self, start: float = -math.inf, stop: float = math.inf) -> tuple[Tc08Reading, ...]:
        """Readings taken in ``[start, stop]`` (clock time)."""
        with self._lock:
            return tuple(r for r in self._readings if start <= r.timestamp <= stop)


@dataclass(frozen=True)
class DickeCycle:
    """The three integrations of one Dicke cycle and the temperatures read during them.

    ``temperatures`` maps each position to the readings taken while it integrated;
    ``repeats`` to how often its integration was discarded and taken again because the
    front-end moved during it (:func:`integrate_connected`).
    """

    source: str
    spectra: Mapping[str, AccumulatedSpectrum]
    integration_s: Mapping[str, float]
    temperatures: Mapping[str, tuple[Tc08Reading, ...]]
    switch_states: Mapping[str, Mapping[str, str]] = field(default_factory=dict)
    repeats: Mapping[str, int] = field(default_factory=dict)

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
    progress: CycleProgress | None = None,
    between: Callable[[], None] | None = None,
) -> DickeCycle:
    """Integrate ``source``, the reference load and the noise source, ``n_spectra`` each.

    With a running :class:`TemperatureLogger`, each position keeps the readings taken
    while its averaged spectra integrated (:func:`readings_during`); a source position
    that saw none gets one reading taken at its end, before the switch moves.
    ``progress`` is called after every spectrum; it may stop the cycle by raising;
    ``between`` after each position's integration (a safe point for the monitor). A
    position during which the front-end moved is integrated again
    (:func:`integrate_connected`; a repeat reports its spectra from 1 again).

    Raises
    ------
    DeviceError
        The front-end moved during more than :data:`MAX_REPEATS` repeats of a position.
    """
    connects = {"source": source, **DICKE_REFERENCES}
    spectra: dict[str, AccumulatedSpectrum] = {}
    seconds: dict[str, float] = {}
    readings: dict[str, tuple[Tc08Reading, ...]] = {}
    states: dict[str, Mapping[str, str]] = {}
    repeats: dict[str, int] = {}
    for position in DICKE_POSITIONS:
        report = None
        if progress is not None:
            report = _position_progress(progress, position)
        taken = integrate_connected(
            frontend,
            spectrometer,
            connects[position],
            n_spectra,
            discard=discard,
            on_spectrum=report,
            label=f"Dicke cycle of {source}, {position} position",
        )
        accumulated = taken.spectrum
        states[position] = taken.state.as_pins()
        repeats[position] = taken.repeats
        spectra[position] = accumulated
        seconds[position] = integration_seconds(accumulated, spectrometer.period)
        if temperatures is not None:
            readings[position] = readings_during(
                temperatures, accumulated.timestamps, spectrometer.period or 0.0
            )
            if position == "source" and not readings[position]:
                # An integration shorter than the log's period (or a slowed reader) saw
                # no reading: read once now, the source still connected, so that a
                # calibrator is never left without its temperature.
                now = temperatures.read_now()
                readings[position] = (now,) if now is not None else ()
        log.info("%s: %s position, %d spectra", source, position, accumulated.n_spectra)
        if between is not None:
            between()
    return DickeCycle(source, spectra, seconds, readings, states, repeats)


@dataclass(frozen=True)
class Integration:
    """One integration the front-end held still for.

    ``state`` is the board's state read back when the path was connected, ``repeats``
    how many integrations before this one were discarded.
    """

    spectrum: AccumulatedSpectrum
    state: FrontEndState
    repeats: int


def integrate_connected(
    frontend: FrontEnd,
    spectrometer: SpectraSource,
    source: str,
    n_spectra: int,
    *,
    discard: int = 1,
    on_spectrum: Callable[[int, int], None] | None = None,
    label: str = "",
    max_repeats: int = MAX_REPEATS,
) -> Integration:
    """Connect ``source`` to the LNA and integrate, again if the front-end moved meanwhile.

    The state :meth:`FrontEnd.connect` reads back is compared with one read right after
    the integration (:meth:`FrontEndState.change_since`): a restart of the board (a
    watchdog reset releases every switch) or any output change means that some spectra
    saw something else than ``source``. That integration is dropped with a warning, the
    path connected again (the restart released it) and the integration repeated.

    Raises
    ------
    DeviceError
        The front-end moved during the integration and during ``max_repeats`` repeats.
    FrontEndTripped
        From the driver: the firmware's dead-man switch went safe (never repeated: the
        host lost the board for a whole timeout).
    """
    what = label or f"integration of {source}"
    repeats = 0
    while True:
        before = frontend.connect(source, "lna")
        spectrum = spectrometer.integrate(n_spectra, discard=discard, on_spectrum=on_spectrum)
        change = frontend.matrix.read_state().change_since(before)
        if change is None:
            return Integration(spectrum, before, repeats)
        if repeats >= max_repeats:
            raise DeviceError(
                FRONT_END,
                f"{what}: the front-end moved during the integration and during all "
                f"{max_repeats} repeats (last: {change}); nothing of it is kept",
            )
        repeats += 1
        log.warning(
            "%s: the front-end moved during the integration: %s; discarding it, "
            "connecting %s again and repeating it (%d of at most %d)",
            what,
            change,
            source,
            repeats,
            max_repeats,
        )


def readings_during(
    temperatures: TemperatureLogger, starts: Sequence[float], period_s: float
) -> tuple[Tc08Reading, ...]:
    """The readings taken while one of the spectra integrated, ``[t, t + period_s]``.

    Spectra that were lost or skipped leave gaps; a reading in a gap did not see what the
    averaged spectra saw (the heated load drifts), so it is left out.
    """
    ordered = sorted(starts)
    if not ordered:
        return ()
    within = temperatures.readings(ordered[0], ordered[-1] + period_s)
    kept = []
    for reading in within:
        index = bisect.bisect_right(ordered, reading.timestamp) - 1
        if index >= 0 and reading.timestamp <= ordered[index] + period_s:
            kept.append(reading)
    return tuple(kept)


def _position_progress(progress: CycleProgress, position: str) -> Callable[[int, int], None]:
    def report(done: int, total: int) -> None:
        progress(position, done, total)

    return report


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


def source_temperature(cycle: DickeCycle, port: int | None) -> tuple[float | None, float]:
    """A source's temperature during its own integration and its standard error (K).

    The mean of TC-08 ``port``'s good readings while the source position integrated
    (the port comes from the site's thermocouple table); ``(None, 0)`` when the source
    has no thermocouple or no usable reading, so that it cannot serve as a calibrator.
    """
    if port is None or not cycle.temperatures.get("source"):
        return None, 0.0
    try:
        return cycle.temperature_k(port), cycle.temperature_std_k(port)
    except ReceiverError:
        return None, 0.0
