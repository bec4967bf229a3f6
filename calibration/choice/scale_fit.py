"""Each parameter's own prior scale, set by the data.

The hierarchical prior of :mod:`calibration.regression.shrinkage` gives the higher Legendre terms of
all five parameters one scale ``tau``. When their structures differ in size (a T_NS with
a 30-sigma slope beside a T_cos whose terms sit at 2-5 sigma), the shared scale follows
the large one and charges the small parameter's terms an Occam factor of
``log(tau / posterior sd)`` sized for the large one: real terms of the small parameter
are dropped, and the bias they leave lies outside the error bars.

Here each parameter ``k`` has its own scale, with the decay ``rho`` shared, and the
scales share a half-Cauchy prior whose scale ``s`` is the receiver's::

    c_k0 ~ N(0, constant_sd^2),    c_kj ~ N(0, (tau_k rho^(j-1))^2)   (j >= 1)
    tau_k | s ~ half-Cauchy(s)

The widths are set by the data in two levels (empirical Bayes), for each ``rho`` of the
prior's grid, the best ``rho`` kept:

1. ``tau_k`` maximising the evidence of the largest model alone (type-II maximum
   likelihood: MacKay 1992, *Neural Comput.* 4, 415; Tipping 2001 for one scale per
   group). A parameter whose structure the data cannot see gets the range's floor
   (1 mK) here: the evidence is flat below the data's reach and the Occam factor keeps
   falling. Its higher terms would then cost nothing and carry no variance, and the
   error bars would miss whatever structure below the data's reach it has.
2. ``s`` from the widths off the floor (:func:`width_scale`, the half-Cauchy scale most
   likely to have given them): the size of the structure this receiver has.
3. ``tau_k`` again, as the mode of their posterior in ``log tau_k`` under that prior
   (:func:`fit_largest`). The prior's density in ``log tau`` grows as ``tau`` below
   ``s``, so an unseen parameter's width sits where the evidence starts to fall, a few
   posterior sd up, never on the floor (a boundary-avoiding prior: Chung et al. 2013,
   *Psychometrika* 78, 685; the half-Cauchy for hierarchical scales: Gelman 2006,
   *Bayesian Anal.* 1, 515); a seen parameter's width moves little (tests).

Which model is the question of each hypothesis of :mod:`calibration.choice.averaging`:

* **smooth functions** (every term up to the box's edge): the largest model. It holds
  every term any candidate can use, so its evidence sees each parameter's whole
  structure; the orders are first searched under these widths.
* **polynomials**: the evidence-best model of that search. The widths are refitted
  there (the same prior), from the first, for the parameters with higher terms in it (a
  parameter with one term has no ``tau_k`` in its evidence and keeps its width), and the
  orders searched again from that best under the new widths; the polynomials are
  averaged under them and the smooth functions under the first
  (:func:`calibration.choice.hypotheses.hypotheses_with_own_widths`).

Each hypothesis's evidence is then taken with its widths marginalised, not at their
mode (:func:`log_occam`, Laplace's method about the mode): five widths fitted to the 35
higher terms of the smooth functions are pinned down more sharply than five fitted to a
few terms of a polynomial, and pay a larger Occam factor for it (2-3 nats more, median).

Measured on the benchmark's ensembles (``python -m benchmarks.model_choice --runs 100
--seed 100``; README, "Model choice", gives every row, ``benchmarks/README.md`` the
alternatives): against type-II widths alone, the half-Cauchy's receiver scale lengthens
the error bars where the data see least (8 calibrators, actual / predicted 1.15 ->
1.12); a fixed scale for it (1, 10, 100 or 3000 K) moves the figures with a number
nobody measured; the widths marginalised rather than taken at their mode
(:func:`log_occam`) stop the smooth functions winning runs of exact quadratics 6-10 nats
below the best polynomial (the issue's case, RMS over runs 1.106 -> 1.082). Refitting
the widths at each leading model or marginalising them by importance sampling moved none
of the figures, nor did marginalising the decay (8 calibrators, RMS over runs 1.165 and,
its posterior too, 1.161, against 1.166) or giving the smooth functions a decay per
parameter (1.165).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..core.errors import IllPosedError
from ..model.noise_waves import N_PARAMETERS
from ..model.polynomial_model import Orders, as_orders
from ..regression.conjugate import ScalePrior, models_log_evidence
from ..regression.normal_equations import NormalEquations
from ..regression.shrinkage import EvidenceGrid, ShrinkagePrior, log_scale_density
from .parameter_scales import (
    BEHIND_NATS,
    maximise,
    maximise_each,
    negative_hessian,
    variances,
    width_log_prior,
)

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ParameterScales:
    """Fitted widths: ``tau_k`` per parameter (K), the shared decay, the constants' sd."""

    tau_k: tuple[float, ...]
    decay: float
    constant_sd_k: float

    def variances(self, orders: Sequence[int]) -> FloatArray:
        """Prior variance of every coefficient of ``orders``, shape ``(1, P)``.

        One row: the shape of :meth:`ShrinkagePrior.variances` with a one-point grid, so
        the mixture of :mod:`calibration.choice.averaging` takes either.
        """
        log_tau = np.log(np.asarray(self.tau_k))[None, :]
        return variances(as_orders(orders), log_tau, self.decay, self.constant_sd_k)

    def log_evidences(
        self, normal: NormalEquations, models: Sequence[Orders], scale_prior: ScalePrior | None
    ) -> FloatArray:
        """Log evidence of each model under these widths (``-inf`` where ill-posed).

        The evidence of :func:`calibration.regression.conjugate.solve` (eq. 3.35, zero prior mean),
        without the posterior's covariance, batched by
        :func:`~calibration.regression.conjugate.models_log_evidence`.
        """
        return models_log_evidence(normal, models, self.variances, scale_prior)


