"""The smooth-function hypothesis with a prior scale per parameter, marginalised.

The hierarchical prior of :mod:`calibration.regression.shrinkage` gives the higher Legendre terms of
all five noise-wave parameters one scale ``tau``. T_NS (about 1000 K) and T_sin (about
90 K) are different physical quantities, and their structures need not be alike in size:
one scale follows the largest, and the terms of a parameter with less structure are
either charged an Occam factor sized for the largest or shrunk with the wrong width. Here
each parameter has its own scale, with the decay shared::

    c_kj | tau_k, rho ~ N(0, (tau_k rho^(j-1))^2)      (j >= 1; constants as before)
    log tau_k ~ as the shared tau's (shrinkage.log_scale_density), independently
    rho ~ uniform on the prior's decays

and the scales are marginalised, not fitted (fitting them, type-II maximum likelihood,
made the error bars overconfident: :mod:`calibration.choice.scale_fit`). Five scales are too
many for a grid; the integral ``Z = sum_rho (1/D) int Z(tau, rho) p(tau) dtau`` is taken
by importance sampling (Owen 2013, *Monte Carlo theory, methods and examples*, ch. 9):
for each decay that carries weight, a Student-t proposal (5 degrees of freedom, seeded,
so the solver stays deterministic) about the mode of ``log Z`` in ``log tau``, its
covariance 1.5^2 times the inverse Hessian there. Each draw ``s`` is a component of the
posterior mixture, with weight ``Z(tau_s) p(tau_s) / (S q(tau_s))``.

The mode is found with the evidence's gradient (MacKay 1992, *Neural Comput.* 4, 415;
for the normal-inverse-gamma model, ``s^2 = b*/a*``)::

    d log Z / d log v_i = ((Sigma_ii + mu_i^2) / (s^2 v_i) - 1) / 2

for a coefficient of prior variance ``v_i``, posterior mean ``mu`` and scale matrix
``Sigma = s^2 Lambda^-1`` (:attr:`LinearPosterior.scale`); ``v_i`` of parameter ``k``'s
higher terms moves with ``2 log tau_k``.

Under the shared-scale prior (``ShrinkagePrior(per_parameter=False)``; the default fits
a scale per parameter instead, :mod:`calibration.choice.scale_fit`), the solver's averaged
posterior (:func:`calibration.choice.model_fit.fit`) offers this as a third hypothesis about
the receiver, beside polynomials and smooth functions under one scale,
all three at even prior odds; the data weigh them through the evidence. Measured on the
benchmark's earlier ensembles, whose random terms were sized in the prior's shrunk sd
(``benchmarks/README.md``; ``python -m benchmarks.model_choice --runs 100 --seed 100``,
the same runs, actual / predicted error and 68/95 % coverage): smooth truths whose five
parameters have their own sizes and decays 1.14, 61/92 % -> 1.07, 65/94 %; 8 calibrators
1.23 -> 1.22; the four EDGES loads 1.04 -> 1.03; the other rows unchanged (REACH-like
truths do not draw it: :data:`BEHIND_NATS`). A prototype that left out the truncation of
the proposal to the prior's box (the ``log_q`` correction below) over-weighted this
hypothesis several-fold and looked better on 8 calibrators (1.17); the weights here
match a quadrature (a test).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from ..core.errors import IllPosedError
from ..model.noise_waves import N_PARAMETERS
from ..model.polynomial_model import Orders
from ..regression.conjugate import LinearPosterior, ScalePrior, solve_many
from ..regression.normal_equations import NormalEquations
from ..regression.shrinkage import (
    ShrinkagePrior,
    log_scale_density,
    log_scale_density_gradient,
    narrowing,
)

FloatArray = NDArray[np.float64]

#: Draws per decay.
DRAWS = 48
#: Degrees of freedom of the Student-t proposal: heavier tails than the Laplace
#: approximation, so a skewed evidence surface is still covered.
PROPOSAL_DOF = 5.0
#: The proposal's width over the inverse Hessian's.
INFLATE = 1.5
#: Decays carrying less than this share of the largest model's shared-scale evidence are
#: left out (their share of the integral is below it too, as far as one scale can tell).
DECAY_SHARE = 1e-3
#: Step in ``log tau`` of the finite difference of the gradient (the Hessian).
STEP = 0.05
#: Seed of the proposal's draws: the same data give the same solution.
SEED = 0
#: The hypothesis is not drawn where the shared-scale smooth model trails the pool's best
#: by more than this (nats): per-parameter scales raised the smooth model's evidence by at
#: most 6.5 nats over the shared scale on REACH-like, weak-term and random truths (20 runs
#: each; on the REACH-like ones the polynomials lead the smooth model by 22-30 nats), so
#: 15 nats behind it cannot carry 1e-4 of the weight, and the solve is spared its cost.
BEHIND_NATS = 15.0


@dataclass(frozen=True)
class ScaleDraws:
    """Posteriors of one model at sampled scales and their log weights.

    ``log_weights`` sum (by ``logsumexp``) to the model's log evidence with the scales
    marginalised, its log prior included.
    """

    posteriors: tuple[LinearPosterior, ...]
    log_weights: FloatArray


def variances(
    orders: Sequence[int], log_tau: FloatArray, decay: float | FloatArray, constant_sd_k: float
) -> FloatArray:
    """Prior variance of every coefficient of ``orders`` for each row of ``log_tau``: ``(S, P)``.

    Parameter ``k``'s constant term has the sd ``constant_sd_k``, its term ``j >= 1``
    ``exp(log_tau[:, k]) decay^(j - 1)`` (:func:`calibration.regression.shrinkage.narrowing`); one
    decay for every row, or one per row (``(S,)``).
    """
    owner, power = _layout(tuple(orders))
    sd = np.exp(log_tau[:, owner]) * narrowing(np.asarray(decay)[..., None], power)
    return np.where(power[None, :] < 0, constant_sd_k**2, sd**2)


@lru_cache(maxsize=4096)
def _layout(orders: Orders) -> tuple[NDArray[np.intp], FloatArray]:
    """Each coefficient's parameter and its order less one (``-1`` on a constant)."""
    owner = np.repeat(np.arange(len(orders)), orders)
    power = np.concatenate([np.arange(n, dtype=np.float64) - 1.0 for n in orders])
    return owner, power


