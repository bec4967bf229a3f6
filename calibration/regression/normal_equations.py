"""Weighted normal equations of the polynomial calibration model, built once per solve.

Both polynomial solvers fit a linear model ``y_if = sum_k F_ifk theta_k(f) + e_if`` over
sources ``i`` and channels ``f``, with per-row weights ``w_if = 1 / var(e_if)`` and
``theta_k(f) = sum_j c_kj B_j(f)``. Everything model selection needs is a handful of
moments over the largest model (``max_orders``)::

    G   = sum_if w_if x_if x_if^T           (Gram matrix, P x P)
    g   = sum_if w_if x_if r_if             (r = y - X c_ref: residual of a reference fit)
    chi = sum_if w_if r_if^2

with ``x_if`` the design row (features times basis functions). They cost
``O(n_sources n_channels n_max^2)`` to build and nothing thereafter: any sub-model is a
sub-block of ``G``.

**Uncertain calibrator temperatures.** A thermometer's error is one offset ``d_i`` for all
channels of source ``i``. With ``d_i ~ N(0, sigma_i^2)`` marginalised, the rows of source
``i`` have covariance ``D_i + sigma_i^2 1 1^T`` instead of ``D_i = diag(1/w_i)``, and by
the Woodbury identity every moment takes a rank-one correction per source::

    k_i = sigma_i^2 / (1 + sigma_i^2 a_i),   a_i = sum_f w_if
    u_i = sum_f w_if x_if,                   v_i = sum_f w_if r_if
    G -= k_i u_i u_i^T,   g -= k_i u_i v_i,   chi -= k_i v_i^2,
    sum log w -= log(1 + sigma_i^2 a_i)      (the log-determinant)

so the moment form, and everything built on it, carries over exactly. (The evidence's
noise scale ``s^2`` then scales the offsets' variance too; with ``s^2`` near 1, as the
radiometer equation makes it, that is immaterial.)

Expressing the fit relative to ``c_ref`` keeps every quadratic form at
the size of the noise, so the evidence does not lose digits to ``y^T W y``, which is
``~1e10`` for kelvin-scale data with millikelvin noise (the cancellation the thesis
warns of in its footnote to eq. 3.36). No ``n_channels x n_channels`` matrix is formed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..model.noise_waves import N_PARAMETERS
from ..model.polynomial_model import Orders, as_orders, coefficient_slices, full_indices

FloatArray = NDArray[np.float64]


def project_pairs(
    features: FloatArray, weights: FloatArray, basis: FloatArray, max_orders: Orders
) -> FloatArray:
    """``G = sum_if w x x^T`` assembled block by block from per-channel feature moments.

    With ``x = f_k(i, f) B_j(f)``, block ``(a, b)`` is ``B^T diag(c_ab) B`` with the moments
    ``c_ab(f) = sum_i w_if f_a f_b``, computed from contiguous copies of the features
    (the strided ones cost more than the copy) and one weighted column at a time.
    """
    slices = coefficient_slices(max_orders)
    gram = np.zeros((sum(max_orders), sum(max_orders)))
    n = max(max_orders)
    pairs = [
        (a, b)
        for a in range(N_PARAMETERS)
        for b in range(a, N_PARAMETERS)
        if max_orders[a] and max_orders[b]
    ]
    if not pairs:
        return gram
    columns = [np.ascontiguousarray(features[..., k]) for k in range(N_PARAMETERS)]
    moments = np.empty((len(pairs), basis.shape[0]))
    weighted, current = columns[0], -1
    for row, (a, b) in enumerate(pairs):
        if a != current:  # pairs come grouped by a: one weighted column at a time
            weighted, current = weights * columns[a], a
        moments[row] = np.einsum("mn,mn->n", weighted, columns[b])
    rows = np.ascontiguousarray(basis[:, :n].T)  # (n, N)
    blocks = [(rows * m) @ rows.T for m in moments]
    for (a, b), block in zip(pairs, blocks, strict=True):
        block = block[: max_orders[a], : max_orders[b]]
        gram[slices[a], slices[b]] = block
        gram[slices[b], slices[a]] = block.T
    return gram


def sandwich_gram(
    features: FloatArray,
    weights: FloatArray,
    variance: FloatArray,
    basis: FloatArray,
    max_orders: Sequence[int],
    offset_variance: FloatArray | None = None,
) -> FloatArray:
    """``X^T C^-1 D C^-1 X`` for row variances ``D = diag(variance)``, in the layout.

    ``C^-1`` is the fit's: ``diag(weights)``, less, for each source ``m`` whose
    temperature offset is marginalised (``offset_variance``, as in
    :func:`build_normal_equations`), the Woodbury term ``k_m W_m 1 1^T W_m`` with
    ``k_m = var_m / (1 + var_m sum W_m)``. Per source, with ``u = X_m^T W_m 1``,
    ``s = X_m^T W_m^2 D_m 1`` and ``a = 1^T W_m^2 D_m 1``::

        X_m^T W_m^2 D_m X_m - k (s u^T + u s^T) + k^2 a u u^T
    """
    orders = as_orders(max_orders)
    wwd = weights**2 * variance
    out = project_pairs(features, wwd, basis, orders)
    if offset_variance is None:
        return out
    for m, var in enumerate(np.asarray(offset_variance, dtype=float)):
        if var <= 0:
            continue
        k = var / (1.0 + var * float(np.sum(weights[m])))
        u = project_vector(features[m : m + 1], weights[m : m + 1], basis, orders)
        s = project_vector(features[m : m + 1], wwd[m : m + 1], basis, orders)
        a = float(np.sum(wwd[m]))
        out = out - k * (np.outer(s, u) + np.outer(u, s)) + k * k * a * np.outer(u, u)
    return out


def project_vector(
    features: FloatArray, weighted_residual: FloatArray, basis: FloatArray, max_orders: Orders
) -> FloatArray:
    """``sum_if x_if * (w r)_if`` for every coefficient."""
    per_channel = np.einsum("mnk,mn->kn", features, weighted_residual)  # (5, N)
    return np.concatenate([basis[:, :n].T @ per_channel[k] for k, n in enumerate(max_orders)])


def evaluate_coefficients(
    coefficients: FloatArray, basis: FloatArray, orders: Sequence[int]
) -> FloatArray:
    """Parameter curves ``(5, N)`` from a concatenated coefficient vector."""
    return np.stack(
        [basis[:, : s.stop - s.start] @ coefficients[s] for s in coefficient_slices(orders)]
    )


class SubModels(Protocol):
    """Which sub-models of the largest the data identify (all, where there is none).

    :class:`calibration.regression.errors_in_variables.Identified`: where the reflections' errors
    decide some models, the box ``box`` holds only identified ones and ``admits`` says
    whether a model beyond it is identified too.
    """

    @property
    def box(self) -> Orders:
        """The largest orders within which every model is identified."""

    def admits(self, orders: Orders) -> bool:
        """Whether the model ``orders`` is identified."""


@dataclass(frozen=True)
class NormalEquations:
    """Moments of a weighted linear model about a reference fit (see module docstring).

    Attributes
    ----------
    max_orders
        Term counts of the largest model; every candidate model is a sub-block.
    gram, cross, chi2_ref
        ``G``, ``g`` and ``chi`` above.
    reference
        The reference coefficients ``c_ref`` (layout of ``max_orders``).
    n_rows
        Number of data rows ``N`` (sources x channels).
    sum_log_weights
        ``sum log w``: the whitening Jacobian in the evidence.
    identified
        The sub-models the data identify, where not all are (:class:`SubModels`).
    """

    max_orders: Orders
    gram: FloatArray
    cross: FloatArray
    chi2_ref: float
    reference: FloatArray
    n_rows: int
    sum_log_weights: float
    identified: SubModels | None = None

    def admits(self, orders: Sequence[int]) -> bool:
        """Whether the data identify the sub-model ``orders`` (:attr:`identified`)."""
        return self.identified is None or self.identified.admits(as_orders(orders))

    def within(self, orders: Sequence[int]) -> NormalEquations:
        """The same equations with a smaller largest model ``orders``.

        Re-referenced at ``c_ref`` with the terms beyond ``orders`` removed (``e``)::

            chi' = chi + 2 e^T g + e^T G e,   g' = (g + G e)[orders],   G' = G[orders]

        so that every sub-model's quadratic form is unchanged. ``identified`` is dropped
        where ``orders`` lies within its box (every model is then identified) and kept
        otherwise: it holds its own moments in its own layout, so it answers for any model.
        """
        idx = self.indices(orders)
        beyond = self.reference.copy()
        beyond[idx] = 0.0
        moved = self.gram @ beyond
        inside = self.identified is not None and all(
            n <= m for n, m in zip(as_orders(orders), self.identified.box, strict=True)
        )
        return replace(
            self,
            max_orders=as_orders(orders),
            gram=self.gram[np.ix_(idx, idx)],
            cross=(self.cross + moved)[idx],
            chi2_ref=float(self.chi2_ref + 2.0 * beyond @ self.cross + beyond @ moved),
            reference=self.reference[idx],
            identified=None if inside else self.identified,
        )

    def indices(self, orders: Sequence[int]) -> NDArray[np.intp]:
        """Positions of a sub-model's coefficients in the ``max_orders`` layout."""
        orders = as_orders(orders)
        if any(n > m for n, m in zip(orders, self.max_orders, strict=True)):
            raise ValueError(f"orders {orders} exceed the built maximum {self.max_orders}")
        return full_indices(orders, self.max_orders)

    def rhs(self, idx: NDArray[np.intp]) -> FloatArray:
        """``X^T W y`` restricted to ``idx`` (``y = X c_ref + r``)."""
        return np.asarray(self.gram[idx] @ self.reference + self.cross[idx])

    def chi2(self, coefficients: FloatArray, idx: NDArray[np.intp]) -> float:
        """``(y - X c)^T W (y - X c)`` for a sub-model's coefficients, without cancellation."""
        d = self.reference.copy()
        d[idx] -= coefficients
        return float(self.chi2_ref + 2.0 * d @ self.cross + d @ self.gram @ d)


