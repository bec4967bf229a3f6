"""Each parameter's own prior scale, set by the data (type-II maximum likelihood).

The hierarchical prior of :mod:`calibration.shrinkage` gives the higher Legendre terms of
all five parameters one scale ``tau``. When their structures differ in size (a T_NS with
a 30-sigma slope beside a T_cos whose terms sit at 2-5 sigma), the shared scale follows
the large one and charges the small parameter's terms an Occam factor of
``log(tau / posterior sd)`` sized for the large one: real terms of the small parameter
are dropped, and the bias they leave lies outside the error bars.

Here each parameter ``k`` has its own scale, with the decay ``rho`` shared::

    c_k0 ~ N(0, constant_sd^2),    c_kj ~ N(0, (tau_k rho^(j-1))^2)   (j >= 1)

and ``(tau_1..tau_5)`` maximise the evidence of one model, for each ``rho`` of the
prior's grid, the best ``rho`` kept (empirical Bayes: MacKay 1992, *Neural Comput.* 4,
415, "evidence approximation"; Tipping 2001 for one scale per group). Which model is
the question of each hypothesis of :mod:`calibration.averaging`:

* **smooth functions** (every term up to the box's edge): the largest model. It holds
  every term any candidate can use, so its evidence sees each parameter's whole
  structure; the orders are first searched under these widths.
* **polynomials**: the evidence-best model of that search. The widths are refitted
  there, from the first, for the parameters with higher terms in it (a parameter with
  one term has no ``tau_k`` in its evidence and keeps its width), and the orders
  searched again from that best under the new widths; the polynomials are averaged
  under them and the smooth functions under the first
  (:func:`calibration.model_fit._hypotheses_with_own_widths`).

This is the solver's default. Measured on the benchmark's ensembles, whose random terms
are drawn at 0.3-30 times the data's own posterior sd
(``python -m benchmarks.model_choice --runs 100 --seed 100``; median error / floor, RMS
over runs, actual / predicted error and 68/95 % coverage):

* against one marginalised shared scale on the same runs: 8 calibrators 1.063, 1.181,
  1.15, 64/94 % against 1.011, 1.142, 1.16, 64/92 %; the four EDGES loads 0.994, 1.110,
  1.08, 67/92 % against 1.036, 1.142, 1.24, 63/89 %; smooth truths 0.637, 0.656, 1.06,
  66/94 % against 0.682, 0.718, 1.15, 65/91 %; random truths with 12 calibrators 0.946,
  1.058, 1.01, 66/95 % against 0.965, 1.080, 1.07, 65/93 %; the REACH-like, weak-term and
  VNA-noise rows within 0.05.
* against the widths fitted at the largest model alone (the default before the refit):
  8 calibrators 1.090, 1.209, 1.11, 66/94 %; the four loads 1.047, 1.142, 1.09, 66/92 %;
  random truths with 12 calibrators 0.994, 1.105, 1.00, 66/95 %; the accuracy
  benchmark's median 0.98 (now 0.95). Those widths are tuned to the model with every
  term: where the data constrain least that model took most of the weight in the worst
  runs, and its extra terms added variance; the polynomials' own widths cut that.
  Refitting for both hypotheses (the smooth one under the polynomials' widths too) made
  the error bars short instead: 8 calibrators 1.018, 1.174, 1.19, 61/93 %.

(On the benchmark's earlier ensembles, whose terms were sized in the shared prior's
shrunk sd and mostly undetectable, fitted scales looked worse than the marginalised one
on the four loads; that comparison did not survive honest truths.) Charging the fitted
widths a Laplace Occam factor per parameter with structure (the largest model's Hessian
in ``log tau``) moved nothing (8 calibrators 1.11 -> 1.11).

A parameter whose structure the data cannot see gets, by type-II maximum likelihood, the
range's floor (1 mK): the evidence is flat below the data's reach and the Occam factor
keeps falling, so its higher terms then cost nothing and carry no variance (a test).
``ShrinkagePrior(width_hyperprior_k=s)`` takes instead the mode of each ``tau_k``'s
posterior in ``log tau_k`` under a half-Cauchy prior of scale ``s``, whose density in
``log tau`` grows as ``tau`` below ``s``: the mode sits where the evidence starts to fall,
a few posterior sd up, never on the floor (a boundary-avoiding prior: Chung et al. 2013,
*Psychometrika* 78, 685; the half-Cauchy for hierarchical scales: Gelman 2006, *Bayesian
Anal.* 1, 515). It is not the default: its scale then decides part of the answer, and the
scale the receiver's physics suggests did not measure better. On the benchmark (the same
runs; 8 calibrators, then the four loads: median, RMS, actual / predicted, 68/95 %):

* type-II (the default): 1.063, 1.181, 1.145, 64/94 %; 0.994, 1.110, 1.08, 67/92 %.
* ``s`` = 10 K, the size of the REACH-like simulation's first-order terms (1.5-25 K,
  :func:`calibration.simulate.default_truth_coefficients`): 1.073, 1.180, 1.100, 64/94 %;
  1.025, 1.122, 1.04, 68/94 %; the smooth truths' 68 % interval at 64.6 %: as many of the
  issue's bounds missed (six) as type-II.
* ``s`` = 1 K: 1.043, 1.179, 1.078, 66/95 %; 0.988, 1.105, 1.01, 69/94 %; every other
  ensemble within its bounds, two missed in all (RMS over runs, both). The benchmark's
  random terms are drawn at 0.3-30 posterior sd, mostly below 1 K: this scale fits the
  ensemble, not an argument from the receiver.
* ``s`` = 100 K and 3000 K: 1.096, 1.189, 1.127 and 1.095, 1.198, 1.117 (8 calibrators).
"""