def evidence_gradient(
    normal: NormalEquations,
    orders: Orders,
    log_tau: FloatArray,
    decay: float | FloatArray,
    prior: ShrinkagePrior,
    scale_prior: ScalePrior | None,
) -> tuple[list[LinearPosterior], FloatArray, FloatArray]:
    """Posteriors, ``log Z`` ``(S,)`` and its gradient in ``log tau`` ``(S, 5)`` (module doc).

    ``decay``: one for every row of ``log_tau``, or one per row.
    """
    var = variances(orders, log_tau, decay, prior.constant_sd_k)
    posts = solve_many(normal, orders, np.zeros_like(var), var, scale_prior)
    log_z = np.array([p.log_evidence for p in posts])
    per_coefficient = np.array([
        0.5 * ((np.diag(p.scale) + p.mean**2) / (p.noise_variance * v) - 1.0)
        for p, v in zip(posts, var, strict=True)
    ])
    owner = np.repeat(np.arange(N_PARAMETERS), orders)
    higher = np.concatenate([np.arange(n) >= 1 for n in orders])
    grad = np.zeros((len(posts), N_PARAMETERS))
    for k in range(N_PARAMETERS):
        grad[:, k] = 2.0 * per_coefficient[:, (owner == k) & higher].sum(axis=1)
    return posts, log_z, grad


#: ``log p(log tau)`` and its gradient at rows of ``log tau``: ``(S,)`` and ``(S, 5)``.
LogPrior = Callable[[FloatArray], tuple[FloatArray, FloatArray]]