def build_normal_equations(
    features: FloatArray,
    weights: FloatArray,
    response: FloatArray,
    basis: FloatArray,
    max_orders: Sequence[int],
    reference: FloatArray | None = None,
    ridge: FloatArray | None = None,
    offset_variance: FloatArray | None = None,
) -> NormalEquations:
    """Build :class:`NormalEquations` for ``features (M, N, 5)``, ``weights``/``response (M, N)``.

    ``basis`` is ``(N, max(max_orders))``. Without ``reference`` the reference fit is the
    largest model's weighted least squares, regularised by ``ridge`` (prior precisions,
    one per coefficient) so that it exists even when the data leave directions free.
    ``offset_variance`` (one per source ``M``, K^2) marginalises a per-source offset of the
    response: the calibrators' temperature uncertainty (module docstring).
    """
    max_orders = as_orders(max_orders)
    gram = project_pairs(features, weights, basis, max_orders)
    if reference is None:
        rhs = project_vector(features, weights * response, basis, max_orders)
        ridge_diag = np.zeros(len(rhs)) if ridge is None else np.asarray(ridge, dtype=float)
        scale = np.sqrt(np.maximum(np.diag(gram), 1e-300))
        a = gram / np.outer(scale, scale) + np.diag(ridge_diag / scale**2 + 1e-12)
        reference = np.linalg.solve(a, rhs / scale) / scale
    residual = response - np.einsum(
        "mnk,kn->mn", features, evaluate_coefficients(reference, basis, max_orders)
    )
    wr = weights * residual
    cross = project_vector(features, wr, basis, max_orders)
    chi2_ref = float(np.sum(wr * residual))
    sum_log_weights = float(np.sum(np.log(weights)))
    if offset_variance is not None:
        for m, var in enumerate(np.asarray(offset_variance, dtype=float)):
            if var <= 0:
                continue
            a = float(np.sum(weights[m]))
            u = project_vector(features[m : m + 1], weights[m : m + 1], basis, max_orders)
            v = float(np.sum(wr[m]))
            k = var / (1.0 + var * a)
            gram = gram - k * np.outer(u, u)
            cross = cross - k * u * v
            chi2_ref -= k * v * v
            sum_log_weights -= float(np.log1p(var * a))
    return NormalEquations(
        max_orders=max_orders,
        gram=gram,
        cross=cross,
        chi2_ref=chi2_ref,
        reference=np.asarray(reference, dtype=float),
        n_rows=int(weights.size),
        sum_log_weights=sum_log_weights,
    )