def fit_scales(
    normal: NormalEquations, prior: ShrinkagePrior, scale_prior: ScalePrior | None,
    orders: Orders | None = None, start: ParameterScales | None = None,
) -> ParameterScales:
    """The ``tau_k`` and decay maximising the evidence of ``orders`` (module docstring).

    With ``prior.width_hyperprior_k`` set, the evidence times the widths' prior (their
    posterior mode) instead. ``orders`` defaults to the largest model. ``tau_k`` is
    searched in ``log`` between the prior's ``tau_min_k`` and ``tau_max_k`` (bounded
    quasi-Newton with the evidence's analytic gradient,
    :func:`calibration.choice.parameter_scales.evidence_gradient`) at every decay in one batched
    search (:func:`~calibration.choice.parameter_scales.maximise_each`),
    from ``start`` if given (and never ending below it), else from the shared scale
    that maximises the evidence at that decay
    (:class:`~calibration.regression.shrinkage.EvidenceGrid`,
    one batch). A parameter with one term in ``orders`` has no ``tau_k`` in its evidence
    (the gradient is zero there): it keeps the start's width. A decay whose best shared
    scale trails the best by more than :data:`~calibration.choice.parameter_scales.BEHIND_NATS`
    is skipped: scales per parameter raised a model's evidence over the shared scale by
    at most 6.5 nats where measured (that constant's note), and tests hold that no
    skipped decay, nor any start, leaves a better maximum behind.
    """
    orders = normal.max_orders if orders is None else orders
    bounds = (float(np.log(prior.tau_min_k)), float(np.log(prior.tau_max_k)))
    shared = EvidenceGrid(normal, prior, scale_prior).of([orders])[0]
    by_decay = shared.reshape(len(prior.decays), prior.n_scales)
    log_prior = width_log_prior(prior, orders)
    best: tuple[float, ParameterScales] | None = None
    if start is not None:
        value = start.log_evidences(normal, [orders], scale_prior)[0]
        if log_prior is not None:
            value += log_prior(np.log(np.asarray(start.tau_k))[None])[0][0]
        best = (float(value), start)
    kept = np.flatnonzero(np.max(by_decay, axis=1) >= np.max(by_decay) - BEHIND_NATS)
    starts = np.stack([
        np.log(np.asarray(start.tau_k)) if start is not None
        else np.full(N_PARAMETERS, np.log(prior.scales_k[int(np.argmax(by_decay[i]))]))
        for i in kept
    ])
    decays = [prior.decays[i] for i in kept]
    maxima = maximise_each(normal, orders, decays, prior, scale_prior, starts, bounds, log_prior)
    finite = [(i, m) for i, m in enumerate(maxima) if m is not None]
    if finite:  # the best polished alone: the batch's stopping rule is shared
        i, (x0, _) = max(finite, key=lambda item: item[1][1])
        polished = maximise(normal, orders, decays[i], prior, scale_prior, x0, bounds, log_prior)
        maxima[i] = polished or maxima[i]
    for decay, found in zip(decays, maxima, strict=True):
        if found is not None and (best is None or found[1] > best[0]):
            scales = tuple(float(t) for t in np.exp(found[0]))
            best = (found[1], ParameterScales(scales, decay, prior.constant_sd_k))
    if best is None or not np.isfinite(best[0]):
        raise IllPosedError(f"no prior scale gives the model {orders} a finite evidence")
    return best[1]


