"""Data preparation before a solve: band masks, smoothing of reflections, averaging cycles.

Flags are boolean arrays of the data's shape, ``True`` = excluded, kept beside the data
(never data removed): :func:`band_flags` for the calibration band, :func:`excision_flags`
for known bands of interference (thesis fig. 4.20 excised four: the band's start, 79 MHz,
108 MHz and its far end), :mod:`calibration.checks.rfi` for what is found in the data.

**Smoothing** (thesis 4.7.1: "a smoothing spline factor of 0.99999999, with a factor of 1
being no smoothing", MATLAB's ``csaps``): the cubic smoothing spline ``s`` minimising::

    p sum_i w_i |y_i - s(x_i)|^2 + (1 - p) integral |s''(x)|^2 dx                    (S1)

i.e. scipy's ``make_smoothing_spline`` with ``lam = (1 - p) / p``, on the real and
imaginary parts of a reflection (or any per-channel quantity, such as the thesis's ``X``
elements). ``p`` depends on the unit of ``x``, which the thesis does not state; here ``x``
is frequency in ``x_unit_hz`` (MHz by default). The spline acts like a kernel smoother of
width ``h = (lam / rho)^(1/4)`` (``rho`` channels per unit of ``x``; Silverman 1984):
:func:`smoothing_width_hz` says how much a factor smooths (0.99999999 on 20 kHz channels
in MHz: 3.7 kHz, under a channel, next to nothing).

**Averaging** repeated Dicke cycles or runs (:func:`weighted_average`), per channel over
the cycle axis, flagged entries left out:

* with each cycle's variance ``v_i``: inverse-variance weights, ``mean = sum(x_i / v_i) /
  sum(1 / v_i)``, ``var = 1 / sum(1 / v_i)`` (the minimum-variance unbiased combination);
* with integration times ``tau_i`` only: weights ``tau_i`` (radiometer noise
  ``v_i = c / tau_i``), ``var = c / sum(tau_i)`` with ``c`` estimated from the scatter,
  ``c = sum(tau_i (x_i - mean)^2) / (n - 1)`` (unbiased; needs two cycles or more);
* with neither: equal weights and the scatter's variance of the mean.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import make_smoothing_spline

from ..core.errors import InvalidDataError

__all__ = [
    "Average",
    "band_flags",
    "excision_flags",
    "smooth_reflection",
    "smoothing_width_hz",
    "weighted_average",
]

BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]


def band_flags(freq_hz: ArrayLike, band_hz: tuple[float, float]) -> BoolArray:
    """``True`` outside the closed band ``[low, high]`` (thesis 4.7.1: 50-130 MHz)."""
    f = np.asarray(freq_hz, dtype=float)
    low, high = band_hz
    if not low < high:
        raise InvalidDataError(f"band {band_hz} must be (low, high) with low < high")
    return np.asarray((f < low) | (f > high), dtype=bool)


def excision_flags(freq_hz: ArrayLike, bands_hz: Sequence[tuple[float, float]]) -> BoolArray:
    """``True`` inside any of the closed bands (known interference)."""
    f = np.asarray(freq_hz, dtype=float)
    flags = np.zeros(f.shape, dtype=bool)
    for low, high in bands_hz:
        if not low <= high:
            raise InvalidDataError(f"excised band ({low}, {high}) must have low <= high")
        flags |= (f >= low) & (f <= high)
    return flags


def smoothing_width_hz(freq_hz: ArrayLike, factor: float, x_unit_hz: float = 1e6) -> float:
    """The kernel width ``(lam / rho)^(1/4)`` of (S1)'s spline with ``p = factor``, in Hz."""
    f = np.asarray(freq_hz, dtype=float)
    rho = (f.size - 1) / ((f[-1] - f[0]) / x_unit_hz)
    return float((_lam(factor) / rho) ** 0.25 * x_unit_hz)


def _lam(factor: float) -> float:
    if not 0 < factor <= 1:
        raise InvalidDataError(f"smoothing factor p must be in (0, 1], got {factor}")
    return (1 - factor) / factor


