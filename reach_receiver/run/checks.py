"""The run's checks: the VNA's test load, a new solution against a benchmark and its forerunner.

Pure functions of arrays, so each is tested on its own and the runner only records
their verdicts.

* **Test load** (thesis 2.1.1): the MS2-6 50 ohm test load measured after the SOL
  calibration is compared, frequency by frequency, with a reference measurement (a PNA-X
  file): ``d(f) = |S11(f) - S11_ref(f)| / |S11_ref(f)|``. The verdict uses a statistic of
  ``d`` over the band: ``max`` is the thesis's literal reading; ``p95`` (the default) is
  robust to the noise of a -40 dB load, whose relative scatter is a few percent at
  REACH's sweep settings, so that the maximum over 1401 points exceeds 5 % by chance.
* **Benchmark** (thesis 2.1.3: "previous calibration coefficients to within 5 %"): the
  polynomial coefficients depend on the basis and order, so the comparison is made on
  the parameters themselves, band-averaged: ``|<T_new> - <T_ref>| / |<T_ref>|`` for each
  of T_unc, T_cos, T_sin, T_NS, T_L.
* **Drift** (:func:`compare_on_source`): a new solution against the previous one, on one
  source's calibrated temperature. A tolerance on each parameter (the benchmark's) says
  nothing of what the difference means for the sky; this check asks whether the two
  solutions agree within their own credible intervals where it matters. The same
  measured spectrum (``Q`` and the source's S11) is calibrated with both solutions
  (eq. 3.27), so its radiometer noise is common and cancels: the difference
  ``D(f) = T_new(f) - T_old(f)`` has, when nothing changed, the covariance of the two
  posteriors' calibration errors added (independent runs). Those errors are smooth and
  correlated over the band (a few polynomial terms), so a per-channel test is neither
  independent nor honest; instead ``D`` is averaged over sub-bands (``d_b``, 5 MHz by
  default), their covariance ``C = C_new + C_old`` taken from posterior draws of each
  solution, and ``chi2 = d^T C^-1 d`` compared with a chi-square of as many degrees of
  freedom as ``C`` has rank (16 sub-bands over 50-130 MHz; fewer where the two posteriors
  span less). Where a kind of drift is expected, the matched test along its shape ``m``
  is added, ``z = m^T C^-1 d / sqrt(m^T C^-1 m)``, and the two joined by Bonferroni,
  ``p = 2 min(p_chi2, p_z)``: one test per calibration, of false-alarm probability ``p``
  at its threshold. The statistic is stated as the two-sided Gaussian sigma of the same
  tail probability (``p = 1e-4`` is 3.9 sigma), the sub-bands beyond 2 sigma on their
  own give the band, and the worst of them the size (K and sigma). The benchmark and the
  drift answer different questions and sit side by side: the benchmark is a tolerance
  against a named file; the drift, a test against the solution used until now.

RFI flags of calibrated spectra are the engine's (:func:`calibration.checks.rfi.flag_sky`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from calibration.model.noise_waves import PARAMETERS
from calibration.solve.solution import CalibratedSpectrum
from calibration.solve.solvers import NoiseWaveSolution

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


@dataclass(frozen=True)
class LoadCheckVerdict:
    """The outcome of one test-load comparison."""

    passed: bool
    statistic: str
    value: float
    tolerance: float
    worst_hz: float


def compare_test_load(
    measured: ComplexArray,
    reference: ComplexArray,
    freq_hz: FloatArray,
    tolerance: float,
    statistic: str = "p95",
    smoothing: int = 21,
) -> LoadCheckVerdict:
    """Compare a measured test load with its reference at the same frequencies."""
    kernel = np.ones(max(1, smoothing)) / max(1, smoothing)
    smoothed = np.convolve(measured, kernel, mode="same")
    edge = max(1, smoothing) // 2
    inner = slice(edge, len(measured) - edge) if len(measured) > 2 * edge else slice(None)
    deviation = np.abs(smoothed[inner] - reference[inner]) / np.abs(reference[inner])
    freq_hz = np.asarray(freq_hz)[inner]
    value = {
        "max": float(np.max(deviation)),
        "p95": float(np.percentile(deviation, 95)),
        "rms": float(np.sqrt(np.mean(deviation**2))),
    }[statistic]
    worst = float(freq_hz[int(np.argmax(deviation))])
    return LoadCheckVerdict(value <= tolerance, statistic, value, tolerance, worst)


@dataclass(frozen=True)
class BenchmarkVerdict:
    """A new solution against a benchmark: relative difference of each band-averaged parameter."""

    passed: bool
    differences: dict[str, float]
    tolerance: float


def compare_with_benchmark(
    solution: NoiseWaveSolution, benchmark: NoiseWaveSolution, freq_hz: FloatArray, tolerance: float
) -> BenchmarkVerdict:
    """Band-averaged parameters of ``solution`` within ``tolerance`` of ``benchmark``'s."""
    new = solution.evaluate(freq_hz).mean(axis=1)
    old = benchmark.evaluate(freq_hz).mean(axis=1)
    differences = {
        name: float(abs(a - b) / abs(b)) for name, a, b in zip(PARAMETERS, new, old, strict=True)
    }
    return BenchmarkVerdict(max(differences.values()) <= tolerance, differences, tolerance)


