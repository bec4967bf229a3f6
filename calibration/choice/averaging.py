"""Bayesian model averaging: the posterior as a mixture over orders and prior scales.

Choosing one model and reporting its posterior ignores that the choice itself is
uncertain: a term the evidence only half wants is either in, with its full variance, or
out, with its bias and no variance for it. The posterior predictive that accounts for
the choice is the evidence-weighted mixture (Hoeting et al. 1999, *Statist. Sci.* 14,
382, eq. 1)::

    p(c | D) = sum_m  p(c | D, m) Z_m / sum_m' Z_m'

over the models ``m`` that carry the weight: here a model is a pair (orders, prior scale
``tau`` of :mod:`calibration.regression.shrinkage`), each with a conjugate posterior of its own. The
components live in coefficient spaces of different sizes; each is embedded in the
envelope of all their orders (absent terms are exactly zero), where the mixture has

    mean = sum_m w_m mu_m,     cov = sum_m w_m (Sigma_m + mu_m mu_m^T) - mean mean^T

(the law of total variance), so everything downstream of a posterior (calibrated spectra,
their errors, the parameters at any frequency) sees the model-choice uncertainty.
:meth:`MixturePosterior.sample` draws from the mixture itself.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..model.polynomial_model import Orders, full_indices
from ..regression.conjugate import LinearPosterior, ScalePrior, solve_many
from ..regression.normal_equations import NormalEquations

FloatArray = NDArray[np.float64]

#: The mixture keeps the heaviest components up to this share of the total weight...
MASS = 0.999
#: ...and at most this many.
MAX_COMPONENTS = 64
def smooth_prior_share(n_models: int) -> float:
    """Prior probability of the smooth-function hypothesis beside ``n_models`` polynomials.

    ``1 / (n_models + 1)``: the smooth functions are one more candidate, as likely as each
    order combination of the box. At even odds with the whole polynomial family (the
    earlier default) the family's prior was spread over ``8^5`` order combinations, a
    charge of ``log 8^5 = 10.4`` nats that the smooth functions did not pay, although their
    fitted decay does the same job (a decay of 0.1 leaves a polynomial of two or three
    terms in effect). They then took 0.997-0.998 of the weight on receivers whose noise
    waves are exact quadratics at 2-6 sigma, 1.6 nats below the best polynomial's
    evidence (``benchmarks/polynomial_truths.py``), and shrank the real quadratic terms;
    on EDGES B18 and EDGES-3 the average sat on the box's edge. Given the prior of one
    model, they win where the data want every term (smooth truths, docs/results.md's
    "Model choice"), by the evidence alone. The price: on truths of many weak terms
    (tests/test_model_choice.py's ensemble) the average's 68 % intervals cover 62.9 %
    where even odds covered 64.8 % (63.3 % at odds of one to ``sqrt(n_models)``, which
    gave the smooth functions 0.72 of the weight on the weak quadratics again).
    """
    return 1.0 / (n_models + 1.0)


@dataclass(frozen=True)
class MixturePosterior(LinearPosterior):
    """A :class:`LinearPosterior` whose moments are those of a mixture (module docstring).

    ``orders`` is the envelope of the components' orders; ``components`` hold each
    component's own posterior (in its own orders) and ``weights`` their normalised weights.
    """

    components: tuple[LinearPosterior, ...] = ()
    weights: FloatArray = field(default_factory=lambda: np.zeros(0))

    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """``n`` draws from the mixture, shape ``(n, P)`` in the envelope's layout."""
        which = rng.choice(len(self.components), size=n, p=self.weights)
        out = np.zeros((n, self.mean.size))
        for m, component in enumerate(self.components):
            rows = np.flatnonzero(which == m)
            if rows.size:
                idx = full_indices(component.orders, self.orders)
                out[np.ix_(rows, idx)] = component.sample(rows.size, rng)
        return out

    def model_weights(self) -> dict[Orders, float]:
        """The weight of each set of orders (summed over the prior scales)."""
        totals: dict[Orders, float] = {}
        for component, weight in zip(self.components, self.weights, strict=True):
            totals[component.orders] = totals.get(component.orders, 0.0) + float(weight)
        return dict(sorted(totals.items(), key=lambda item: -item[1]))


def with_smooth_hypothesis(
    grids: Mapping[Orders, FloatArray],
    full: Orders,
    n_models: int,
    smooth_share: float | None = None,
) -> dict[Orders, FloatArray]:
    """The evaluated models' log evidence grids plus the log of their prior probability.

    Two hypotheses about the receiver, at odds ``smooth_share : 1 - smooth_share`` (by
    default :func:`smooth_prior_share`: the smooth functions as likely as one polynomial
    model):

    * **polynomials**: each parameter is a polynomial of some order, every combination of
      orders in the search box (``n_models`` of them) equally likely;
    * **smooth functions**: every parameter has every term up to the box's edge (``full``),
      none exactly zero, held in by the hierarchical prior's decay (an analytic
      function's Legendre coefficients fall geometrically but do not stop).

    (Under one shared prior scale, a third, smooth functions with a prior scale per
    parameter, joins these two in :func:`calibration.choice.model_fit.fit` through
    :func:`join_hypotheses`.)

    The first is what the order search explores; alone it charges a term the data only
    half see an Occam factor that drops it, and the bias it leaves is outside the error
    bars (measured: 57/84 % coverage of 68/95 % intervals where a third of the terms sit
    below 2 sigma). The second keeps every term, shrunk, with its variance. The data weigh
    the two through the evidence: a receiver whose higher terms are exactly zero favours
    the polynomials by tens of nats (the REACH-like simulation: 30 nats, the order choice
    unchanged), one with many weak terms the smooth functions by a few.
    ``p(m) = (1 - s) / n_models`` for every model of the box and ``s`` more for ``full``.
    """
    s = smooth_prior_share(n_models) if smooth_share is None else smooth_share
    polynomial = np.log1p(-s) - np.log(n_models)
    out = {m: np.asarray(grid, dtype=float) + polynomial for m, grid in grids.items()}
    if full in out:
        out[full] = np.asarray(grids[full], dtype=float) + np.logaddexp(
            polynomial, np.log(s)
        )
    return out


def select_components(
    grids: Mapping[Orders, FloatArray], mass: float = MASS, limit: int = MAX_COMPONENTS
) -> list[tuple[Orders, int, float]]:
    """The (orders, scale index, weight) that carry ``mass`` of the total evidence.

    ``grids`` maps each evaluated model to its log evidence at every prior scale; the
    weights are renormalised over the components kept.
    """
    models = list(grids)
    logs = np.stack([grids[m] for m in models])  # (models, scales)
    finite = np.isfinite(logs)
    if not finite.any():
        raise ValueError("no model has a finite evidence")
    weights = np.where(finite, np.exp(logs - logs[finite].max()), 0.0).ravel()
    weights /= weights.sum()
    order = np.argsort(-weights)[:limit]
    kept = order[: int(np.searchsorted(np.cumsum(weights[order]), mass)) + 1]
    total = float(weights[kept].sum())
    n_scales = logs.shape[1]
    return [
        (models[i // n_scales], int(i % n_scales), float(weights[i] / total)) for i in kept
    ]


class GridPrior(Protocol):
    """A coefficient prior given on a grid of widths: ``variances(orders)`` is ``(G, P)``."""

    def variances(self, orders: Sequence[int]) -> FloatArray:
        """Prior variance of every coefficient of ``orders`` at every grid point."""
        ...


def mixture_posterior(
    normal: NormalEquations,
    components: Sequence[tuple[Orders, int, float]],
    prior: GridPrior,
    scale_prior: ScalePrior | None,
    log_evidence: float,
) -> MixturePosterior:
    """The mixture of the components' conjugate posteriors (module docstring)."""
    by_model: dict[Orders, list[int]] = {}
    for i, (orders, _, _) in enumerate(components):
        by_model.setdefault(orders, []).append(i)
    solved: dict[int, LinearPosterior] = {}
    for orders, members in by_model.items():  # one stacked solve per model
        variances = prior.variances(orders)[[components[i][1] for i in members]]
        posts = solve_many(normal, orders, np.zeros_like(variances), variances, scale_prior)
        solved.update(zip(members, posts, strict=True))
    posteriors = [solved[i] for i in range(len(components))]
    weights = np.array([w for _, _, w in components])
    return mixture_of(posteriors, weights, log_evidence, normal.n_rows)


def pool_log_evidence(grids: Mapping[Orders, FloatArray]) -> float:
    """The total log evidence of a pool: every model and grid point, their priors included.

    The grid points are equally likely
    (:func:`calibration.regression.shrinkage.marginal_log_evidence`).
    """
    logs = np.concatenate([np.ravel(g) for g in grids.values()])
    size = next(iter(grids.values())).size
    top = float(np.max(logs))
    return top + float(np.log(np.sum(np.exp(logs - top)))) - float(np.log(size))


def join_hypotheses(
    mixture: MixturePosterior,
    log_z_mixture: float,
    others: Sequence[LinearPosterior],
    other_log_weights: FloatArray,
) -> MixturePosterior:
    """``mixture`` and weighted further components, at even prior odds between the two.

    ``log_z_mixture`` is the total log evidence behind ``mixture`` (:func:`pool_log_evidence`)
    and ``other_log_weights`` the components' log evidence shares, summing (by
    ``logsumexp``) to theirs. The further components that carry :data:`MASS` of their own
    weight are kept, at most :data:`MAX_COMPONENTS`.
    """
    log_w = np.asarray(other_log_weights, dtype=float)
    # Which further components carry MASS of their own weight, from their own largest: a
    # hypothesis hundreds of nats behind the mixture would underflow to 0 / 0 against it.
    own = np.exp(log_w - np.max(log_w))
    order = np.argsort(-own)
    cumulative = np.cumsum(own[order]) / np.sum(own)
    kept = order[: int(np.searchsorted(cumulative, MASS)) + 1][:MAX_COMPONENTS]
    top = max(float(np.max(log_w)), log_z_mixture)
    w_other = np.exp(log_w[kept] - top)
    kept, w_other = kept[w_other > 0], w_other[w_other > 0]  # none that weigh nothing
    weights = np.concatenate([mixture.weights * np.exp(log_z_mixture - top), w_other])
    return mixture_of(
        [*mixture.components, *(others[i] for i in kept)],
        weights / weights.sum(),
        mixture.log_evidence,
        mixture.n_rows,
    )


def mixture_of(
    posteriors: Sequence[LinearPosterior], w: FloatArray, log_evidence: float, n_rows: int
) -> MixturePosterior:
    """The mixture of ``posteriors`` with normalised weights ``w``: its moments in the envelope."""
    envelope: Orders = tuple(  # type: ignore[assignment]
        max(p.orders[k] for p in posteriors) for k in range(len(posteriors[0].orders))
    )
    size = sum(envelope)
    embedded = np.zeros((len(posteriors), size))
    for m, post in enumerate(posteriors):
        embedded[m, full_indices(post.orders, envelope)] = post.mean
    mean = w @ embedded
    # About the mixture's mean, not as E[c c^T] - mean mean^T: the levels (about 1000 K)
    # would cancel to a relative 1e-16 of their square, as large as a well-measured
    # coefficient's variance, and leave the covariance indefinite.
    spread = embedded - mean
    covariance = (spread * w[:, None]).T @ spread
    for post, weight in zip(posteriors, w, strict=True):
        idx = full_indices(post.orders, envelope)
        covariance[np.ix_(idx, idx)] += weight * post.covariance
    covariance = 0.5 * (covariance + covariance.T)
    dof = min(p.dof for p in posteriors)
    scale = covariance if np.isinf(dof) else covariance * (dof - 2.0) / dof
    return MixturePosterior(
        orders=envelope,
        mean=mean,
        scale=scale,
        dof=dof,
        log_evidence=log_evidence,
        noise_variance=float(w @ [p.noise_variance for p in posteriors]),
        chi2=float(w @ [p.chi2 for p in posteriors]),
        n_rows=n_rows,
        components=tuple(posteriors),
        weights=w,
    )
