"""What each schedule step does with the instruments, and the record it leaves in the store.

:class:`Actions` holds the run's state (the latest S11 of each target, the Dicke cycles
of each source, the current solution, the temperature log) and has one method per step
kind. The runner (:mod:`.runner`) decides the order, repetitions and what to do on a
fault; nothing here catches errors.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from calibration.solution import Solution
from reach_receiver.acquire import (
    DickeCycle,
    TemperatureLogger,
    take_dicke_cycle,
    take_s11,
)
from reach_receiver.clock import Clock
from reach_receiver.devices.vna import S11Measurement, SweepSettings
from reach_receiver.errors import ConfigError, ReceiverError
from reach_receiver.frontend.layout import NOISE_SOURCE, REFERENCE_LOAD
from reach_receiver.instruments import Instruments
from reach_receiver.schedule import steps as st
from reach_receiver.schedule.checks import compare_test_load
from reach_receiver.schedule.lst import next_utc_at_lst
from reach_receiver.store.run_store import RunStore
from reach_receiver.store.touchstone import read_touchstone

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

#: The validation source: calibrated with each new solution, never used to make one.
VALIDATION_SOURCE = "ant"


class CheckFailed(ReceiverError):
    """A check that must pass did not (the test load after every allowed recalibration)."""


@dataclass
class CheckRecord:
    """A check's name, verdict and a one-line description, for the run's summary."""

    name: str
    passed: bool
    detail: str


@dataclass
class Actions:
    """The instruments, the store and the state a run accumulates.

    ``truth`` (simulated runs only) gives the noise-wave parameters the simulator used,
    so the summary can state the actual calibration error of the validation source.
    """

    instruments: Instruments
    store: RunStore
    truth: Callable[[FloatArray], FloatArray] | None = None
    spectrum_period_s: float = 30.0
    s11: dict[str, S11Measurement] = field(default_factory=dict)
    cycles: dict[str, list[DickeCycle]] = field(default_factory=dict)
    solution: Solution | None = None
    checks: list[CheckRecord] = field(default_factory=list)
    results: dict[str, object] = field(default_factory=dict)
    sweep: SweepSettings = field(default_factory=SweepSettings)
    temperatures: TemperatureLogger | None = None
    _stored_readings: int = 0

    @property
    def clock(self) -> Clock:
        """The run's clock."""
        return self.instruments.clock

    # ----------------------------------------------------------------- set-up and power
    def initialise(self, step: st.Initialise) -> None:
        """Connect everything, go safe, power the rails, start the temperature log."""
        devices = self.instruments
        devices.connect()
        devices.frontend.safe()
        for rail in _power_order(step.rails):
            devices.teensy.set_rail(rail, True)
        if "tec" in step.rails:
            devices.connect_tec()
        self.temperatures_step(st.Temperatures(step.where))

    def power(self, step: st.Power) -> None:
        """Switch rails."""
        for rail, on in step.states:
            self.instruments.teensy.set_rail(rail, on)

    def connect(self, step: st.Connect) -> None:
        """Connect a source to the LNA or the VNA."""
        self.instruments.frontend.connect(step.source, step.to)

    def safe(self, step: st.Safe) -> None:
        """The front-end's safe state."""
        del step
        self.instruments.frontend.safe()

    def temperatures_step(self, step: st.Temperatures) -> None:
        """(Re)start the background thermocouple log."""
        if self.temperatures is not None:
            self.flush_temperatures()
            self.temperatures.stop()
        self.temperatures = TemperatureLogger(self.instruments.tc08, self.clock, step.period_s)
        self._stored_readings = 0
        self.temperatures.start()

    def flush_temperatures(self) -> None:
        """Store the readings logged since the last flush."""
        if self.temperatures is None:
            return
        readings = self.temperatures.readings()[self._stored_readings :]
        if not readings:
            return
        channels = sorted(readings[0].raw_c)
        values = np.array([[r.temperatures_c.get(c, math.nan) for c in channels] for r in readings])
        names = [self.instruments.tc08.ports.get(c, f"port{c}") for c in channels]
        self.store.add_temperatures([r.timestamp for r in readings], values, names)
        self._stored_readings += len(readings)

    def tec(self, step: st.Tec) -> None:
        """Set the enclosure temperature and, if asked, wait until it is stable."""
        self.instruments.connect_tec()
        tec = self.instruments.tec
        tec.set_setpoint(step.setpoint_c)
        if step.wait is not None:
            wait = step.wait
            status = tec.wait_until_stable(wait.tolerance_c, wait.hold_s, wait.timeout_s)
            log.info("enclosure stable at %.3f C", status.temperature)

    def wait(self, step: st.Wait) -> None:
        """Wait a duration, or until a UTC time or a local sidereal time."""
        now = self.clock.now()
        if step.seconds is not None:
            target = now + step.seconds
        elif step.until_utc is not None:
            target = step.until_utc.timestamp()
        elif step.until_lst_h is not None:
            from datetime import datetime, timezone

            after = datetime.fromtimestamp(now, tz=timezone.utc)
            longitude = self.instruments.site.longitude_deg
            target = next_utc_at_lst(after, step.until_lst_h, longitude).timestamp()
        else:
            return
        self.clock.sleep(max(0.0, target - now))

    # ----------------------------------------------------------------- the VNA
    def vna_calibrate(self, step: st.VnaCalibrate) -> None:
        """Configure the sweep and calibrate with the MS2 short, open and load."""
        given = {k: v for k, v in vars(step.sweep).items() if v is not None}
        self.sweep = replace(SweepSettings(), **given)
        self._calibrate_vna()
        self.store.add_event("vna_calibrated", str(self.sweep), timestamp=self.clock.now())

    def _calibrate_vna(self) -> None:
        devices = self.instruments

        def connect_standard(standard: str) -> None:
            devices.frontend.connect(standard, "vna")

        devices.vna.configure(self.sweep)
        devices.vna.calibrate_sol(connect_standard)

    def test_load_check(self, step: st.TestLoadCheck) -> None:
        """Measure the test load against its reference; recalibrate and retry on failure."""
        reference = step.reference or self.instruments.site.references.get("test_load")
        if reference is None:
            raise ConfigError("test_load_check: no reference file (step or site references)")
        ref_freq, ref_s11, _ = read_touchstone(Path(reference))
        for attempt in range(step.retries + 1):
            measured = take_s11(self.instruments.frontend, self.instruments.vna, "test_load")
            inside = (measured.freq_hz >= ref_freq[0]) & (measured.freq_hz <= ref_freq[-1])
            f = measured.freq_hz[inside]
            ref = np.interp(f, ref_freq, ref_s11.real) + 1j * np.interp(f, ref_freq, ref_s11.imag)
            verdict = compare_test_load(
                measured.s11[inside], ref, f, step.tolerance, step.statistic
            )
            detail = (
                f"{verdict.statistic} deviation {100 * verdict.value:.2f} % "
                f"(tolerance {100 * step.tolerance:.0f} %), attempt {attempt + 1}"
            )
            self.store.add_s11(
                f"test_load_{attempt}", measured.freq_hz, measured.s11,
                timestamp=measured.timestamp, settings=vars(self.sweep), calibrated=True,
            )
            self.store.add_check(
                "test_load", verdict.passed, timestamp=self.clock.now(),
                details={"statistic": verdict.statistic, "value": verdict.value,
                         "tolerance": step.tolerance, "attempt": attempt + 1,
                         "worst_hz": verdict.worst_hz},
            )
            self.checks.append(CheckRecord("test load", verdict.passed, detail))
            if verdict.passed:
                return
            if attempt < step.retries:
                log.warning("test load check failed (%s); recalibrating the VNA", detail)
                self._calibrate_vna()
        raise CheckFailed(f"test-load check failed after {step.retries} recalibrations: {detail}")

    def s11_step(self, step: st.MeasureS11) -> None:
        """Measure and store each target's reflection."""
        for target in step.targets:
            m = take_s11(self.instruments.frontend, self.instruments.vna, target)
            self.s11[target] = m
            self.store.add_s11(
                target, m.freq_hz, m.s11, timestamp=m.timestamp,
                settings=vars(m.settings), calibrated=m.calibrated,
            )

    # ----------------------------------------------------------------- spectra
    def n_spectra(self, seconds: float) -> int:
        """Spectra that make ``seconds`` of integration at the spectrometer's period."""
        period = self.instruments.spectrometer.period or self.spectrum_period_s
        return max(1, round(seconds / period))

    def spectrum(self, step: st.MeasureSpectrum) -> None:
        """Integrate one source without Dicke switching."""
        devices = self.instruments
        state = devices.frontend.connect(step.source, "lna")
        acc = devices.spectrometer.integrate(self.n_spectra(step.seconds))
        period = devices.spectrometer.period or self.spectrum_period_s
        self.store.add_spectrum(
            step.source, acc.mean, timestamps=acc.timestamps,
            integration_s=acc.n_spectra * period, switch_state=state.as_pins(),
            timestamp=self.clock.now(),
        )

    def dicke(self, step: st.Dicke) -> None:
        """A Dicke cycle of each source, stored as soon as it is complete."""
        for source in step.sources:
            self._dicke_cycle(source, step.seconds)

    def _dicke_cycle(self, source: str, seconds: float) -> DickeCycle:
        devices = self.instruments
        cycle = take_dicke_cycle(
            devices.frontend, devices.spectrometer, source, self.n_spectra(seconds),
            self.temperatures,
        )
        self.cycles.setdefault(source, []).append(cycle)
        port = self.instruments.site.thermocouples.get(source)
        temperature, temperature_std = _source_temperature(cycle, port)
        connects = {"source": source, "load": REFERENCE_LOAD, "ns": NOISE_SOURCE}
        self.store.add_dicke(
            source,
            spectra={k: v.mean for k, v in cycle.spectra.items()},
            timestamps={k: v.timestamps for k, v in cycle.spectra.items()},
            integration_s=dict(cycle.integration_s),
            n_spectra={k: v.n_spectra for k, v in cycle.spectra.items()},
            temperature_k=temperature,
            temperature_std_k=temperature_std,
            switch_states={
                k: {"connected": connects[k], **cycle.switch_states.get(k, {})}
                for k in cycle.spectra
            },
            counters={
                k: {"packets_lost": v.packets_lost, "heaps_dropped": v.heaps_dropped}
                for k, v in cycle.spectra.items()
            },
            timestamp=self.clock.now(),
        )
        self.flush_temperatures()
        return cycle


def _source_temperature(cycle: DickeCycle, port: int | None) -> tuple[float | None, float]:
    """The source's mean thermocouple temperature during its integration and its error (K)."""
    if port is None or not cycle.temperatures.get("source"):
        return None, 0.0
    try:
        return cycle.temperature_k(port), cycle.temperature_std_k(port)
    except ReceiverError:
        return None, 0.0


def _power_order(rails: tuple[str, ...]) -> list[str]:
    """Rails in a safe switch-on order: the switch supplies before what depends on them."""
    order = ["12v", "24v", "6v", "fan", "tec", "ns"]
    return sorted(rails, key=lambda r: order.index(r) if r in order else len(order))