#: Posterior draws of each solution for the sub-bands' covariance (in blocks, for memory).
DRIFT_DRAWS = 1000
#: A sub-band beyond this many of its own sigma is part of the band a drift reports.
BAND_SIGMA = 2.0


def sigma_of(log_p: float) -> float:
    """The two-sided Gaussian sigma of a tail probability given by its log (``1e-4``: 3.89).

    Beyond ``p = 1e-300`` from the tail's asymptotic form, ``p/2 ~ phi(z) / z``.
    """
    from scipy import stats
    if log_p > math.log(1e-300):
        return float(stats.norm.isf(math.exp(log_p) / 2.0))
    z = math.sqrt(-2.0 * log_p)
    for _ in range(3):  # z^2 = -2 ln(p/2) - ln(2 pi z^2)
        z = math.sqrt(-2.0 * (log_p - math.log(2.0)) - math.log(2.0 * math.pi * z * z))
    return z


def _chi2_log_sf(chi2: float, dof: int) -> float:
    """``ln P(X > chi2)`` for ``dof`` degrees of freedom, finite far into the tail.

    Where scipy's underflows, the leading term of the upper incomplete gamma function,
    ``Gamma(k/2, x/2) ~ (x/2)^(k/2 - 1) exp(-x/2)``.
    """
    from scipy import stats
    log_sf = float(stats.chi2.logsf(chi2, dof))
    if math.isfinite(log_sf):
        return log_sf
    half = chi2 / 2.0
    return (dof / 2.0 - 1.0) * math.log(half) - half - math.lgamma(dof / 2.0)


@dataclass(frozen=True)
class SubBand:
    """One sub-band of the drift check: its edges, ``d_b`` and its standard deviation."""

    lo_hz: float
    hi_hz: float
    difference_k: float
    std_k: float

    @property
    def sigma(self) -> float:
        """``d_b`` in its own standard deviations (signed)."""
        return self.difference_k / self.std_k if self.std_k > 0 else 0.0


@dataclass(frozen=True)
class DriftVerdict:
    """A new solution against the previous one on one source (module docstring).

    ``sigma`` is the joint statistic (``chi2`` on ``dof`` sub-bands, tail probability
    ``p_value``) as a two-sided Gaussian sigma; ``band_hz`` the span of the sub-bands
    beyond :data:`BAND_SIGMA` (the worst one when none is), ``size_k`` and
    ``size_sigma`` the worst sub-band's difference (new minus old) and its own sigma.
    """

    sigma: float
    chi2: float
    dof: int
    p_value: float
    sub_bands: tuple[SubBand, ...]
    band_hz: tuple[float, float]
    size_k: float
    size_sigma: float
    matched_sigma: float = math.nan

    def drifted(self, threshold_sigma: float) -> bool:
        """Whether the joint statistic is beyond ``threshold_sigma``."""
        return self.sigma > threshold_sigma

    def describe(self) -> str:
        """``0.412 K (5.1 sigma) over 50-70 MHz; joint 6.3 sigma over 8 sub-bands``."""
        lo, hi = self.band_hz
        return (f"{self.size_k:+.3g} K ({abs(self.size_sigma):.1f} sigma) over "
                f"{lo / 1e6:.1f}-{hi / 1e6:.1f} MHz; joint {self.sigma:.1f} sigma over "
                f"{self.dof} sub-bands")

    def as_dict(self) -> dict[str, object]:
        """The numbers, for a check record."""
        return {
            "sigma": self.sigma, "chi2": self.chi2, "dof": self.dof, "p_value": self.p_value,
            "band_lo_hz": self.band_hz[0], "band_hi_hz": self.band_hz[1],
            "size_k": self.size_k, "size_sigma": self.size_sigma,
            "matched_sigma": None if math.isnan(self.matched_sigma) else self.matched_sigma,
            "sub_band_lo_hz": [b.lo_hz for b in self.sub_bands],
            "sub_band_difference_k": [b.difference_k for b in self.sub_bands],
            "sub_band_std_k": [b.std_k for b in self.sub_bands],
        }


