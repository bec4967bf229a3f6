"""The VNA's random error in the calibrators' design rows: its bias, and where it decides.

The radiometric solver's rows (:func:`calibration.solve.radiometric_solver.linearise`) are built
from *measured* reflections: the features ``x`` and the response ``y`` of a row are
functions of ``Gamma = Gamma_true + e`` (each source's own, and the receiver's), so the
row residual ``R(c) = y - x . c`` carries the reflection error as ``(y' - x' c) . e``
with ``'`` the derivative in ``(Re, Im) Gamma``. Its variance

    v(c) = sum over the error components of sigma^2 / 2 (y' - x' c)^2

depends on the coefficients ``c``. The rows' weights hold ``v`` at the operating point
(:func:`calibration.model.reflection_noise.reflection_variance`), but least squares, and the
evidence with it, sees ``E sum w R(c)^2 = sum w [R_true(c)^2 + v(c)]``: it gains by moving
``c`` to where ``v(c)`` is small, the attenuation bias of regression on regressors measured
with error (Fuller 1987, *Measurement Error Models*, Wiley, ch. 2). Where the calibrators
pin every direction of a model, the gain is ``v``'s share of the information, a few
parts in 1e4 for REACH's twelve. Where a model has a direction the calibrators hardly see
(four calibrators leave one combination of the five parameters free in every channel,
held only by the polynomials' smoothness), moving along it costs nothing in ``R_true``
and removes ``v``: a simulated run of four calibrators with VNA trace noise of 1e-3 chose
orders (7, 6, 8, 5, 5) against the truth's (1, 4, 3, 4, 5), its quadratic form 250 below
the true model's, and calibrated an antenna 300 times the noise floor off, 15 times its
error bars.

Two remedies, both in the moment form of :mod:`calibration.regression.normal_equations`:

1. **The moment correction** (Fuller's, for a known error variance): ``v(c) - v(c_0)``
   is subtracted from the quadratic form, ``c_0`` the operating point, so that every
   model is scored on ``R_true`` with the noise level the weights assume. With
   ``v(c) = c^T C c - 2 c^T d + const``::

       G' = G - C,  g' = g + C c_ref - d,  chi' = chi - v(c_ref) + v(c_0)

   ``C = sum w x'x'^T sigma^2 / 2`` and ``d = sum w x'y' sigma^2 / 2`` projected on the
   basis, as the Gram matrix is.
   The corrected fit's covariance is the sandwich ``A^-1 G A^-1`` (``A = G' + P``, ``G``
   the rows' true information, the weights being the rows' variances at ``c_0``), its
   posterior's ``A^-1`` widened by ``A^-1 C A^-1``
   (:func:`calibration.solve.correlated_reflections.widen`, beside the shared errors' term).
2. **Identification**: the correction is sound where the data's information ``G``
   exceeds the errors' ``C`` in every direction, unstable as they meet (its variance
   grows as ``1 / (1 - mu)``, ``mu`` the largest generalised eigenvalue of ``(C, G)``), and
   meaningless beyond. A model whose ``mu`` exceeds :data:`MU_MAX` is one the
   calibrators do not identify above their reflections' errors, and the order box is cut
   until every model in it is (:func:`identified_orders`; a sub-model's ``mu`` is never
   larger, by interlacing). In the run above: ``mu`` 3e-4 at the true orders, 0.02 at
   (4, 4, 4, 4, 4), 0.56 at (5, 5, 5, 5, 5), 1.01 at (6, 6, 6, 6, 6). The cut box is where
   the operating point and the prior's widths are fitted; the models beyond it whose own
   ``mu`` is within the limit are searched too (:class:`Identified`): the identified
   models are a down-set, and a truth with many terms in one parameter and few in the
   others lies outside any box cut evenly.

The derivatives are central differences of the solver's own rows (the design terms hold
``|Gamma|^2`` and are not holomorphic), as :mod:`calibration.model.reflection_noise` takes them.
The receiver's error is common to every row of a channel; ``v`` is a sum of per-row
second moments, so that sharing does not enter it. The calibrators' marginalised
temperature offsets (``offset_variance``) change ``G`` by a rank-one term per source; ``C``
is taken without it (second order in two small errors).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from ..model.polynomial_model import Orders, as_orders, full_indices
from .normal_equations import NormalEquations, evaluate_coefficients, project_pairs, project_vector

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: The largest share of apparent information the reflection errors may hold in any
#: direction of a model (``mu``, module docstring): beyond it, the moment correction at
#: least doubles that direction's variance, and its first-order expansion is in doubt.
MU_MAX = 0.5
#: Central-difference step in ``Gamma`` (as :data:`calibration.model.reflection_noise.STEP`).
STEP = 1e-6

#: The solver's rows ``(features (M, N, 5), response (M, N))`` at given reflections
#: (sources ``(M, N)``, receiver ``(N,)``), about a fixed operating point and weights.
Rows = Callable[[ComplexArray, ComplexArray], tuple[FloatArray, FloatArray]]


@dataclass(frozen=True)
class RowErrors:
    """Each independent reflection error's effect on the rows, one sd's worth.

    ``features`` ``(K, M, N, 5)`` and ``response`` ``(K, M, N)``: for error component
    ``k`` (real and imaginary parts of the sources' and of the receiver's reflection),
    ``x' sigma / sqrt 2`` and ``y' sigma / sqrt 2``.
    """

    features: FloatArray
    response: FloatArray

    def variance(self, weights: FloatArray, theta: FloatArray) -> float:
        """``sum w v`` at the parameter curves ``theta`` ``(5, N)``: the rows' error share."""
        slope = self.response - np.einsum("kmnp,pn->kmn", self.features, theta)
        return float(np.sum(weights[None] * slope**2))