#: A width within this factor of the range's floor is on it (collapsed: the data see no
#: structure there), and says nothing of the scale of the structure they do see.
ON_FLOOR = 1.01


def width_scale(widths: ParameterScales, prior: ShrinkagePrior) -> float | None:
    """The half-Cauchy scale most likely to have given the widths off the floor (K).

    Maximises ``sum_k log p(tau_k | s)`` with ``p(tau | s) = 2 / (pi s (1 + (tau/s)^2))``:
    ``sum_k (tau_k^2 - s^2) / (tau_k^2 + s^2) = 0``, one root between the smallest and
    largest width (the geometric mean of two). ``None`` where every width is on the floor.
    """
    from scipy.optimize import brentq
    tau = np.asarray(widths.tau_k)
    tau = tau[tau > ON_FLOOR * prior.tau_min_k]
    if tau.size == 0:
        return None
    lo, hi = float(np.log(tau.min())), float(np.log(tau.max()))
    if lo == hi:
        return float(tau[0])

    def score(log_s: float) -> float:  # falls as s grows: positive at lo, negative at hi
        r2 = (tau / np.exp(log_s)) ** 2
        return float(np.sum((r2 - 1.0) / (r2 + 1.0)))

    return float(np.exp(brentq(score, lo, hi, xtol=1e-12)))


def fit_largest(
    normal: NormalEquations, prior: ShrinkagePrior, scale_prior: ScalePrior | None
) -> tuple[ParameterScales, ShrinkagePrior]:
    """The widths at the largest model and the prior later fits use (module docstring).

    With ``prior.width_scale_from_data`` (and no scale given), type-II maximum likelihood
    first; its widths set the half-Cauchy scale (:func:`width_scale`), and the widths are
    fitted again under that prior, as every later fit (the refit) is.
    """
    widths = fit_scales(normal, prior, scale_prior)
    if prior.width_hyperprior_k is not None or not prior.width_scale_from_data:
        return widths, prior
    scale = width_scale(widths, prior)
    if scale is None:
        return widths, prior
    prior = replace(prior, width_hyperprior_k=scale)
    return fit_scales(normal, prior, scale_prior), prior


#: Step in ``log tau`` of the central differences of the evidence's analytic gradient.
HESSIAN_STEP = 1e-3


def log_occam(
    normal: NormalEquations, orders: Orders, widths: ParameterScales,
    prior: ShrinkagePrior, scale_prior: ScalePrior | None,
) -> float:
    """What marginalising the fitted widths adds to ``orders``' log evidence (Laplace).

    The widths are a mode, not known: the evidence of a hypothesis is
    ``int Z(u) p(u) du`` over ``u = log tau_k`` of the ``d`` parameters with higher terms
    in ``orders``, under their prior ``p`` (``prior.width_hyperprior_k``, or uniform in
    ``log tau``). About the mode ``u*`` (Laplace's method; MacKay 1992,
    *Neural Comput.* 4, 415, the Occam factor of the hyperparameters)::

        log int Z p du  ~  log Z(u*) + log p(u*) + (d/2) log 2 pi - (1/2) log det(-H)

    with ``H`` the Hessian of ``log Z + log p`` at ``u*`` (central differences of the
    analytic gradient, :func:`~calibration.choice.parameter_scales.negative_hessian`). Returned:
    all but ``log Z(u*)``. Widths that many terms pin down pay more than widths a few
    terms leave loose, so a hypothesis is no longer favoured for fitting more of them:
    the smooth functions fit five widths to 35 higher terms, a polynomial of the issue's
    case five to ten. At most 0 (the marginal cannot exceed the best width's evidence);
    a direction the evidence leaves flat counts at the curvature of its prior alone.
    """
    structured = np.flatnonzero([n > 1 for n in orders])
    if structured.size == 0:
        return 0.0
    mode = np.log(np.asarray(widths.tau_k, dtype=float))
    hessian = negative_hessian(
        normal, orders, mode, widths.decay, prior, scale_prior,
        width_log_prior(prior, orders), structured, HESSIAN_STEP,
    )
    curvature = np.linalg.eigvalsh(hessian)
    flat = 1.0 / np.log(prior.tau_max_k / prior.tau_min_k) ** 2
    log_p = float(np.sum(log_scale_density(mode[structured], prior, prior.width_hyperprior_k)))
    occam = (
        log_p + 0.5 * structured.size * np.log(2.0 * np.pi)
        - 0.5 * float(np.sum(np.log(np.maximum(curvature, flat))))
    )
    return min(0.0, occam)