def sub_band_masks(freq_hz: FloatArray, width_hz: float) -> list[NDArray[np.bool_]]:
    """Contiguous sub-bands of about ``width_hz`` covering ``freq_hz`` (none empty)."""
    f = np.asarray(freq_hz, dtype=float)
    span = float(f[-1] - f[0]) if f.size > 1 else 0.0
    n = max(1, min(round(span / width_hz), f.size))
    edges = np.linspace(f[0], f[-1], n + 1)
    index = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, n - 1)
    return [index == b for b in range(n) if np.any(index == b)]


def _sub_band_draws(
    spectrum: CalibratedSpectrum, average: FloatArray, n: int, rng: np.random.Generator
) -> FloatArray:
    """``(n, B)`` sub-band means (``average``: channels x sub-bands) of posterior draws."""
    block = 250
    return np.concatenate([
        spectrum.draw_calibration(min(block, n - start), rng) @ average
        for start in range(0, n, block)
    ])


def compare_on_source(
    new: CalibratedSpectrum,
    old: CalibratedSpectrum,
    sub_band_hz: float = 5e6,
    independent_variance: FloatArray | float = 0.0,
    template: FloatArray | None = None,
    draws: int = DRIFT_DRAWS,
    seed: int = 0,
) -> DriftVerdict:
    """The drift test of module docstring on one measured spectrum calibrated twice.

    ``new`` and ``old`` are the same spectrum (same channels) calibrated with the new and
    the previous solution; ``independent_variance`` (K^2 per channel) is any further
    difference independent between channels (the receiver's S11 measured twice);
    ``template`` (K per channel), the shape an expected kind of drift gives the
    difference, adds the matched test along it.
    """
    from scipy import stats
    freq = np.asarray(new.freq_hz, dtype=float)
    if old.freq_hz.shape != freq.shape or not np.allclose(old.freq_hz, freq):
        raise ValueError("the two calibrated spectra must share their channels")
    masks = sub_band_masks(freq, sub_band_hz)
    average = np.stack([m / m.sum() for m in masks], axis=1)
    d = np.asarray(new.mean - old.mean, dtype=float) @ average
    rng = np.random.default_rng(seed)
    cov = np.atleast_2d(np.cov(_sub_band_draws(new, average, draws, rng), rowvar=False))
    cov = cov + np.atleast_2d(np.cov(_sub_band_draws(old, average, draws, rng), rowvar=False))
    extra = np.broadcast_to(np.asarray(independent_variance, dtype=float), freq.shape)
    cov = cov + np.diag([extra[m].sum() / m.sum() ** 2 for m in masks])
    values, vectors = np.linalg.eigh(cov)
    keep = values > values.max() * 1e-12 if values.max() > 0 else np.zeros(values.shape, bool)
    basis = vectors[:, keep] / np.sqrt(values[keep])
    whitened = basis.T @ d
    chi2 = float(whitened @ whitened)
    dof = int(keep.sum())
    log_p = _chi2_log_sf(chi2, dof) if dof else 0.0
    matched = math.nan
    if template is not None and dof:
        shape = basis.T @ (np.asarray(template, dtype=float) @ average)
        norm = float(np.sqrt(shape @ shape))
        if norm > 0:
            matched = float(shape @ whitened) / norm
            log_matched = math.log(2.0) + float(stats.norm.logsf(abs(matched)))
            # Two tests, one alarm: Bonferroni, p = 2 min(p_chi2, p_matched).
            log_p = min(0.0, math.log(2.0) + min(log_p, log_matched))
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    bands = tuple(
        SubBand(float(freq[m][0]), float(freq[m][-1]), float(db), float(sb))
        for m, db, sb in zip(masks, d, std, strict=True)
    )
    beyond = [b for b in bands if abs(b.sigma) >= BAND_SIGMA]
    worst = max(bands, key=lambda b: abs(b.sigma))
    span = beyond or [worst]
    return DriftVerdict(
        sigma_of(log_p), chi2, dof, math.exp(log_p), bands, (span[0].lo_hz, span[-1].hi_hz),
        worst.difference_k, worst.sigma, matched,
    )
