"""The calibrated antenna's predicted error and what more time on one calibrator does to it.

A solution calibrates the antenna as ``T_ant(f) = x_a(f)^T c`` (eq. 3.27 with the
antenna's design row ``x_a``, eqs. 3.22-3.26, 3.40); its calibration error is
``x_a^T Cov(c) x_a`` (the first part of the predictive, eq. 3.41). Over a band of interest
``F`` (all channels, or a site's weighted band), the A-optimal criterion is that error's
mean square::

    V = (1/|F|) sum_{f in F} x_a(f)^T C x_a(f) = tr(C A),   A = (1/|F|) sum_{f in F} x_a x_a^T

with ``C = Lambda^-1`` the posterior covariance of the current model (its precision
``Lambda = G / s^2 + V_0^-1``, eq. 3.36, ``G`` the radiometric solver's Gram matrix).

**More time on calibrator i.** ``G`` is a sum over sources of ``G_i = sum_f w_if x_if
x_if^T`` (less the Woodbury term of a marginalised temperature offset,
:mod:`calibration.regression.normal_equations`), with the Gauss-Newton rows ``x_if`` and
weights ``w_if = 1 / (g_if^2 var(Q_if) + e_if)``
(:mod:`calibration.solve.linearisation`): ``g = X_L T_NS``, ``e`` the reflections' error in
kelvin. The radiometer equation gives ``var(Q) ~ 1 / tau`` (eq. 3.9 with ``sigma_P = P /
sqrt(B tau)``), so ``t`` more seconds per Dicke position on source ``i``, averaged with
what it has (``tau_i``), make::

    w'_if = 1 / (g_if^2 var(Q_if) tau_i / (tau_i + t) + e_if)
    Lambda' = Lambda + (G_i(w') - G_i(w)) / s^2                (a P x P update of one source)
    V'      = tr(Lambda'^-1 A)

No model search and no new fit: the rows are those of the current posterior mean, and
``e`` (which more time does not reduce) is why a well-measured calibrator stops paying.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import LinAlgError, cho_factor, cho_solve

from ..model.data import CalibrationData
from ..model.noise_waves import INDEX, design_terms, model_q
from ..model.polynomial_model import Orders
from ..model.reflection_noise import reflection_variance
from ..regression.normal_equations import project_pairs, project_vector
from ..solve.solution import Solution

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


def band_mask(freq_hz: FloatArray, band_hz: tuple[float, float] | None) -> NDArray[np.bool_]:
    """The channels of the band of interest (all where ``band_hz`` is ``None``)."""
    freq = np.asarray(freq_hz, dtype=float)
    if band_hz is None:
        return np.ones(freq.size, dtype=bool)
    lo, hi = band_hz
    mask = (freq >= lo) & (freq <= hi)
    if not np.any(mask):
        raise ValueError(
            f"the band of interest {lo / 1e6:g}-{hi / 1e6:g} MHz holds none of the data's "
            f"channels ({freq[0] / 1e6:g}-{freq[-1] / 1e6:g} MHz)"
        )
    return mask


def _scaled_inverse(matrix: FloatArray) -> FloatArray:
    """The inverse of a symmetric positive matrix, Jacobi-scaled (diagonals span decades)."""
    d = np.sqrt(np.maximum(np.diag(matrix), 1e-300))
    inv = np.linalg.inv(matrix / np.outer(d, d)) / np.outer(d, d)
    return np.asarray(0.5 * (inv + inv.T))


def trace_inverse(precision: FloatArray, moment: FloatArray) -> float:
    """``tr(Lambda^-1 A)`` by a Jacobi-scaled Cholesky factorisation (``inf`` if singular)."""
    d = np.sqrt(np.maximum(np.diag(precision), 1e-300))
    try:
        factor = cho_factor(precision / np.outer(d, d), lower=True)
    except LinAlgError:
        return float("inf")
    return float(np.trace(cho_solve(factor, moment / np.outer(d, d))))


@dataclass
class AntennaInformation:
    """What :func:`antenna_information` gathers: ``Lambda``, ``A`` and each source's rows.

    ``gram(i, tau)`` is ``G_i`` with source ``i`` integrated ``tau`` seconds per position
    (module docstring), cached: the planner asks for the same few per decision.
    """

    names: tuple[str, ...]
    orders: Orders
    precision: FloatArray  # Lambda (P x P), the posterior's own
    moment: FloatArray  # A (P x P)
    noise_variance: float  # s^2
    seconds: FloatArray  # tau_i, per Dicke position
    features: FloatArray  # (M, N, 5) Gauss-Newton rows at the posterior mean
    radiometer_k2: FloatArray  # (M, N) g^2 var(Q) at tau_i
    reflection_k2: FloatArray  # (M, N) e
    offset_k2: FloatArray  # (M,) temperature offsets' variance
    basis: FloatArray = field(repr=False)
    _cache: dict[tuple[int, float], FloatArray] = field(default_factory=dict, repr=False)

    def variance(self, precision: FloatArray | None = None) -> float:
        """``V = tr(Lambda^-1 A)`` (K^2), at the current or a given precision."""
        return trace_inverse(self.precision if precision is None else precision, self.moment)

    def gram(self, i: int, tau: float) -> FloatArray:
        """``G_i`` at ``tau`` seconds per position (``tau = 0``: the source left out)."""
        key = (i, float(tau))
        if key not in self._cache:
            size = self.precision.shape[0]
            if tau <= 0:
                self._cache[key] = np.zeros((size, size))
            else:
                w = 1.0 / (self.radiometer_k2[i] * self.seconds[i] / tau + self.reflection_k2[i])
                f, wi = self.features[i : i + 1], w[None]
                g = project_pairs(f, wi, self.basis, self.orders)
                var = float(self.offset_k2[i])
                if var > 0:
                    u = project_vector(f, wi, self.basis, self.orders)
                    g = g - var / (1.0 + var * float(np.sum(w))) * np.outer(u, u)
                self._cache[key] = g
        return self._cache[key]

    def precision_with(self, seconds: Sequence[float] | FloatArray) -> FloatArray:
        """``Lambda`` with every source integrated ``seconds[i]`` instead of ``tau_i``."""
        out = self.precision.copy()
        for i, tau in enumerate(seconds):
            if tau != self.seconds[i]:
                out += (self.gram(i, tau) - self.gram(i, self.seconds[i])) / self.noise_variance
        return out

    def after(self, i: int, more_s: float) -> float:
        """``V'`` with ``more_s`` more seconds per position on source ``i``."""
        seconds = self.seconds.copy()
        seconds[i] += more_s
        return self.variance(self.precision_with(seconds))

    def shares(self) -> FloatArray:
        """Each source's share of the antenna's information.

        ``Lambda = sum_i G_i / s^2 + V_0^-1`` splits ``V = tr(C A)`` exactly as
        ``V = sum_i tr(C A C G_i) / s^2 + tr(C A C V_0^-1)``: source ``i``'s term over the
        sources' total is its share (the sum is 1; the prior's part is left out).
        """
        cov = _scaled_inverse(self.precision)
        weighted = cov @ self.moment @ cov
        parts = np.array([
            float(np.sum(weighted * self.gram(i, self.seconds[i]))) / self.noise_variance
            for i in range(len(self.names))
        ])
        return np.asarray(parts / np.sum(parts))


