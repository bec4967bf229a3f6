"""The VNA's random error on a source's reflection, carried into its temperature.

A source's reflection enters the calibration equation (eq. 3.27) through the design
terms (eqs. 3.22-3.25): ``T = x(Gamma, Q) . theta``. A measured ``Gamma = Gamma_true + e``,
``e`` a circular complex error of rms ``sigma`` (real and imaginary parts each of variance
``sigma^2 / 2``, independent between channels: the trace noise of a sweep), moves ``T``
by ``J_re Re(e) + J_im Im(e)`` to first order, so::

    var_T = (J_re^2 + J_im^2) sigma^2 / 2,      J = dT / d(Re, Im) Gamma

``J`` by central differences: the design terms hold ``|Gamma|^2`` and are not holomorphic.
For a calibrator, this variance sits in the residual of each of its rows (the radiometric
solver adds it to the row's radiometer variance, about its operating point); for a
calibrated source, in its predictive (:meth:`calibration.solve.solution.Solution.calibrate`).

The receiver's own reflection ``Gamma_rec`` is measured by the same VNA, and its error
moves ``T`` the same way with ``J = dT / d(Re, Im) Gamma_rec``
(:func:`receiver_temperature_variance`). That error is common to every source at a
channel: for a calibrated source it is a variance of its own, per channel, which no fit of
smooth parameters can absorb, and the predictive carries it; in the calibrators' rows it
sits in each row's variance (its sharing between the rows, and its partial cancellation
in a calibrated source, are discussed in :mod:`calibration.solve.correlated_reflections`, which
widens the posterior for the sources' own errors shared between neighbouring channels).
Two errors on different sweeps are independent and their variances add. A row's variance
depends on the coefficients it is evaluated at, which a fit can exploit where the
calibrators leave a direction nearly free: :mod:`calibration.regression.errors_in_variables` removes
that bias and cuts the orders to what the calibrators identify above these errors.

The VNA's systematic errors (thesis table 2.3), correlated across channels and sweeps,
are :mod:`calibration.checks.vna_systematics`'.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .noise_waves import design_terms, source_temperature

FloatArray = NDArray[np.float64]

#: Step of the central differences: far above rounding (|Gamma| <= 1), far below any
#: structure of the design terms in Gamma.
STEP = 1e-6


def temperature_variance(
    theta: FloatArray,
    gamma: ArrayLike,
    gamma_rec: ArrayLike,
    q: ArrayLike,
    gamma_std: ArrayLike,
) -> FloatArray:
    """``var_T`` (K^2) of the module docstring, per channel (shape of ``gamma``).

    ``theta`` is ``(5, n_channels)`` (or broadcasting), ``gamma_std`` the complex rms
    error of ``gamma``.
    """
    g = np.asarray(gamma, dtype=complex)

    def temperature(step: complex) -> FloatArray:
        return np.asarray(source_temperature(theta, design_terms(g + step, gamma_rec), q))

    return _variance(temperature, gamma_std)


def receiver_temperature_variance(
    theta: FloatArray,
    gamma: ArrayLike,
    gamma_rec: ArrayLike,
    q: ArrayLike,
    gamma_rec_std: ArrayLike,
) -> FloatArray:
    """``var_T`` (K^2) from the receiver reflection's error ``gamma_rec_std`` (module docstring)."""
    j_re, j_im = _receiver_slopes(theta, gamma, gamma_rec, q)
    sigma = np.asarray(gamma_rec_std, dtype=float)
    return np.asarray((j_re**2 + j_im**2) * sigma**2 / 2.0, dtype=float)


def reflection_variance(
    theta: FloatArray,
    gamma: ArrayLike,
    gamma_rec: ArrayLike,
    q: ArrayLike,
    gamma_std: ArrayLike | None,
    gamma_rec_std: ArrayLike | None,
) -> FloatArray | float:
    """Both errors' ``var_T`` (K^2) added (independent sweeps); 0 where neither is known."""
    out: FloatArray | float = 0.0
    if gamma_std is not None:
        out = out + temperature_variance(theta, gamma, gamma_rec, q, gamma_std)
    if gamma_rec_std is not None:
        out = out + receiver_temperature_variance(theta, gamma, gamma_rec, q, gamma_rec_std)
    return out


def _receiver_slopes(
    theta: FloatArray, gamma: ArrayLike, gamma_rec: ArrayLike, q: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """``J = dT / d(Re, Im) Gamma_rec`` (K per unit reflection), each of ``gamma``'s shape."""
    g_rec = np.asarray(gamma_rec, dtype=complex)

    def temperature(step: complex) -> FloatArray:
        return np.asarray(source_temperature(theta, design_terms(gamma, g_rec + step), q))

    return _slopes(temperature)


def _slopes(temperature: Callable[[complex], FloatArray]) -> tuple[FloatArray, FloatArray]:
    """``(J_re, J_im)`` by central differences of ``temperature``."""

    def slope(step: complex) -> FloatArray:
        return (temperature(step) - temperature(-step)) / (2 * STEP)

    return slope(STEP), slope(1j * STEP)


def _variance(temperature: Callable[[complex], FloatArray], std: ArrayLike) -> FloatArray:
    """``(J_re^2 + J_im^2) sigma^2 / 2`` with ``J`` by central differences of ``temperature``."""
    j_re, j_im = _slopes(temperature)
    sigma = np.asarray(std, dtype=float)
    return np.asarray((j_re**2 + j_im**2) * sigma**2 / 2.0, dtype=float)


#: ``E|Delta^k e|^2 / E|e|^2`` for white noise: the sum of the squared binomial
#: coefficients of the k-th difference, C(2k, k).
_DIFFERENCE_GAIN = {4: 70.0, 6: 924.0}
#: The 4th- and 6th-difference estimates must agree to this fraction, else the sweep's own
#: structure (a long cable's ripple on a coarse grid), not its noise, sets them.
TRACE_NOISE_AGREEMENT = 0.25


def trace_noise(gamma: ArrayLike) -> float | None:
    """The complex rms white noise of one sweep, from its own scatter; ``None`` if unsure.

    A smooth reflection has vanishing high differences point to point, white noise does
    not: ``E|Delta^4 e|^2 = 70 sigma^2`` and ``E|Delta^6 e|^2 = 924 sigma^2``. Each is
    estimated by the median of ``|Delta^k gamma|^2`` (exponential for circular Gaussian
    noise, median = ln 2 x mean), robust to a few outliers. Where the two estimates
    disagree by more than :data:`TRACE_NOISE_AGREEMENT`, the structure of the reflection
    leaks into the differences (a grid too coarse for it), and nothing is claimed. At REACH's
    sweep (1401 points over 40-180 MHz) the 10 m cable's ~10 MHz ripple contributes
    ~1e-5 of its amplitude to the 4th difference, far below the trace noise.
    """
    g = np.asarray(gamma, dtype=complex)
    if g.ndim != 1 or g.size < 64:
        return None
    estimates = {
        k: float(np.median(np.abs(np.diff(g, k)) ** 2) / (gain * np.log(2.0)))
        for k, gain in _DIFFERENCE_GAIN.items()
    }
    low, high = estimates[4], estimates[6]
    if not (low > 0 and abs(high / low - 1.0) <= TRACE_NOISE_AGREEMENT):
        return None
    return float(np.sqrt(low))
