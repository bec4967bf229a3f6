"""Simulated calibration runs: the forward model plus radiometer and VNA noise.

A run is generated from a :class:`ReceiverTruth` (noise-wave polynomials, gain, offset,
receiver reflection) and the reflection models of :mod:`calibration.model.reflections`:

1. noiseless powers ``P_src, P_L, P_NS`` from eqs. 3.20, 3.12 and 3.13;
2. radiometer noise on every spectrum, ``sigma_P = P / sqrt(B tau)`` with ``B`` the channel
   width and ``tau`` the integration time of that Dicke position;
3. optionally complex Gaussian noise of standard deviation ``vna_sigma`` on every measured
   reflection coefficient (the powers use the true ones): per channel, or, with
   ``vna_step_channels = L > 1``, at sweep points every ``L`` channels and carried onto the
   channels by cubic splines as the hand-over does, so that neighbouring channels share it
   (:func:`vna_reading`).

The default band and channels are the REACH ones: 50-130 MHz at 400 MSPS / 32768 =
12.207 kHz (6554 channels). The simulated receiver of ``reach_receiver.sim`` reuses
:func:`simulate_source` so that its instruments and this module agree on the physics.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..core.constants import ITPM_CHANNEL_WIDTH_HZ, REACH_CALIBRATORS
from .basis import BasisKind, PolynomialBasis
from .data import CalibrationData, Integration, SourceData
from .noise_waves import dicke_powers
from .polynomial_model import PolynomialParameters
from .reflections import lna_reflection, reach_source_reflection

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


#: Noise-diode excess noise ratio, Noisecom NC346A (thesis table 2.1), MHz -> dB.
NC346A_ENR_DB = {
    30: 6.05,
    40: 6.03,
    50: 6.00,
    60: 5.94,
    70: 5.91,
    80: 5.87,
    90: 5.84,
    100: 5.79,
    110: 5.80,
    120: 5.77,
    130: 5.80,
    140: 5.81,
    150: 5.83,
    200: 5.88,
}


def enr_noise_temperature(freq_hz: FloatArray) -> FloatArray:
    """Excess noise temperature of the noise diode, ``290 K * 10^(ENR/10)`` (eq. 2.1)."""
    mhz = np.array(sorted(NC346A_ENR_DB), dtype=float)
    enr = np.array([NC346A_ENR_DB[int(m)] for m in mhz])
    return np.asarray(290.0 * 10 ** (np.interp(np.asarray(freq_hz) / 1e6, mhz, enr) / 10))


def default_truth_coefficients(basis: PolynomialBasis) -> dict[str, list[float]]:
    """Frequency-dependent noise-wave parameters like the REACH receiver's (Legendre, K).

    ``T_NS`` follows the NC346A's ENR (table 2.1) fitted over the band; the others are
    the thesis's values (section 4.2) with smooth frequency structure added.
    """
    f = np.linspace(basis.f_lo_hz, basis.f_hi_hz, 200)
    ns = np.polynomial.legendre.legfit(basis.normalised(f), enr_noise_temperature(f), 3)
    return {
        "unc": [250.0, -12.0, 6.0, -3.0],
        "cos": [190.0, 25.0, -8.0],
        "sin": [90.0, -15.0, 10.0, 4.0],
        "NS": [float(c) for c in ns],
        "L": [300.0, 1.5, -0.8],
    }


@dataclass(frozen=True)
class ReceiverTruth:
    """Everything about the simulated receiver that a calibration should recover or cancel."""

    parameters: PolynomialParameters
    gain_coefficients: tuple[float, ...] = (1.0e-3, 0.4e-3, -0.3e-3)
    offset_coefficients_k: tuple[float, ...] = (150.0, 20.0)

    @classmethod
    def reach_like(cls, basis: PolynomialBasis) -> ReceiverTruth:
        """The default receiver: REACH-like parameters on ``basis``."""
        return cls.from_coefficients(basis, default_truth_coefficients(basis))

    @classmethod
    def from_coefficients(
        cls, basis: PolynomialBasis, coefficients: Mapping[str, Sequence[float]]
    ) -> ReceiverTruth:
        """Truth from per-parameter coefficient lists (keys: unc, cos, sin, NS, L)."""
        from .noise_waves import PARAMETERS

        orders = tuple(len(coefficients[p]) for p in PARAMETERS)
        flat = np.concatenate([np.asarray(coefficients[p], dtype=float) for p in PARAMETERS])
        return cls(PolynomialParameters(basis, orders, flat))  # type: ignore[arg-type]

    def theta(self, freq_hz: FloatArray) -> FloatArray:
        """True parameters ``(5, n_channels)``."""
        return self.parameters.evaluate(freq_hz)

    def gain(self, freq_hz: FloatArray) -> FloatArray:
        """System gain ``g`` (arbitrary power units per K)."""
        x = self.parameters.basis.normalised(freq_hz)
        return np.asarray(np.polynomial.legendre.legval(x, self.gain_coefficients), float)

    def offset_k(self, freq_hz: FloatArray) -> FloatArray:
        """Receiver offset ``T_0`` (K)."""
        x = self.parameters.basis.normalised(freq_hz)
        return np.asarray(np.polynomial.legendre.legval(x, self.offset_coefficients_k), float)


@dataclass(frozen=True)
class SimulationConfig:
    """How a calibration run is simulated. Every field has the REACH default."""

    f_lo_hz: float = 50e6
    f_hi_hz: float = 130e6
    channel_width_hz: float = ITPM_CHANNEL_WIDTH_HZ
    integration_s: float = 600.0
    calibrators: tuple[str, ...] = REACH_CALIBRATORS
    t_ambient_k: float = 298.0
    t_hot_k: float = 370.0
    vna_sigma: float = 0.0
    vna_step_channels: int = 1
    radiometer_noise: bool = True
    truth_coefficients: dict[str, list[float]] | None = field(default=None, hash=False)
    truth_basis: BasisKind = "legendre"

    def frequencies(self) -> FloatArray:
        """Channel centres covering the band at the channel width."""
        n = int(np.floor((self.f_hi_hz - self.f_lo_hz) / self.channel_width_hz)) + 1
        return np.asarray(self.f_lo_hz + self.channel_width_hz * np.arange(n), dtype=float)

    def basis(self) -> PolynomialBasis:
        """The basis of the truth coefficients on the simulated band."""
        return PolynomialBasis(self.truth_basis, self.f_lo_hz, self.f_hi_hz)

    def truth(self) -> ReceiverTruth:
        """The receiver to simulate."""
        if self.truth_coefficients is None:
            return ReceiverTruth.reach_like(self.basis())
        return ReceiverTruth.from_coefficients(self.basis(), self.truth_coefficients)

    def temperature_k(self, name: str) -> float:
        """Physical temperature of a source: the heated load is hot, the rest ambient."""
        return self.t_hot_k if name == "hot" else self.t_ambient_k


def vna_reading(
    gamma_true: ComplexArray, sigma: float, rng: np.random.Generator, step_channels: int = 1
) -> ComplexArray:
    """``gamma_true`` as a VNA reads it: circular complex noise of rms ``sigma``.

    With ``step_channels = L > 1`` the noise is drawn at every ``L``-th channel (and the
    last), the sweep's points, and the noisy points are carried onto every channel by
    cubic splines through their real and imaginary parts.
    """
    from scipy.interpolate import CubicSpline
    g = np.asarray(gamma_true, dtype=complex)
    if step_channels <= 1:
        noise = rng.standard_normal(g.shape) + 1j * rng.standard_normal(g.shape)
        return np.asarray(g + sigma * noise / np.sqrt(2))
    nodes = np.arange(0, g.size, step_channels)
    if nodes[-1] != g.size - 1:
        nodes = np.append(nodes, g.size - 1)
    noise = rng.standard_normal(nodes.shape) + 1j * rng.standard_normal(nodes.shape)
    read = g[nodes] + sigma * noise / np.sqrt(2)
    x = np.arange(g.size, dtype=float)
    spline_re = CubicSpline(nodes.astype(float), read.real)(x)
    spline_im = CubicSpline(nodes.astype(float), read.imag)(x)
    return np.asarray(spline_re + 1j * spline_im, dtype=complex)


def simulate_source(
    name: str,
    freq_hz: FloatArray,
    gamma_true: ComplexArray,
    gamma_rec_true: ComplexArray,
    temperature_k: FloatArray | float,
    truth: ReceiverTruth,
    integration: Integration,
    channel_width_hz: float,
    rng: np.random.Generator | None,
    vna_sigma: float = 0.0,
    known_temperature: bool = True,
    vna_step_channels: int = 1,
) -> SourceData:
    """One source's Dicke cycle: powers with radiometer noise (``rng=None``: noiseless)."""
    theta = truth.theta(freq_hz)
    powers = dicke_powers(
        theta,
        gamma_true,
        gamma_rec_true,
        temperature_k,
        truth.gain(freq_hz),
        truth.offset_k(freq_hz),
    )
    seconds = (integration.source_s, integration.load_s, integration.ns_s)
    noisy = []
    for p, tau in zip(powers, seconds, strict=True):
        if rng is None:
            noisy.append(np.array(p, dtype=float))
        else:
            noisy.append(p + rng.standard_normal(p.shape) * p / np.sqrt(channel_width_hz * tau))
    gamma = np.array(gamma_true, dtype=complex)
    if rng is not None and vna_sigma > 0:
        gamma = vna_reading(gamma, vna_sigma, rng, vna_step_channels)
    temp = np.broadcast_to(np.asarray(temperature_k, dtype=float), freq_hz.shape).copy()
    known_error = vna_sigma if rng is not None and vna_sigma > 0 else None
    return SourceData(
        name=name,
        gamma=gamma,
        p_source=noisy[0],
        p_load=noisy[1],
        p_ns=noisy[2],
        integration=integration,
        temperature_k=temp if known_temperature else None,
        gamma_std=known_error,
    )