def smooth_reflection(
    freq_hz: ArrayLike,
    values: ArrayLike,
    factor: float,
    flags: ArrayLike | None = None,
    x_unit_hz: float = 1e6,
) -> NDArray[np.complexfloating] | FloatArray:
    """The smoothing spline (S1) of ``values`` (complex or real, one per channel).

    Flagged channels do not enter the fit; the spline is evaluated at every channel (the
    flags stay with the data). ``factor = 1`` returns the interpolating spline, i.e. the
    unflagged data unchanged.
    """
    f = np.asarray(freq_hz, dtype=float)
    y = np.asarray(values)
    if f.ndim != 1 or y.shape != f.shape or np.any(np.diff(f) <= 0):
        raise InvalidDataError("smoothing needs increasing frequencies and one value each")
    keep = np.ones(f.shape, bool) if flags is None else ~np.asarray(flags, dtype=bool)
    if np.count_nonzero(keep) < 5:
        raise InvalidDataError("smoothing needs at least 5 unflagged channels")
    x = f / x_unit_hz
    lam = _lam(factor)

    def fit(part: FloatArray) -> FloatArray:
        spline = make_smoothing_spline(x[keep], part[keep], lam=lam)
        return np.asarray(spline(x), dtype=float)

    if np.iscomplexobj(y):
        return np.asarray(fit(y.real) + 1j * fit(y.imag), dtype=complex)
    return fit(np.asarray(y, dtype=float))


@dataclass(frozen=True)
class Average:
    """A weighted average over cycles, per channel (:func:`weighted_average`).

    ``flags`` marks channels with no unflagged cycle (mean and variance NaN there);
    ``n_used`` counts the cycles that entered each channel.
    """

    mean: FloatArray
    variance: FloatArray
    n_used: NDArray[np.int_]
    flags: BoolArray


def weighted_average(
    values: ArrayLike,
    variance: ArrayLike | None = None,
    integration_s: ArrayLike | None = None,
    flags: ArrayLike | None = None,
) -> Average:
    """Average cycles ``values`` of shape ``(cycle, ...)`` over the first axis.

    ``variance`` broadcasts against ``values`` (each cycle's variance per channel);
    ``integration_s`` has one time per cycle. Give one of them, or neither (equal weights).
    """
    x = np.asarray(values, dtype=float)
    if x.ndim < 1 or x.shape[0] == 0:
        raise InvalidDataError("weighted_average needs at least one cycle on axis 0")
    if variance is not None and integration_s is not None:
        raise InvalidDataError("give the cycles' variances or their integration times, not both")
    used = np.ones(x.shape, bool) if flags is None else ~np.asarray(flags, bool)
    used = np.broadcast_to(used, x.shape) & np.isfinite(x)
    n = np.sum(used, axis=0)
    if variance is not None:
        v = np.broadcast_to(np.asarray(variance, dtype=float), x.shape)
        if np.any(~(v[used] > 0)):
            raise InvalidDataError("cycle variances must be > 0")
        weight = np.where(used, 1 / np.where(used, v, 1.0), 0.0)
    else:
        tau = np.ones(x.shape[0]) if integration_s is None else np.asarray(integration_s, float)
        if tau.shape != (x.shape[0],) or np.any(~(tau > 0)):
            raise InvalidDataError("integration_s needs one time > 0 per cycle")
        weight = np.where(used, tau.reshape((-1,) + (1,) * (x.ndim - 1)), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        total = np.sum(weight, axis=0)
        mean = np.sum(weight * np.where(used, x, 0.0), axis=0) / total
        if variance is not None:
            var = 1 / total
        else:  # c = sum(tau (x - mean)^2) / (n - 1);  var = c / sum(tau)
            scatter = np.sum(weight * np.where(used, x - mean, 0.0) ** 2, axis=0)
            var = np.where(n > 1, scatter / (n - 1), np.nan) / total
    empty = n == 0
    return Average(
        mean=np.asarray(np.where(empty, np.nan, mean), dtype=float),
        variance=np.asarray(np.where(empty, np.nan, var), dtype=float),
        n_used=np.asarray(n),
        flags=np.asarray(empty, dtype=bool),
    )