def antenna_information(
    solution: Solution,
    data: CalibrationData,
    antenna_s11: ComplexArray,
    antenna_temperature_k: float | FloatArray = 298.0,
    band_hz: tuple[float, float] | None = None,
) -> AntennaInformation:
    """:class:`AntennaInformation` of ``solution`` (solved from ``data``) for the antenna.

    ``antenna_s11`` is the antenna's reflection over ``data``'s channels; its ``Q`` is the
    one the model gives a source of ``antenna_temperature_k`` (:func:`model_q`): the
    design row depends on it through ``X_NS = Q X_L``, the calibration error barely.
    """
    freq = data.freq_hz
    gamma_ant = np.asarray(antenna_s11, dtype=complex)
    if gamma_ant.shape != freq.shape:
        raise ValueError(
            f"the antenna's reflection has {gamma_ant.size} channels, the data {freq.size}"
        )
    orders = solution.orders
    theta = solution.evaluate(freq)
    basis = solution.basis.matrix(freq, max(orders))
    ant_terms = design_terms(gamma_ant, data.gamma_rec)
    t_ant = np.broadcast_to(np.asarray(antenna_temperature_k, dtype=float), freq.shape)
    rows = solution.design_rows(freq, data.gamma_rec, gamma_ant, model_q(theta, ant_terms, t_ant))
    inside = rows[band_mask(freq, band_hz)]
    moment = inside.T @ inside / inside.shape[0]

    terms = data.terms()
    temps, _, var_q = data.stacked()
    q0 = model_q(theta, terms, temps)  # noiseless: the information at the estimate
    gain = terms.x_l * theta[INDEX["NS"]]
    gammas = np.stack([s.gamma for s in data.sources.values()])
    extra = reflection_variance(
        theta[:, None, :], gammas, data.gamma_rec, q0, data.reflection_errors(),
        data.gamma_rec_std,
    )
    return AntennaInformation(
        names=tuple(data.names),
        orders=orders,
        precision=_scaled_inverse(solution.posterior.covariance),
        moment=moment,
        noise_variance=float(solution.posterior.noise_variance),
        seconds=np.array([s.integration.source_s for s in data.sources.values()], dtype=float),
        features=terms.matrix(q0),
        radiometer_k2=np.asarray(gain**2 * var_q),
        reflection_k2=np.broadcast_to(np.asarray(extra, dtype=float), var_q.shape).copy(),
        offset_k2=data.temperature_variances(),
        basis=basis,
    )