@dataclass(frozen=True)
class SimulatedRun:
    """A simulated run with the truth that generated it."""

    data: CalibrationData
    truth: ReceiverTruth
    config: SimulationConfig
    validation: SourceData
    validation_noiseless: SourceData
    validation_temperature_k: FloatArray
    gamma_rec_true: ComplexArray


def simulate_run(
    config: SimulationConfig | None = None,
    rng: np.random.Generator | int | None = 0,
    validation: str = "ant",
) -> SimulatedRun:
    """Simulate a full calibration run and a validation source (the mock antenna).

    ``rng`` seeds the noise (an int, a Generator, or ``None`` for a noiseless run).
    """
    config = config or SimulationConfig()
    if isinstance(rng, int):
        rng = np.random.default_rng(rng)
    freq = config.frequencies()
    truth = config.truth()
    integration = Integration(config.integration_s, config.integration_s, config.integration_s)
    gamma_rec_true = lna_reflection(freq, config.f_lo_hz, config.f_hi_hz)
    gamma_rec = gamma_rec_true
    if rng is not None and config.vna_sigma > 0:
        gamma_rec = vna_reading(gamma_rec_true, config.vna_sigma, rng, config.vna_step_channels)
    noise_rng = rng if config.radiometer_noise else None

    def make(name: str, source_rng: np.random.Generator | None, known: bool) -> SourceData:
        return simulate_source(
            name,
            freq,
            reach_source_reflection(name, freq),
            gamma_rec_true,
            config.temperature_k(name),
            truth,
            integration,
            config.channel_width_hz,
            source_rng,
            config.vna_sigma if rng is not None else 0.0,
            known,
            config.vna_step_channels,
        )

    sources = {name: make(name, noise_rng, True) for name in config.calibrators}
    data = CalibrationData(
        freq_hz=freq,
        gamma_rec=gamma_rec,
        sources=sources,
        channel_width_hz=config.channel_width_hz,
        metadata={"simulated": True, "integration_s": config.integration_s},
        gamma_rec_std=config.vna_sigma if rng is not None and config.vna_sigma > 0 else None,
        reflection_correlation_channels=float(max(config.vna_step_channels, 1)),
    )
    t_val = np.full(freq.shape, config.temperature_k(validation))
    return SimulatedRun(
        data=data,
        truth=truth,
        config=config,
        validation=make(validation, noise_rng, False),
        validation_noiseless=simulate_source(
            validation,
            freq,
            reach_source_reflection(validation, freq),
            gamma_rec_true,
            t_val,
            truth,
            integration,
            config.channel_width_hz,
            None,
            0.0,
            False,
        ),
        validation_temperature_k=t_val,
        gamma_rec_true=gamma_rec_true,
    )
