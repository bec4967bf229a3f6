"""The one physical model behind every simulated instrument.

The switch state (fed from the simulated Teensy's pins) decides what the LNA and the VNA
see; the calibration engine's forward model (eqs. 3.12, 3.13, 3.20 through
:func:`calibration.model.noise_waves.dicke_powers`) turns that into power spectra; radiometer
noise ``sigma_P = P / sqrt(B tau)`` is drawn for each spectrum of duration ``tau``;
temperatures follow the enclosure (held by the simulated TEC) and a heated load that
wanders slowly.

The Dicke references are physical here, as in the deployed instrument (thesis 2.1.1):
the reference load is the ambient 50 ohm calibrator at MS1-4 and the noise source is the
NC346A diode at MS1-3, matched, adding its ENR (table 2.1, eq. 2.1) to its physical
temperature. The engine's ``T_L`` and ``T_NS`` are therefore *effective* quantities,

    T_L = (P_ref / g - T_0) / (1 - |Gamma_rec|^2),
    T_NS = (P_ns / g - T_0) / (1 - |Gamma_rec|^2) - T_L,

which :meth:`ReceiverPhysics.effective_theta` computes exactly, so that a calibration of
simulated data can be checked against the truth it should recover.

With a :class:`~reach_receiver.sim.drift.NoiseWaveDrift` (``PhysicsConfig.drift``; none by
default) the LNA's noise waves follow its temperature, which may ramp slowly.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from calibration.model.basis import PolynomialBasis
from calibration.model.data import CalibrationData, SourceData
from calibration.model.noise_waves import dicke_powers
from calibration.model.reflections import lna_reflection, reach_source_reflection, resistor
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, ReceiverTruth, enr_noise_temperature
from reach_receiver.clock import Clock
from reach_receiver.frontend.layout import (
    MS2_TO_LNA,
    MS2_TO_SOURCES,
    NOISE_SOURCE,
    REFERENCE_LOAD,
    SOURCE_THERMOCOUPLE,
    VNA_STANDARDS,
    source_at,
)
from reach_receiver.sim.drift import NoiseWaveDrift
from reach_receiver.sim.effects import SimEffects

if TYPE_CHECKING:  # the engine's solvers: only the simulator's checks take a solution
    from calibration.solve.solvers import NoiseWaveSolution

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

KELVIN_AT_0C = 273.15

#: What an unconnected port looks like to the receiver and the VNA: an open circuit.
OPEN = "open"


@dataclass(frozen=True)
class PhysicsConfig:
    """Settings of the simulated receiver's physics.

    The noise-wave model is defined on ``[f_lo_hz, f_hi_hz]`` (the REACH band); outside
    it the spectra carry the band-edge values, which no calibration uses.
    """

    f_lo_hz: float = 50e6
    f_hi_hz: float = 130e6
    n_channels: int = 16384
    channel_width_hz: float = ITPM_CHANNEL_WIDTH_HZ
    t_hot_k: float = 370.0
    hot_wander_k: float = 0.3
    hot_wander_period_s: float = 5400.0
    lna_above_enclosure_k: float = 2.0
    outdoor_c: float = 18.0
    outdoor_swing_c: float = 8.0
    seed: int = 0
    effects: SimEffects = field(default_factory=SimEffects)
    drift: NoiseWaveDrift | None = None


class ReceiverPhysics:
    """State and physics of the simulated front-end, shared by all simulated instruments.

    Thread-safe: the spectrometer's sender thread, the VNA server and the Teensy's pin
    reader all call in.

    Parameters
    ----------
    clock
        The simulation's clock (time stamps, drift, the heated load's wander).
    config
        Physical settings.
    enclosure_c
        The enclosure's temperature now, in degrees C (the simulated TEC's plate).
    truth
        The receiver's noise waves, gain and offset; REACH-like by default.
    """

    def __init__(
        self,
        clock: Clock,
        config: PhysicsConfig | None = None,
        enclosure_c: Callable[[], float] | None = None,
        truth: ReceiverTruth | None = None,
    ) -> None:
        self.clock = clock
        self.config = config or PhysicsConfig()
        self._enclosure_c = enclosure_c or (lambda: 25.0)
        basis = PolynomialBasis("legendre", self.config.f_lo_hz, self.config.f_hi_hz)
        self.truth = truth or ReceiverTruth.reach_like(basis)
        self.freq_hz = self.config.channel_width_hz * np.arange(self.config.n_channels)
        self._model_freq = np.clip(self.freq_hz, self.config.f_lo_hz, self.config.f_hi_hz)
        self._gamma_rec = lna_reflection(self._model_freq, self.config.f_lo_hz, self.config.f_hi_hz)
        self._theta = self.truth.theta(self._model_freq)
        self._gain = self.truth.gain(self._model_freq)
        self._offset = self.truth.offset_k(self._model_freq)
        self._enr_k = self.enr_k(self._model_freq)
        self._rng = np.random.default_rng(self.config.seed)
        self._lock = threading.Lock()
        self._pins: dict[str, str] = {}
        self._t0 = clock.now()
        #: Called before every measurement to take in pin changes not yet reported
        #: (the simulated Teensy's ``sync``): a measurement never sees stale switches.
        self.sync_pins: Callable[[], None] = lambda: None

    # ----------------------------------------------------------------- switch state
    def update_pins(self, pins: Mapping[str, str]) -> None:
        """Take the microcontroller's output state (the ``PINS``/``state`` payload)."""
        with self._lock:
            self._pins = dict(pins)

    def _pin(self, name: str, default: str = "0") -> str:
        with self._lock:
            return self._pins.get(name, default)

    def _on(self, rail: str) -> bool:
        return self._pin(rail) == "1"

    def _position(self, switch: str, rail: str) -> int:
        return int(self._pin(switch)) if self._on(rail) else 0

    def lna_input(self) -> str:
        """The source at the LNA's input (``"open"`` when nothing is connected)."""
        if self._pin("mts", "lna") != "lna":
            return OPEN
        source = source_at(
            self._position("ms1", "12v"), self._position("ms3", "12v"), self._position("ms4", "12v")
        )
        return source or OPEN

    def vna_target(self) -> str:
        """What the VNA's port sees through MS2 and the MTS (a source, ``lna``, a standard)."""
        ms2 = self._position("ms2", "24v")
        to_vna = self._pin("mts", "lna") == "vna" and self._on("24v")
        if ms2 == MS2_TO_SOURCES and to_vna:
            source = source_at(
                self._position("ms1", "12v"),
                self._position("ms3", "12v"),
                self._position("ms4", "12v"),
            )
            return source or OPEN
        if ms2 == MS2_TO_LNA and to_vna:
            return "lna"
        for standard, position in VNA_STANDARDS.items():
            if ms2 == position:
                return standard
        return OPEN

    # ----------------------------------------------------------------- reflections
    def reflection(self, name: str, freq_hz: FloatArray) -> ComplexArray:
        """True reflection coefficient of a source, the LNA or a VNA standard."""
        f = np.clip(np.asarray(freq_hz, dtype=float), 1.0, None)
        if name == "lna":
            return lna_reflection(f, self.config.f_lo_hz, self.config.f_hi_hz)
        fixed = {"short": -1.0, "open": 1.0, "load": 0.0, OPEN: 1.0, NOISE_SOURCE: 0.0}
        if name in fixed:
            return np.full(f.shape, fixed[name], dtype=complex)
        if name == "test_load":
            return resistor(f, 50.8, lead_inductance_h=0.6e-9)
        return reach_source_reflection(name, f)

    def reflection_at_vna(self, freq_hz: FloatArray) -> ComplexArray:
        """What the VNA measures at its port now, before its own error model."""
        self.sync_pins()
        target = self.vna_target()
        gamma = self.reflection(target, freq_hz)
        if target in (*VNA_STANDARDS, OPEN, "lna"):
            return gamma
        f = np.clip(np.asarray(freq_hz, dtype=float), 1.0, None)
        return self.config.effects.at_vna(gamma, f)

    # ----------------------------------------------------------------- temperatures
    def enclosure_k(self) -> float:
        """The enclosure's temperature now (K)."""
        return self._enclosure_c() + KELVIN_AT_0C

    def hot_k(self, t: float) -> float:
        """The heated load's temperature: its setpoint plus a slow wander."""
        c = self.config
        phase = 2 * math.pi * (t - self._t0) / c.hot_wander_period_s
        return c.t_hot_k + c.hot_wander_k * math.sin(phase)

    def outdoor_c(self, t: float) -> float:
        """Air temperature at the antenna: a daily swing."""
        c = self.config
        return c.outdoor_c + c.outdoor_swing_c * math.sin(2 * math.pi * (t % 86400.0) / 86400.0)

    def source_temperature_k(self, name: str, t: float) -> float:
        """Physical temperature of a source at time ``t`` (its thermocouple's truth)."""
        if name == "hot":
            return self.hot_k(t)
        if name == "ant":
            return self.outdoor_c(t) + KELVIN_AT_0C
        return self.enclosure_k()

    def lna_c(self, t: float) -> float:
        """The LNA's temperature (C): the enclosure's, its own heating, any drift's ramp."""
        lna = self.enclosure_k() - KELVIN_AT_0C + self.config.lna_above_enclosure_k
        drift = self.config.drift
        return lna if drift is None else lna + drift.ramp_k(t - self._t0)

    def theta_at(self, t: float, freq_hz: FloatArray | None = None) -> FloatArray:
        """The receiver's parameters ``(5, n)`` at time ``t`` (its drift applied).

        On the physics' own channels unless ``freq_hz`` is given.
        """
        theta = self._theta if freq_hz is None else self.truth.theta(np.asarray(freq_hz, float))
        drift = self.config.drift
        return theta if drift is None else drift.theta(theta, self.lna_c(t))

    def thermocouples_c(self, t: float) -> list[float]:
        """True temperatures of TC-08 ports 0-8 (table 2.2), degrees C."""
        enclosure = self.enclosure_k() - KELVIN_AT_0C
        terminations = enclosure
        if self.config.effects.cable_gradient:
            terminations += self.config.effects.termination_above_cable_k
        return [
            enclosure + 1.0,
            enclosure,
            self.hot_k(t) - KELVIN_AT_0C,
            terminations,
            terminations,
            enclosure,
            enclosure,
            self.lna_c(t),
            self.outdoor_c(t),
        ]

    def mcp9808_c(self) -> dict[int, float]:
        """The front-end's I2C sensors (addresses 0x18-0x1B): enclosure and LNA board."""
        enclosure = self.enclosure_k() - KELVIN_AT_0C
        lna = self.lna_c(self.clock.now())
        return {0x18: enclosure, 0x19: enclosure + 0.2, 0x1A: lna, 0x1B: enclosure - 0.1}

    # ----------------------------------------------------------------- spectra
    def noiseless_power(self, name: str, t: float, ns_on: bool | None = None) -> FloatArray:
        """``P = g (T_src (1-|G|^2)|F|^2 + noise waves + T_0)`` for the source at the LNA.

        Every channel, at time ``t``, effects on; the noise source's diode is powered as
        ``ns_on`` says (default: as its pin is now).
        """
        t_src: float | FloatArray = self.source_temperature_k(name, t)
        diode = self._on("ns") if ns_on is None else ns_on
        if name == NOISE_SOURCE and diode:
            t_src = self.enclosure_k() + self._enr_k
        elif name == "ant":
            t_src = self.sky_temperature_k(self._model_freq, t)
        return self._power(name, t_src, t)

    def _power(self, name: str, t_src: float | FloatArray, t: float) -> FloatArray:
        """The LNA's noiseless power for ``name`` at ``t_src`` (its own plane; effects on)."""
        effects = self.config.effects
        f = self._model_freq
        gamma = self.reflection(name, f)
        if effects.any:
            cable = effects.cables().get(name)
            if cable is not None and isinstance(t_src, float):
                t_cab = self.thermocouples_c(t)[cable[1]] + KELVIN_AT_0C
                t_term = self.thermocouples_c(t)[self.thermocouple_of(name)] + KELVIN_AT_0C
                t_src = effects.through_cable(name, gamma, f, t_term, t_cab)
            gamma, t_src = effects.through_mts(gamma, t_src, f, self.enclosure_k())
        theta = self.theta_at(t)
        p, _, _ = dicke_powers(theta, gamma, self._gamma_rec, t_src, self._gain, self._offset)
        return np.asarray(p, dtype=float)

    def true_temperature_k(
        self, name: str, q: FloatArray, freq_hz: FloatArray, t: float | None = None
    ) -> FloatArray:
        """The temperature at the sources' plane that gives the measured ``q`` (eq. 3.21).

        The forward model is linear in the source's temperature, ``P = P_0 + T dP``, so
        ``T = (Q (P_NS - P_L) + P_L - P_0) / dP`` with the noiseless references: with or
        without :mod:`~reach_receiver.sim.effects`, the truth a calibration is judged by.
        ``freq_hz`` must be channel centres of the spectrometer; ``t`` is when ``q`` was
        measured (the physics' start by default; it matters only with a drift or effects).
        """
        k = np.rint(np.asarray(freq_hz) / self.config.channel_width_hz).astype(int)
        t = self._t0 if t is None else t
        p0 = self._power(name, np.zeros(self._model_freq.shape), t)[k]
        dp = self._power(name, np.ones(self._model_freq.shape), t)[k] - p0
        p_l = self.noiseless_power(REFERENCE_LOAD, t)[k]
        p_ns = self.noiseless_power(NOISE_SOURCE, t, ns_on=True)[k]
        return np.asarray((np.asarray(q) * (p_ns - p_l) + p_l - p0) / dp, dtype=float)

    def sky_temperature_k(self, freq_hz: FloatArray, t: float) -> FloatArray:
        """A sky-like antenna temperature: a power law, ``T = 2000 K (f / 75 MHz)^-2.5``."""
        del t
        return np.asarray(2000.0 * (np.asarray(freq_hz) / 75e6) ** -2.5, dtype=float)

    def spectrum(self, t_start: float, duration_s: float) -> FloatArray:
        """Spectra of both spectrometer inputs over ``[t_start, t_start + duration_s]``.

        Input 0 is the receiver's LNA, input 1 a second front-end's terminated input. Each
        channel gets radiometer noise ``P / sqrt(B tau)``. With the LNA rail off there is
        no signal, only a floor ten orders of magnitude down.
        """
        self.sync_pins()
        t_mid = t_start + 0.5 * duration_s
        radiometer = 1.0 / math.sqrt(self.config.channel_width_hz * duration_s)
        if self._on("6v"):
            p0 = self.noiseless_power(self.lna_input(), t_mid)
            if self.config.effects.rfi:
                with self._lock:
                    n_lines = len(self.config.effects.rfi_channels_hz)
                    draws = np.asarray(self._rng.exponential(size=n_lines), dtype=float)
                spikes = self.config.effects.spikes(np.asarray(self.freq_hz, dtype=float), draws)
                p0 = np.asarray(p0 * (1.0 + spikes), dtype=float)
        else:
            p0 = np.full(self.freq_hz.shape, 1e-10 * float(np.mean(self._gain)))
        p1 = self.noiseless_power(REFERENCE_LOAD, t_mid)
        out = np.stack([p0, p1])
        with self._lock:
            noise = self._rng.standard_normal(out.shape)
        return np.asarray(out * (1.0 + radiometer * noise), dtype=float)

    # ----------------------------------------------------------------- the truth
    def effective_theta(self, freq_hz: FloatArray, t: float | None = None) -> FloatArray:
        """The noise-wave parameters ``(5, n)`` a perfect calibration recovers (eqs. above).

        At time ``t`` (now by default): it matters only with a drift.
        """
        f = np.asarray(freq_hz, dtype=float)
        theta = self.theta_at(self.clock.now() if t is None else t, f)
        gamma_rec = lna_reflection(f, self.config.f_lo_hz, self.config.f_hi_hz)
        gain = self.truth.gain(f)
        offset = self.truth.offset_k(f)
        rec_match = 1.0 - np.abs(gamma_rec) ** 2
        gamma_ref = self.reflection(REFERENCE_LOAD, f)
        p_ref, _, _ = dicke_powers(theta, gamma_ref, gamma_rec, self.enclosure_k(), gain, offset)
        t_ns = self.enclosure_k() + self.enr_k(f)
        zero = np.zeros(f.shape, dtype=complex)
        p_ns, _, _ = dicke_powers(theta, zero, gamma_rec, t_ns, gain, offset)
        t_l = (p_ref / gain - offset) / rec_match
        effective = theta.copy()
        effective[4] = t_l
        effective[3] = (p_ns / gain - offset) / rec_match - t_l
        return effective

    def calibration_error_k(
        self, solution: NoiseWaveSolution, data: CalibrationData, source: SourceData
    ) -> float:
        """RMS over the band of ``T_cal(Q) - T_true(Q)`` for ``source`` (kelvin).

        Both temperatures use the same measured Q (eq. 3.21), so the difference is the
        error the calibration adds, which its posterior predicts, plus that of the
        reflections measured for this source (the VNA's trace noise on its S11 and the
        receiver's). ``T_true`` is :meth:`true_temperature_k`, at the sources' plane: with
        :mod:`~reach_receiver.sim.effects` on, the receiver seen from the sources is the
        MTS path and the LNA together, whose noise waves are not the LNA's own
        (:meth:`effective_theta`), so these could not judge a corrected calibration.
        """
        return float(np.sqrt(np.mean(self.calibration_errors_k(solution, data, source) ** 2)))

    def calibration_errors_k(
        self, solution: NoiseWaveSolution, data: CalibrationData, source: SourceData
    ) -> FloatArray:
        """``T_cal(Q) - T_true(Q)`` per channel (:meth:`calibration_error_k`)."""
        freq = data.freq_hz
        spectrum = solution.calibrate(freq, data.gamma_rec, source)
        true_t = self.true_temperature_k(source.name, source.q, freq)
        return np.asarray(spectrum.mean - true_t, dtype=float)

    def enr_k(self, freq_hz: FloatArray) -> FloatArray:
        """The noise diode's excess temperature: a cubic through table 2.1's ENR (eq. 2.1).

        A real diode's output is smooth; the table's straight-line interpolation between
        its 10 MHz points would put kinks into the spectrum that no diode has.
        """
        band = np.linspace(self.config.f_lo_hz, self.config.f_hi_hz, 200)
        span = self.config.f_hi_hz - self.config.f_lo_hz
        centre = self.config.f_lo_hz + self.config.f_hi_hz

        def x(f: FloatArray) -> FloatArray:
            return np.asarray((2 * np.asarray(f) - centre) / span, dtype=float)

        coefficients = np.polynomial.legendre.legfit(x(band), enr_noise_temperature(band), 3)
        return np.asarray(np.polynomial.legendre.legval(x(freq_hz), coefficients), dtype=float)

    def thermocouple_of(self, source: str) -> int:
        """The TC-08 port that measures ``source``'s temperature (table 2.2)."""
        return SOURCE_THERMOCOUPLE[source]