from __future__ import annotations

from collections.abc import Sequence
from contextlib import suppress
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .conjugate import ScalePrior, stacked_log_evidence
from .errors import IllPosedError
from .noise_waves import N_PARAMETERS
from .normal_equations import NormalEquations
from .parameter_scales import (
    BEHIND_NATS,
    maximise,
    maximise_each,
    variances,
    width_log_prior,
)
from .polynomial_model import Orders, as_orders
from .shrinkage import EvidenceGrid, ShrinkagePrior

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
        the mixture of :mod:`calibration.averaging` takes either.
        """
        log_tau = np.log(np.asarray(self.tau_k))[None, :]
        return variances(as_orders(orders), log_tau, self.decay, self.constant_sd_k)

    def log_evidences(
        self, normal: NormalEquations, models: Sequence[Orders], scale_prior: ScalePrior | None
    ) -> FloatArray:
        """Log evidence of each model under these widths (``-inf`` where ill-posed).

        The evidence of :func:`calibration.conjugate.solve` (eq. 3.35, zero prior mean),
        without the posterior's covariance: models with the same number of coefficients
        share one stacked factorisation
        (:func:`~calibration.conjugate.stacked_log_evidence`).
        """
        out = np.full(len(models), -np.inf)
        groups: dict[int, list[int]] = {}
        for i, orders in enumerate(models):
            groups.setdefault(sum(orders), []).append(i)
        for members in groups.values():
            idx = np.stack([normal.indices(models[i]) for i in members])
            var = np.concatenate([self.variances(models[i]) for i in members])
            try:
                out[members] = stacked_log_evidence(normal, idx, var, scale_prior)
            except np.linalg.LinAlgError:  # one ill-posed model: score the group one by one
                for i, row, v in zip(members, idx, var, strict=True):
                    with suppress(np.linalg.LinAlgError):
                        out[i] = stacked_log_evidence(normal, row[None], v[None], scale_prior)[0]
        return out


def fit_scales(
    normal: NormalEquations, prior: ShrinkagePrior, scale_prior: ScalePrior | None,
    orders: Orders | None = None, start: ParameterScales | None = None,
) -> ParameterScales:
    """The ``tau_k`` and decay maximising the evidence of ``orders`` (module docstring).

    With ``prior.width_hyperprior_k`` set, the evidence times the widths' prior (their
    posterior mode) instead. ``orders`` defaults to the largest model. ``tau_k`` is
    searched in ``log`` between the prior's ``tau_min_k`` and ``tau_max_k`` (bounded
    quasi-Newton with the evidence's analytic gradient,
    :func:`calibration.parameter_scales.evidence_gradient`) at every decay in one batched
    search (:func:`~calibration.parameter_scales.maximise_each`),
    from ``start`` if given (and never ending below it), else from the shared scale
    that maximises the evidence at that decay (:class:`~calibration.shrinkage.EvidenceGrid`,
    one batch). A parameter with one term in ``orders`` has no ``tau_k`` in its evidence
    (the gradient is zero there): it keeps the start's width. A decay whose best shared
    scale trails the best by more than :data:`~calibration.parameter_scales.BEHIND_NATS`
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