def scale_log_prior(prior: ShrinkagePrior) -> LogPrior:
    """The hyperprior of the five scales (``prior.scale_hyperprior_k``), independent."""
    s = prior.scale_hyperprior_k

    def log_prior(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        return np.sum(log_scale_density(x, prior, s), axis=1), log_scale_density_gradient(x, s)

    return log_prior


def width_log_prior(prior: ShrinkagePrior, orders: Orders) -> LogPrior | None:
    """The fitted widths' prior (``prior.width_hyperprior_k``) for the model ``orders``.

    Only the parameters with higher terms in ``orders``: the others' ``tau_k`` is not in
    the model, and the prior alone would move it. ``None`` where the widths have none.
    """
    s = prior.width_hyperprior_k
    if s is None:
        return None
    structured = np.array([n > 1 for n in orders])

    def log_prior(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        value = np.sum(log_scale_density(x, prior, s)[:, structured], axis=1)
        return value, log_scale_density_gradient(x, s) * structured

    return log_prior


def _log_posterior(
    normal: NormalEquations, orders: Orders, x: FloatArray, decay: float | FloatArray,
    prior: ShrinkagePrior, scale_prior: ScalePrior | None, log_prior: LogPrior | None,
) -> tuple[FloatArray, FloatArray]:
    """``log Z`` at each row of ``x`` and its gradient (with ``log_prior`` added)."""
    _, log_z, grad = evidence_gradient(normal, orders, x, decay, prior, scale_prior)
    if log_prior is None:
        return log_z, grad
    log_p, grad_p = log_prior(x)
    return log_z + log_p, grad + grad_p


def maximise(
    normal: NormalEquations, orders: Orders, decay: float, prior: ShrinkagePrior,
    scale_prior: ScalePrior | None, start: FloatArray, bounds: tuple[float, float],
    log_prior: LogPrior | None,
) -> tuple[FloatArray, float] | None:
    """The ``log tau`` maximising ``log Z`` plus ``log_prior`` (if any).

    Type-II maximum likelihood, or the posterior mode of the scales; the maximum is
    returned with it, ``None`` where no scale gives a finite one. Bounded quasi-Newton
    with the analytic gradient (:func:`evidence_gradient`) from ``start``.
    """
    from scipy.optimize import minimize

    def negative(x: FloatArray) -> tuple[float, FloatArray]:
        try:
            value, grad = _log_posterior(
                normal, orders, x[None], decay, prior, scale_prior, log_prior
            )
        except IllPosedError:
            return np.inf, np.zeros_like(x)
        return -float(value[0]), -grad[0]

    result = minimize(negative, start, jac=True, method="L-BFGS-B", bounds=[bounds] * start.size)
    if not np.isfinite(result.fun):
        return None
    return result.x, -float(result.fun)


def maximise_each(
    normal: NormalEquations, orders: Orders, decays: Sequence[float], prior: ShrinkagePrior,
    scale_prior: ScalePrior | None, starts: FloatArray, bounds: tuple[float, float],
    log_prior: LogPrior | None = None,
) -> list[tuple[FloatArray, float] | None]:
    """:func:`maximise` at each of ``decays`` in one search.

    ``starts`` is ``(D, 5)``. The sum of the decays' ``log Z`` is separable, so its
    maximum is each decay's; one quasi-Newton search over the stacked scales scores every
    decay in one batched solve per step, several times faster than a search per decay
    (the same maxima to 1e-6 nats on simulated runs). One stopping rule serves every
    decay, so one whose evidence lies far below the others' (millions of nats, in a test)
    can be left a few 1e-3 nats short: :func:`calibration.choice.scale_fit.fit_scales` polishes
    the best alone. Should the starts leave a model ill-posed, each decay is searched
    alone.
    """
    from scipy.optimize import minimize
    rows, width = starts.shape
    decay = np.asarray(decays, dtype=float)

    def total(x: FloatArray) -> tuple[float, FloatArray]:
        try:
            log_z, grad = _log_posterior(
                normal, orders, x.reshape(rows, width), decay, prior, scale_prior, log_prior
            )
        except IllPosedError:
            return -np.inf, np.zeros_like(x)
        return float(np.sum(log_z)), grad.ravel()

    # Measured from the starts' log Z: the search's relative stopping rule then acts on the
    # gain (nats), not on a sum of D evidences of thousands of nats each.
    origin = total(starts.ravel())[0]

    def negative(x: FloatArray) -> tuple[float, FloatArray]:
        value, grad = total(x)
        return origin - value, -grad

    result = None
    if np.isfinite(origin):
        result = minimize(
            negative, starts.ravel(), jac=True, method="L-BFGS-B", bounds=[bounds] * starts.size
        )
    if result is None or not np.isfinite(result.fun):
        return [
            maximise(normal, orders, d, prior, scale_prior, x0, bounds, log_prior)
            for d, x0 in zip(decays, starts, strict=True)
        ]
    x = result.x.reshape(rows, width)
    log_z, _ = _log_posterior(normal, orders, x, decay, prior, scale_prior, log_prior)
    return [(row, float(z)) for row, z in zip(x, log_z, strict=True)]


def negative_hessian(
    normal: NormalEquations, orders: Orders, x: FloatArray, decay: float,
    prior: ShrinkagePrior, scale_prior: ScalePrior | None, log_prior: LogPrior | None,
    coordinates: Sequence[int] | NDArray[np.intp], step: float,
) -> FloatArray:
    """``-d^2 (log Z + log_prior) / d x_i d x_j`` at ``x`` over ``coordinates``, symmetric.

    Central differences (step ``step`` in ``log tau``) of the analytic gradient
    (:func:`evidence_gradient`), one batched solve. Raises :class:`IllPosedError` where a
    shifted point leaves the model ill-posed.
    """
    index = np.asarray(coordinates, dtype=np.intp)
    shifts = np.zeros((2 * index.size, x.size))
    shifts[0::2, index] = step * np.eye(index.size)
    shifts[1::2, index] = -step * np.eye(index.size)
    _, grads = _log_posterior(
        normal, orders, x[None, :] + shifts, decay, prior, scale_prior, log_prior
    )
    hessian = (grads[0::2, index] - grads[1::2, index]) / (2.0 * step)
    return -0.5 * (hessian + hessian.T)


def _mode(
    normal: NormalEquations, orders: Orders, decay: float, prior: ShrinkagePrior,
    scale_prior: ScalePrior | None, start: FloatArray, bounds: tuple[float, float],
) -> tuple[FloatArray, FloatArray] | None:
    """The mode of ``log Z + log p(log tau)`` and the Hessian of its negative there."""
    log_prior = scale_log_prior(prior)
    found = maximise(normal, orders, decay, prior, scale_prior, start, bounds, log_prior)
    if found is None:
        return None
    x = found[0]
    try:
        hessian = negative_hessian(
            normal, orders, x, decay, prior, scale_prior, log_prior, range(x.size), STEP
        )
    except IllPosedError:
        return None
    return x, hessian


def _t_log_density(x: FloatArray, mean: FloatArray, chol: FloatArray, dof: float) -> FloatArray:
    from scipy.special import gammaln
    d = mean.size
    z = np.linalg.solve(chol, (x - mean).T).T
    return (
        gammaln(0.5 * (dof + d)) - gammaln(0.5 * dof) - 0.5 * d * np.log(dof * np.pi)
        - np.sum(np.log(np.diag(chol))) - 0.5 * (dof + d) * np.log1p(np.sum(z * z, axis=1) / dof)
    )


def draw_scales(
    normal: NormalEquations,
    orders: Orders,
    prior: ShrinkagePrior,
    scale_prior: ScalePrior | None,
    shared_grid: FloatArray,
    log_model_prior: float,
) -> ScaleDraws | None:
    """The model ``orders`` under a scale per parameter, as weighted draws (module docstring).

    ``shared_grid`` is the model's log evidence on the shared-scale grid
    (:class:`~calibration.regression.shrinkage.EvidenceGrid`): it picks the decays worth
    sampling and
    each one's starting scale. ``None`` where no decay gives a usable mode.
    """
    bounds = (float(np.log(prior.tau_min_k)), float(np.log(prior.tau_max_k)))
    width = bounds[1] - bounds[0]
    by_decay = np.asarray(shared_grid).reshape(len(prior.decays), prior.n_scales)
    top = float(np.max(by_decay))
    share = np.exp(by_decay - top).sum(axis=1)
    share /= share.sum()
    rng = np.random.default_rng(SEED)
    posteriors: list[LinearPosterior] = []
    log_weights: list[FloatArray] = []
    log_prior = -np.log(len(prior.decays)) + log_model_prior
    for i, decay in enumerate(prior.decays):
        if share[i] < DECAY_SHARE:
            continue
        start = np.full(N_PARAMETERS, np.log(prior.scales_k[int(np.argmax(by_decay[i]))]))
        found = _mode(normal, orders, decay, prior, scale_prior, start, bounds)
        if found is None:
            continue
        mode, hessian = found
        values, vectors = np.linalg.eigh(hessian)
        values = np.maximum(values, 12.0 / width**2)  # no wider than the uniform prior
        chol = np.linalg.cholesky((vectors / values) @ vectors.T * INFLATE**2)
        z = rng.standard_normal((8 * DRAWS, N_PARAMETERS))
        chi = rng.chisquare(PROPOSAL_DOF, 8 * DRAWS)
        candidates = mode + (z @ chol.T) / np.sqrt(chi / PROPOSAL_DOF)[:, None]
        inside = np.all((candidates >= bounds[0]) & (candidates <= bounds[1]), axis=1)
        x = candidates[inside][:DRAWS]
        if not len(x):
            continue
        # The proposal truncated to the prior's box: its density over the share inside.
        log_q = _t_log_density(x, mode, chol, PROPOSAL_DOF) - np.log(np.mean(inside))
        try:
            posts, log_z, _ = evidence_gradient(normal, orders, x, decay, prior, scale_prior)
        except IllPosedError:
            continue
        posteriors.extend(posts)
        log_p = np.sum(log_scale_density(x, prior, prior.scale_hyperprior_k), axis=1)
        log_weights.append(log_z + log_p + log_prior - log_q - np.log(len(x)))
    if not posteriors:
        return None
    return ScaleDraws(tuple(posteriors), np.concatenate(log_weights))