def row_errors(
    rows: Rows,
    gamma: ComplexArray,
    gamma_rec: ComplexArray,
    gamma_std: FloatArray | None,
    gamma_rec_std: FloatArray | float | None,
) -> RowErrors | None:
    """:class:`RowErrors` by central differences of ``rows``; ``None`` if no error is known."""
    parts: list[tuple[FloatArray, FloatArray]] = []
    for sigma, shift in (
        (gamma_std, lambda step: (gamma + step, gamma_rec)),
        (gamma_rec_std, lambda step: (gamma, gamma_rec + step)),
    ):
        if sigma is None:
            continue
        scale = np.broadcast_to(np.asarray(sigma, dtype=float), gamma.shape) / np.sqrt(2.0)
        for unit in (1.0, 1.0j):
            x_up, y_up = rows(*shift(STEP * unit))
            x_down, y_down = rows(*shift(-STEP * unit))
            parts.append((
                (x_up - x_down) / (2 * STEP) * scale[..., None],
                (y_up - y_down) / (2 * STEP) * scale,
            ))
    if not parts:
        return None
    return RowErrors(np.stack([p[0] for p in parts]), np.stack([p[1] for p in parts]))


@dataclass(frozen=True)
class ErrorMoments:
    """``C`` and ``d`` of the module docstring in the layout of ``max_orders``."""

    gram: FloatArray
    cross: FloatArray


def error_moments(
    errors: RowErrors, weights: FloatArray, basis: FloatArray, max_orders: Orders
) -> ErrorMoments:
    """Project the row errors' second moments on the basis, as the normal equations are."""
    k = errors.features.shape[0]
    features = errors.features.reshape(-1, *errors.features.shape[2:])
    stacked = np.tile(weights, (k, 1))
    return ErrorMoments(
        project_pairs(features, stacked, basis, max_orders),
        project_vector(features, stacked * errors.response.reshape(stacked.shape), basis,
                       max_orders),
    )


def corrected(
    normal: NormalEquations,
    moments: ErrorMoments,
    errors: RowErrors,
    weights: FloatArray,
    basis: FloatArray,
    operating_point: FloatArray,
) -> NormalEquations:
    """The normal equations with ``v(c) - v(c_0)`` removed (module docstring, remedy 1)."""
    ref = normal.reference
    at_reference = evaluate_coefficients(ref, basis, normal.max_orders)
    return replace(
        normal,
        gram=normal.gram - moments.gram,
        cross=normal.cross + moments.gram @ ref - moments.cross,
        chi2_ref=normal.chi2_ref
        - errors.variance(weights, at_reference)
        + errors.variance(weights, operating_point),
    )


