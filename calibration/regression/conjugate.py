"""Conjugate Bayesian linear regression: posterior, evidence, predictive.

The model (thesis section 3.3.1) is ``y = X c + e`` with ``e ~ N(0, s^2 W^-1)``, a
Gaussian prior ``c | s^2 ~ N(mu_0, s^2 V_0)`` and either

* an inverse-gamma prior ``s^2 ~ IG(a, b)`` (the normal-inverse-gamma prior of eq. 3.34),
  giving a Student-t posterior with ``2 a*`` degrees of freedom and the evidence of
  eq. 3.35, or
* a known ``s^2 = 1`` (the noise variance is fully given by ``W``), giving a Gaussian
  posterior and the Gaussian evidence.

With ``Lambda = X^T W X + V_0^-1`` the posterior update is (eq. 3.36, whitened)::

    mu*  = Lambda^-1 (X^T W y + V_0^-1 mu_0),     V* = Lambda^-1
    a*   = a + N/2
    b*   = b + (1/2) [ (y - X mu*)^T W (y - X mu*) + (mu* - mu_0)^T V_0^-1 (mu* - mu_0) ]

The bracket is evaluated as residuals, never as ``y^T y - mu*^T V*^-1 mu*`` (the numerically
stable form of the thesis's footnote to eq. 3.36). The log evidence is::

    log Z = -N/2 log 2 pi + 1/2 sum log w + a log b - a* log b* + log Gamma(a*) - log Gamma(a)
            - 1/2 log |Lambda| - 1/2 log |V_0|                            (eq. 3.35)

and with known ``s^2 = 1``: ``... - 1/2 Q_min - 1/2 log|Lambda| - 1/2 log|V_0|``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from contextlib import suppress
from dataclasses import dataclass, field

import numpy as np
from numpy.linalg import LinAlgError
from numpy.typing import NDArray

from ..core.errors import IllPosedError
from ..model.noise_waves import N_PARAMETERS, PARAMETERS
from ..model.polynomial_model import Orders, as_orders, coefficient_slices
from .normal_equations import NormalEquations

FloatArray = NDArray[np.float64]
LOG_2PI = float(np.log(2 * np.pi))


@dataclass(frozen=True)
class CoefficientPrior:
    """Independent Gaussian priors on the polynomial coefficients, in kelvin.

    ``sd_k`` is one width for all coefficients or one per parameter (unc, cos, sin, NS, L);
    ``mean_k`` optionally gives prior mean coefficients per parameter name (missing terms
    are zero). The default, 3000 K about zero, is our reading of the thesis's "spread of 10"
    on a 300 K scale (section 4.4): wide against any physical noise temperature.
    """

    sd_k: float | Sequence[float] = 3000.0
    mean_k: Mapping[str, Sequence[float]] = field(default_factory=dict)

    def vectors(self, orders: Sequence[int]) -> tuple[FloatArray, FloatArray]:
        """Prior mean and variance of every coefficient, concatenated for ``orders``."""
        sds = np.broadcast_to(np.asarray(self.sd_k, dtype=float), (N_PARAMETERS,))
        if np.any(sds <= 0):
            raise ValueError("prior widths must be > 0")
        means, variances = [], []
        for k, n in enumerate(orders):
            given = np.asarray(self.mean_k.get(PARAMETERS[k], ()), dtype=float)[:n]
            means.append(np.concatenate([given, np.zeros(n - given.size)]))
            variances.append(np.full(n, sds[k] ** 2))
        return np.concatenate(means), np.concatenate(variances)


@dataclass(frozen=True)
class TermPrior(CoefficientPrior):
    """A prior term by term: what is known beforehand of the size of a receiver's structure.

    ``term_sd_k[name]`` gives the sd (K) of that parameter's Legendre terms 1, 2, ... (the
    last repeats to higher orders); levels and parameters not named keep ``sd_k``. Zero
    prior means. Under it the orders are not climbed but every model of the search's box
    is scored, all equally likely, and averaged (:func:`calibration.choice.model_fit.fit`): the
    posterior of a receiver whose term sizes (from an earlier season, or a simulation's
    own ensemble, ``benchmarks/model_choice.py``) and possible orders are known.
    """

    term_sd_k: Mapping[str, Sequence[float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.mean_k:
            raise ValueError("a TermPrior has zero prior means")
        for name, sds in self.term_sd_k.items():
            if name not in PARAMETERS:
                raise ValueError(f"unknown parameter {name!r} (one of {', '.join(PARAMETERS)})")
            if len(sds) == 0 or any(not sd > 0 for sd in sds):
                raise ValueError(f"the term widths of {name} must be positive, at least one")

    def vectors(self, orders: Sequence[int]) -> tuple[FloatArray, FloatArray]:
        """Prior mean (zero) and variance of every coefficient of ``orders``."""
        means, variances = super().vectors(orders)
        start = 0
        for name, n in zip(PARAMETERS, orders, strict=True):
            given = np.asarray(self.term_sd_k.get(name, ()), dtype=float)
            if given.size and n > 1:
                terms = given[np.minimum(np.arange(n - 1), given.size - 1)]
                variances[start + 1 : start + n] = terms**2
            start += n
        return means, variances


@dataclass(frozen=True)
class ScalePrior:
    """Inverse-gamma prior ``IG(a, b)`` on the noise-variance scale ``s^2`` (eq. 3.34)."""

    a: float = 1.0
    b: float = 2.0

    def __post_init__(self) -> None:
        if not (self.a > 0 and self.b > 0):
            raise ValueError("the inverse-gamma prior needs a > 0 and b > 0")


@dataclass(frozen=True)
class LinearPosterior:
    """Posterior of the coefficients of one model.

    ``mean`` and ``scale`` locate a multivariate Student-t with ``dof`` degrees of freedom
    (``dof = inf``: Gaussian with covariance ``scale``). ``noise_variance`` is the
    posterior estimate of ``s^2`` (``b*/a*``; 1 when the scale is known).
    """

    orders: Orders
    mean: FloatArray
    scale: FloatArray
    dof: float
    log_evidence: float
    noise_variance: float
    chi2: float
    n_rows: int

    @property
    def covariance(self) -> FloatArray:
        """Posterior covariance of the coefficients."""
        if np.isinf(self.dof):
            return self.scale
        return self.scale * self.dof / (self.dof - 2.0)

    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """``n`` posterior draws of the coefficient vector, shape ``(n, P)``."""
        chol = np.linalg.cholesky(self.scale)
        z = rng.standard_normal((n, self.mean.size)) @ chol.T
        if not np.isinf(self.dof):
            z *= np.sqrt(self.dof / rng.chisquare(self.dof, size=(n, 1)))
        return self.mean + z

    def per_parameter(self) -> dict[str, FloatArray]:
        """Posterior mean coefficients by parameter name."""
        return {
            p: self.mean[s]
            for p, s in zip(PARAMETERS, coefficient_slices(self.orders), strict=True)
        }


def solve(
    normal: NormalEquations,
    orders: Sequence[int],
    prior_mean: FloatArray,
    prior_var: FloatArray,
    scale_prior: ScalePrior | None,
) -> LinearPosterior:
    """Posterior and evidence of the sub-model ``orders``.

    ``prior_mean``/``prior_var`` are the ``V_0``-scale prior of that model's coefficients;
    ``scale_prior=None`` means the noise variance is known (``s^2 = 1``).
    """
    return solve_many(normal, orders, prior_mean[None], prior_var[None], scale_prior)[0]


def solve_many(
    normal: NormalEquations,
    orders: Sequence[int],
    prior_means: FloatArray,
    prior_vars: FloatArray,
    scale_prior: ScalePrior | None,
) -> list[LinearPosterior]:
    """:func:`solve` for one model under ``B`` priors (``(B, P)`` means and variances) at once.

    Each posterior: precision ``Lambda = G + V_0^-1``, mean ``Lambda^-1 (X^T W y + V_0^-1
    m_0)``, and the evidence of eq. 3.35 (``Q_min`` and ``log|Lambda|``). The precisions are
    Jacobi-scaled before their (stacked) Cholesky factorisation. A prior the data and it
    together leave singular raises :class:`IllPosedError`.
    """
    orders = as_orders(orders)
    idx = normal.indices(orders)
    inv_var = 1.0 / prior_vars
    try:
        chol, jacobi, scaled = _factorised(normal, idx, inv_var)
    except LinAlgError as err:
        raise IllPosedError(
            f"the data do not constrain a model with orders {orders}: "
            "add calibrators or lower the orders"
        ) from err
    rhs = normal.rhs(idx)[None] + prior_means * inv_var
    inverse = np.linalg.inv(scaled) / (jacobi[:, :, None] * jacobi[:, None, :])
    inverse = 0.5 * (inverse + np.swapaxes(inverse, 1, 2))
    means = np.einsum("bij,bj->bi", inverse, rhs)
    chi2 = _chi2(normal, idx, means)
    q_min = chi2 + np.sum((means - prior_means) ** 2 * inv_var, axis=1)
    log_z = log_evidence_from(normal, q_min, _occam(chol, jacobi, prior_vars), scale_prior)
    if scale_prior is None:
        return [
            LinearPosterior(orders, m, c, np.inf, float(z), 1.0, float(x), normal.n_rows)
            for m, c, z, x in zip(means, inverse, log_z, chi2, strict=True)
        ]
    a_star = scale_prior.a + 0.5 * normal.n_rows
    b_star = scale_prior.b + 0.5 * q_min
    return [
        LinearPosterior(
            orders, m, (bs / a_star) * c, 2.0 * a_star, float(z), float(bs / a_star), float(x),
            normal.n_rows,
        )
        for m, c, z, bs, x in zip(means, inverse, log_z, b_star, chi2, strict=True)
    ]


def stacked_log_evidence(
    normal: NormalEquations,
    idx: NDArray[np.intp],
    prior_vars: FloatArray,
    scale_prior: ScalePrior | None,
) -> FloatArray:
    """Log evidence alone of ``B`` sub-models of equal size, zero prior mean, at once.

    ``idx`` ``(B, P)`` picks each model's coefficients (:meth:`NormalEquations.indices`),
    ``prior_vars`` ``(B, P)`` their prior variances. The algebra of :func:`solve_many`
    without the posterior covariance; raises ``LinAlgError`` where a precision is singular.
    """
    chol, jacobi, scaled = _factorised(normal, idx, 1.0 / prior_vars)
    rhs = normal.rhs(idx)
    means = np.linalg.solve(scaled, (rhs / jacobi)[:, :, None])[:, :, 0] / jacobi
    q_min = _chi2(normal, idx, means) + np.sum(means**2 / prior_vars, axis=1)
    return log_evidence_from(normal, q_min, _occam(chol, jacobi, prior_vars), scale_prior)


def models_log_evidence(
    normal: NormalEquations,
    models: Sequence[Orders],
    variances: Callable[[Orders], FloatArray],
    scale_prior: ScalePrior | None,
) -> FloatArray:
    """Log evidence of each of ``models`` (``-inf`` where ill-posed), zero prior mean.

    ``variances(orders)`` gives a model's prior variances, shape ``(1, P)``. Models with
    the same number of coefficients share one stacked factorisation
    (:func:`stacked_log_evidence`); a group with an ill-posed model is scored one by one.
    """
    out = np.full(len(models), -np.inf)
    groups: dict[int, list[int]] = {}
    for i, orders in enumerate(models):
        groups.setdefault(sum(orders), []).append(i)
    for members in groups.values():
        idx = np.stack([normal.indices(models[i]) for i in members])
        var = np.concatenate([variances(models[i]) for i in members])
        try:
            out[members] = stacked_log_evidence(normal, idx, var, scale_prior)
        except LinAlgError:
            for i, row, v in zip(members, idx, var, strict=True):
                with suppress(LinAlgError):
                    out[i] = stacked_log_evidence(normal, row[None], v[None], scale_prior)[0]
    return out


def log_evidence_from(
    normal: NormalEquations, q_min: FloatArray, occam: FloatArray, scale_prior: ScalePrior | None
) -> FloatArray:
    """Eq. 3.35 (or its known-``s^2`` form) from ``Q_min`` and the Occam term, per prior.

    ``occam`` is ``-1/2 log|Lambda| - 1/2 log|V_0|``.
    """
    from scipy.special import gammaln
    base = -0.5 * normal.n_rows * LOG_2PI + 0.5 * normal.sum_log_weights
    if scale_prior is None:
        return np.asarray(base - 0.5 * q_min + occam)
    a, b = scale_prior.a, scale_prior.b
    a_star = a + 0.5 * normal.n_rows
    return np.asarray(
        base + a * np.log(b) - a_star * np.log(b + 0.5 * q_min)
        + gammaln(a_star) - gammaln(a) + occam
    )


def _factorised(
    normal: NormalEquations, idx: NDArray[np.intp], inv_var: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Cholesky factors of the Jacobi-scaled precisions ``G + V_0^-1``, with the scaling.

    ``idx``: one model's coefficients ``(P,)`` for every prior, or one model per row
    ``(B, P)``. Scaled to unit diagonal first: the precision's diagonal spans many decades
    (a 1000 K constant beside a 1 mK-wide high term), which the factorisation would
    otherwise feel.
    """
    if idx.ndim == 1:
        block = normal.gram[np.ix_(idx, idx)]
        precision = np.broadcast_to(block, (len(inv_var), *block.shape)).copy()
    else:
        precision = normal.gram[idx[:, :, None], idx[:, None, :]]
    diagonal = np.einsum("bii->bi", precision)
    diagonal += inv_var
    jacobi = np.sqrt(diagonal)
    scaled = precision / (jacobi[:, :, None] * jacobi[:, None, :])
    return np.linalg.cholesky(scaled), jacobi, scaled


def _chi2(normal: NormalEquations, idx: NDArray[np.intp], means: FloatArray) -> FloatArray:
    """The weighted residual sum of squares at each of ``means``, from the moments.

    ``idx`` as in :func:`_factorised`.
    """
    offsets = np.broadcast_to(normal.reference, (len(means), normal.reference.size)).copy()
    offsets[np.arange(len(means))[:, None], idx] -= means
    quadratic = np.sum((offsets @ normal.gram) * offsets, axis=1)
    return np.asarray(normal.chi2_ref + 2.0 * offsets @ normal.cross + quadratic)


def _occam(chol: FloatArray, jacobi: FloatArray, prior_vars: FloatArray) -> FloatArray:
    """``-1/2 log|Lambda| - 1/2 log|V_0|`` from the scaled Cholesky factor and its scaling."""
    log_det_precision = 2.0 * np.sum(
        np.log(np.diagonal(chol, axis1=1, axis2=2)) + np.log(jacobi), axis=1
    )
    return np.asarray(-0.5 * log_det_precision - 0.5 * np.sum(np.log(prior_vars), axis=1))