def unidentified_share(gram: FloatArray, moments: FloatArray, orders: Orders,
                       max_orders: Orders) -> float:
    """``mu``: the largest generalised eigenvalue of ``(C, G)`` on the model ``orders``.

    ``inf`` where the data's own ``G`` is singular there (nothing is identified).
    """
    idx = full_indices(orders, max_orders)
    g = gram[np.ix_(idx, idx)]
    scale = np.sqrt(np.maximum(np.diag(g), np.finfo(float).tiny))
    try:
        lower = np.linalg.cholesky(g / np.outer(scale, scale))
    except np.linalg.LinAlgError:
        return float("inf")
    c = moments[np.ix_(idx, idx)] / np.outer(scale, scale)
    half = np.linalg.solve(lower, np.linalg.solve(lower, c).T)
    return float(np.linalg.eigvalsh(0.5 * (half + half.T))[-1])


def identified_orders(
    gram: FloatArray, moments: FloatArray, largest: Orders, smallest: Orders,
    mu_max: float = MU_MAX,
) -> tuple[Orders, float]:
    """The largest orders within ``largest`` that the data identify, and their ``mu``.

    Identified: ``mu <= mu_max``.

    While ``largest`` is not identified, the box shrinks from the top: of the parameters
    with the most terms, the one whose last term's removal lowers ``mu`` most loses it.
    Which parameter's structure is real the cut cannot know; dropping the terms that lower
    ``mu`` most wherever they are cut the poorly seen parameters to their levels in a
    test run (four calibrators: (8, 3, 6, 8, 8) from (8, 8, 8, 8, 8), where the truth's
    T_cos has four terms), and the search found nothing to stand on. Stops at
    ``smallest``, whose ``mu`` may still exceed ``mu_max``; the caller decides what that means.
    """
    orders = as_orders(largest)
    mu = unidentified_share(gram, moments, orders, largest)
    while mu > mu_max:
        free = [k for k, n in enumerate(orders) if n > smallest[k]]
        if not free:
            break
        most = max(orders[k] for k in free)
        trials = []
        for k in free:
            if orders[k] == most:
                fewer = as_orders([m - (j == k) for j, m in enumerate(orders)])
                trials.append((unidentified_share(gram, moments, fewer, largest), fewer))
        mu, orders = min(trials)
    return orders, mu


@dataclass(frozen=True)
class Identified:
    """The models of a box the calibrators identify above their reflections' errors.

    ``box`` is :func:`identified_orders`' cut: every model within it is identified. A
    model beyond it may be identified too (the identified models are a down-set, not a
    box): ``admits`` asks its own ``mu``. Four calibrators with VNA noise 1e-3 showed why
    the box alone is not enough: the truth (1, 6, 3, 5, 3) had ``mu`` 0.005, but the box
    cut from (8, 8, 8, 8, 8) was (6, 5, 5, 6, 6), and the antenna came out 56 times the
    noise floor off. ``data_gram`` and ``error_gram`` are ``G`` and ``C`` in the layout of
    ``max_orders``.
    """

    box: Orders
    data_gram: FloatArray
    error_gram: FloatArray
    max_orders: Orders
    mu_max: float = MU_MAX
    _shares: dict[Orders, float] = field(default_factory=dict, compare=False, repr=False)

    def share(self, orders: Orders) -> float:
        """``mu`` of ``orders`` (:func:`unidentified_share`), computed once."""
        if orders not in self._shares:
            self._shares[orders] = unidentified_share(
                self.data_gram, self.error_gram, orders, self.max_orders
            )
        return self._shares[orders]

    def admits(self, orders: Orders) -> bool:
        """Whether ``orders`` is identified: within ``box``, or ``mu <= mu_max``."""
        if all(n <= m for n, m in zip(orders, self.box, strict=True)):
            return True
        return self.share(as_orders(orders)) <= self.mu_max
