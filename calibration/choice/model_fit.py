"""Fit one polynomial model, or choose the orders by evidence, on built normal equations.

Shared by the thesis solver and the radiometric solver: they differ only in how they build
the :class:`~calibration.regression.normal_equations.NormalEquations` (likelihood) and in
their priors. With a fixed :class:`~calibration.regression.conjugate.CoefficientPrior`
(the thesis's), one model is chosen by a climb over orders; with a
:class:`~calibration.regression.conjugate.TermPrior` (term sizes known beforehand), every
model between the order limits is scored and averaged; with a
:class:`~calibration.regression.shrinkage.ShrinkagePrior` (the radiometric solver's
default), the prior's scales are set by the data, one per parameter
(:mod:`calibration.choice.scale_fit`: at the largest model, then refitted at the first
search's best for a second, each hypothesis weighed with its widths marginalised by
Laplace's method; or one shared scale, marginalised on a grid), the climb moves
parameters jointly from the clearly measured terms
(:func:`~calibration.choice.order_search.significant_orders`), scoring each step's models
in one batch (:meth:`ParameterScales.log_evidences
<calibration.choice.scale_fit.ParameterScales.log_evidences>`, or
:class:`~calibration.regression.shrinkage.EvidenceGrid`), and the posterior is the
evidence-weighted mixture of the models that carry the weight
(:mod:`calibration.choice.averaging`; with the smooth-function hypothesis
(:mod:`calibration.choice.hypotheses`), and under a shared scale also the smooth
functions under a scale per parameter marginalised,
:mod:`calibration.choice.parameter_scales`), or of the best model's prior scales alone.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..core.errors import IllPosedError
from ..model.polynomial_model import Orders, as_orders
from ..regression.conjugate import (
    CoefficientPrior,
    LinearPosterior,
    ScalePrior,
    TermPrior,
    models_log_evidence,
    solve,
)
from ..regression.normal_equations import NormalEquations
from ..regression.shrinkage import EvidenceGrid, ShrinkagePrior, marginal_log_evidence
from .averaging import (
    join_hypotheses,
    mixture_posterior,
    pool_log_evidence,
    select_components,
    smooth_prior_share,
    with_smooth_hypothesis,
)
from .hypotheses import hypotheses_with_own_widths
from .order_search import search_orders, search_orders_jointly, significant_orders
from .parameter_scales import BEHIND_NATS, draw_scales
from .scale_fit import ParameterScales, fit_largest, fit_scales, log_occam

Prior = CoefficientPrior | ShrinkagePrior


#: The search box of the default (automatic) choice: 8 terms a parameter, raised where
#: the data ask for more (:func:`~calibration.choice.model_size.fit_extending`).
DEFAULT_MAX_ORDERS: Orders = (8, 8, 8, 8, 8)


@dataclass(frozen=True)
class OrderChoice:
    """Fixed orders, or a search between ``min_orders`` and ``max_orders``.

    ``max_orders`` given is a limit, honoured: the search never goes beyond it (a
    parameter that ends at it is reported in ``orders_at_ceiling``). Left out (``None``),
    the box is automatic: it starts at :data:`DEFAULT_MAX_ORDERS`, and where the
    evidence-best model reaches its edge in some parameter, that parameter's limit is
    raised by ``extend_step`` and the search resumed, up to ``ceiling`` terms, only while
    the calibrators constrain the raised terms
    (:func:`~calibration.choice.model_size.fit_extending` states the rule).
    """

    orders: Orders | None = None
    min_orders: Orders = (1, 1, 1, 1, 1)
    max_orders: Orders | None = None
    lookahead: int = 2
    extend_step: int = 4
    ceiling: int = 16

    @classmethod
    def fixed(cls, orders: Sequence[int]) -> OrderChoice:
        """Use exactly these orders."""
        o = as_orders(orders)
        return cls(orders=o, min_orders=o, max_orders=o)

    @property
    def limits(self) -> Orders:
        """The search's upper limits: ``max_orders``, or the automatic box's start."""
        if self.max_orders is not None:
            return self.max_orders
        return self.orders if self.orders is not None else DEFAULT_MAX_ORDERS

    @property
    def grows(self) -> bool:
        """Whether the limits may be raised: only an automatic box (no ``max_orders``)."""
        return self.orders is None and self.max_orders is None and self.extend_step > 0

    @property
    def largest(self) -> Orders:
        """The largest model the normal equations must hold."""
        return self.orders if self.orders is not None else self.limits


def check_constrained(normal: NormalEquations, orders: Orders, rcond: float = 1e-13) -> None:
    """Raise :class:`IllPosedError` if the data alone leave a direction of ``orders`` free.

    The prior would still give a posterior, but it would be the prior's answer, not the
    data's: too few calibrators (or too little reflection variety) for these orders.
    """
    idx = normal.indices(orders)
    gram = normal.gram[np.ix_(idx, idx)]
    scale = np.sqrt(np.maximum(np.diag(gram), np.finfo(float).tiny))
    eig = np.linalg.eigvalsh(gram / np.outer(scale, scale))
    if eig[0] <= rcond * eig[-1]:
        raise IllPosedError(
            f"the calibrators do not constrain a model with orders {orders} "
            f"(Gram eigenvalue ratio {eig[0] / eig[-1]:.1e}): "
            "add calibrators or lower the orders"
        )


def fit(
    normal: NormalEquations,
    choice: OrderChoice,
    prior: Prior,
    prior_variance_scale: float,
    scale_prior: ScalePrior | None,
    allow_prior_dominated: bool = False,
    starts: Sequence[Orders] = (),
    average: bool = True,
    skipped: dict[Orders, str] | None = None,
    smooth: bool = True,
) -> tuple[LinearPosterior, dict[Orders, float]]:
    """Posterior of the chosen (or evidence-best) model and the evidence table.

    ``prior_variance_scale`` divides the kelvin prior variances into ``V_0`` units (the
    NIG prior's coefficient covariance is ``s^2 V_0``). Fixed orders that the data leave
    unconstrained raise :class:`IllPosedError` unless ``allow_prior_dominated``. With a
    :class:`ShrinkagePrior`, ``average`` mixes the models that carry the weight; without
    it, only the best model's prior scales; with a
    :class:`~calibration.regression.conjugate.TermPrior`,
    every model of the box is scored, all equally likely, and mixed (or the best kept).
    Models the search had to pass over (no
    finite evidence) are recorded in ``skipped`` with the reason, and do not stop it.
    ``smooth`` offers the averaged search the smooth-function hypothesis
    (:func:`~calibration.choice.averaging.with_smooth_hypothesis`) when the data constrain it.
    """
    make, table = _fit(
        normal, choice, prior, prior_variance_scale, scale_prior, allow_prior_dominated,
        starts, average, skipped, smooth,
    )
    return make(), table


#: The posterior of a finished search, computed only when asked for.
Deferred = Callable[[], LinearPosterior]


def _fit(
    normal: NormalEquations,
    choice: OrderChoice,
    prior: Prior,
    prior_variance_scale: float,
    scale_prior: ScalePrior | None,
    allow_prior_dominated: bool,
    starts: Sequence[Orders],
    average: bool,
    skipped: dict[Orders, str] | None,
    smooth: bool,
) -> tuple[Deferred, dict[Orders, float]]:
    """:func:`fit`, its posterior deferred: a search whose limits are then raised needs none."""
    skipped = {} if skipped is None else skipped
    if isinstance(prior, ShrinkagePrior):
        return _fit_shrinkage(
            normal, choice, prior, scale_prior, allow_prior_dominated, starts, average, skipped,
            smooth,
        )

    if isinstance(prior, TermPrior) and choice.orders is None:
        return _fit_every_model(
            normal, choice, prior, prior_variance_scale, scale_prior, average, skipped
        )

    def posterior(orders: Orders) -> LinearPosterior:
        mean, var = prior.vectors(orders)
        return solve(normal, orders, mean, var / prior_variance_scale, scale_prior)

    if choice.orders is not None:
        if not allow_prior_dominated:
            check_constrained(normal, choice.orders)
        post = posterior(choice.orders)
        return (lambda: post), {choice.orders: post.log_evidence}

    def log_evidence(orders: Orders) -> float:
        if not normal.admits(orders):
            return -np.inf
        try:
            return posterior(orders).log_evidence
        except IllPosedError as err:
            skipped[orders] = str(err)
            return -np.inf

    result = search_orders(
        log_evidence,
        choice.min_orders,
        choice.limits,
        starts=[
            s for s in starts if all(n <= m for n, m in zip(s, choice.limits, strict=True))
        ],
        lookahead=choice.lookahead,
    )
    if not np.isfinite(result.log_evidence):
        raise IllPosedError("no model between the order limits is constrained by the data")
    return (lambda: posterior(result.best)), result.table


#: The most models :func:`_fit_every_model` scores: the default search box, 8^5.
MAX_MODELS = 8**5


@dataclass(frozen=True)
class _FixedWidths:
    """A fixed prior's variances in ``V_0`` units, in the shape the mixture takes."""

    prior: CoefficientPrior
    variance_scale: float

    def variances(self, orders: Sequence[int]) -> np.ndarray:
        return self.prior.vectors(orders)[1][None, :] / self.variance_scale


def _fit_every_model(
    normal: NormalEquations,
    choice: OrderChoice,
    prior: TermPrior,
    variance_scale: float,
    scale_prior: ScalePrior | None,
    average: bool,
    skipped: dict[Orders, str],
) -> tuple[Deferred, dict[Orders, float]]:
    """Every model between the order limits scored, all equally likely, and averaged.

    The posterior is the evidence-weighted mixture (:mod:`calibration.choice.averaging`) of the
    models that carry the weight, or the best one alone without ``average``.
    """
    limits = zip(choice.min_orders, choice.limits, strict=True)
    models = [as_orders(m) for m in itertools.product(*(range(lo, hi + 1) for lo, hi in limits))]
    if len(models) > MAX_MODELS:
        raise ValueError(f"{len(models)} models between the order limits: at most {MAX_MODELS}")
    models = [m for m in models if normal.admits(m)]
    widths = _FixedWidths(prior, variance_scale)
    logs = models_log_evidence(normal, models, widths.variances, scale_prior)
    table = {m: float(z) for m, z in zip(models, logs, strict=True)}
    pool = {m: np.array([z]) for m, z in table.items() if np.isfinite(z)}
    reason = "the data and prior give it no finite evidence"
    skipped.update({m: reason for m in table if m not in pool})
    if not pool:
        raise IllPosedError("no model between the order limits is constrained by the data")
    best = max(pool, key=table.__getitem__)

    def posterior() -> LinearPosterior:
        if not average:
            variances = widths.variances(best)[0]
            return solve(normal, best, np.zeros_like(variances), variances, scale_prior)
        components = select_components(pool)
        return mixture_posterior(normal, components, widths, scale_prior, table[best])

    return posterior, table


#: The most refits of the widths in :func:`_fit_shrinkage`'s ``settle``: a run of four
#: calibrators with VNA noise 1e-3 (truth (1, 6, 3, 5, 3)) went (5, 4, 6, 3, 4),
#: (1, 3, 7, 4, 3), then the truth, a fixed point, on the third.
REFITS = 4


#: A climb whose end trails the box's top model by more than this has stalled (odds of
#: e^10 against it): it is resumed from the top. Closer, the two are within what the
#: widths' and operating point's choices move (a four-calibrator run: 0.07 nats, and
#: resuming there ended in another basin, 33x the floor off where the climb's end was
#: at 1.1x); the stall it is for was thousands of nats (``tests/test_model_choice.py``).
STALLED_NATS = 10.0


def _clipped(orders: Sequence[int], lo: Orders, hi: Orders) -> Orders:
    return as_orders([min(max(n, a), b) for n, a, b in zip(orders, lo, hi, strict=True)])


def _fit_shrinkage(
    normal: NormalEquations,
    choice: OrderChoice,
    prior: ShrinkagePrior,
    scale_prior: ScalePrior | None,
    allow_prior_dominated: bool,
    starts: Sequence[Orders],
    average: bool,
    skipped: dict[Orders, str],
    smooth: bool = True,
) -> tuple[Deferred, dict[Orders, float]]:
    """:func:`fit` with the prior scale marginalised (or fitted per parameter), averaged.

    With widths fitted per parameter (:func:`~calibration.choice.scale_fit.fit_largest`, whose
    prior, with its widths' scale set by the data, every later fit shares), the search
    runs twice: under the widths fitted at the largest model, then from its best
    under the widths refitted at that best; the second table is the one returned, and
    the smooth-function hypothesis keeps the first widths
    (:func:`~calibration.choice.hypotheses.hypotheses_with_own_widths`).

    Where the data identify only some models of the box (``normal.identified``,
    :class:`~calibration.regression.errors_in_variables.Identified`), the widths and the smooth
    hypothesis are fitted in the box they identify whole, the search scores only
    identified models, and the refit is repeated from several climbs' ends until each
    stays put, every search climbing from the diagonal too, the fixed point with the most
    evidence (its widths marginalised) kept: widths fitted in a box that lacks the terms
    the data want can favour a wrong model by 20 nats. Four calibrators with VNA noise
    1e-3 and a truth beyond that box (``tests/test_errors_in_variables.py``) calibrated
    33-56x the noise floor off in eight seeds of eight with the box alone; now the single
    best model is at 0.67-1.26x in eight of eight, the average at 0.73-4.7x with error
    bars wider than its error. Refitting from the best alone, or without the diagonal's
    climbs, left two or three of the eight at 9-48x.
    """
    grids: dict[Orders, np.ndarray] = {}
    widths: ShrinkagePrior | ParameterScales = prior
    smooth_widths: ParameterScales | None = None  # set where the polynomials' are refitted
    refitted_at: Orders = choice.limits  # ...at this model, their mode's
    # The largest box whose every model the data identify: the widths' and the smooth
    # hypothesis's model, and the climb's start (models beyond it are scored only where
    # identified, normal.admits).
    full = choice.limits if normal.identified is None else normal.identified.box
    inner = normal if normal.identified is None else normal.within(full)
    if prior.per_parameter:
        widths, prior = fit_largest(inner, prior, scale_prior)  # prior: with that scale

    batch = None if prior.per_parameter else EvidenceGrid(normal, prior, scale_prior)

    def log_evidences(models: Sequence[Orders]) -> list[float]:
        scored = [m for m in models if normal.admits(m)]
        rows: list[np.ndarray] = []
        if scored and batch is not None:  # the shared scale's grid, with its hyperprior mass
            rows = list(batch.of(scored) + prior.log_grid_weights[None, :])
        elif scored:
            assert isinstance(widths, ParameterScales)
            rows = list(widths.log_evidences(normal, scored, scale_prior)[:, None])
        found = dict(zip(scored, rows, strict=True))
        values = []
        for orders in models:
            if orders not in found:  # not identified above the reflections' errors
                values.append(-np.inf)
                continue
            row = found[orders]
            grids[orders] = np.asarray(row)
            values.append(marginal_log_evidence(grids[orders]))
            if not np.isfinite(values[-1]):
                skipped[orders] = "the data and prior give it no finite evidence at any prior scale"
        return values

    def log_evidence(orders: Orders) -> float:
        return log_evidences([orders])[0]

    def search(starts: Sequence[Orders]) -> tuple[Orders, dict[Orders, float]]:
        lo, hi = choice.min_orders, choice.limits  # a raised limit starts at the last best
        inside = [s for s in starts if all(n <= m for n, m in zip(s, hi, strict=True))]
        inside = inside or [significant_orders(inner, prior, lo, full)]
        result = search_orders_jointly(
            log_evidence, lo, hi, starts=inside, lookahead=choice.lookahead, many=log_evidences,
        )
        if log_evidence(full) > result.log_evidence + STALLED_NATS:  # resumed from the top
            result = search_orders_jointly(
                log_evidence, lo, hi, starts=[result.best, full], lookahead=choice.lookahead,
                many=log_evidences,
            )
        return result.best, {m: z for m, z in result.table.items() if normal.admits(m)}

    def settle(
        start: Orders, first: ParameterScales, spread: Sequence[Orders]
    ) -> tuple[float, ParameterScales, Orders]:
        """Widths refitted at the best and the climbs resumed, until the best stays (REFITS).

        Each search climbs from the best and from every model of ``spread``.

        Returns the fixed point's log evidence with its widths marginalised
        (:func:`~calibration.choice.scale_fit.log_occam`), its widths and its orders.
        """
        nonlocal widths
        at = start
        for _ in range(REFITS):
            widths = fit_scales(normal, prior, scale_prior, orders=at, start=first)
            moved, _ = search([at, *spread])
            if moved == at:
                break
            at = moved
        else:
            widths = fit_scales(normal, prior, scale_prior, orders=at, start=first)
        score = log_evidence(at) + log_occam(normal, at, widths, prior, scale_prior)
        return score, widths, at

    if choice.orders is not None:
        if not allow_prior_dominated:
            check_constrained(normal, choice.orders)
        best = choice.orders
        table = {best: log_evidence(best)}
    else:
        best, table = search(starts)
        refit = isinstance(widths, ParameterScales) and max(best) > 1 and np.isfinite(table[best])
        if refit and normal.identified is not None:
            # Beyond the cut box the evidence has several hills, and the widths fitted
            # within it may favour the wrong one: the climbs' ends from the diagonal
            # (n, n, n, n, n) are each settled, every search climbing from the diagonal
            # too, and the best fixed point kept.
            assert isinstance(widths, ParameterScales)
            smooth_widths = first = widths
            lo, hi = choice.min_orders, choice.limits
            spread = [_clipped((n,) * len(lo), lo, hi) for n in range(1, max(hi) + 1)]
            ends = {best} | {search([start])[0] for start in spread}
            settled = [settle(end, first, spread) for end in sorted(ends) if max(end) > 1]
            _, widths, refitted_at = max(settled, key=lambda fixed: fixed[0])
            grids.clear()
            skipped.clear()
            best, table = search([refitted_at, *spread])
        elif refit:  # refitted at the best, and the search run again from there
            assert isinstance(widths, ParameterScales)
            smooth_widths, refitted_at = widths, best
            widths = fit_scales(normal, prior, scale_prior, orders=best, start=widths)
            grids.clear()
            skipped.clear()
            best, table = search([best])
    if not np.isfinite(table[best]):
        raise IllPosedError("no model between the order limits is constrained by the data")

    def posterior() -> LinearPosterior:
        pool: dict[Orders, np.ndarray] = dict(grids) if average else {best: grids[best]}
        # The smooth-function hypothesis (averaging.with_smooth_hypothesis), offered only
        # where the data alone constrain every term of it, as fixed orders must be.
        offered = smooth and average and choice.orders is None and _constrained(normal, full)
        if offered:
            if full not in grids:  # scored for the mixture; the search's table keeps its own
                log_evidence(full)
            box = int(np.prod([hi - lo + 1 for lo, hi in zip(
                choice.min_orders, full, strict=True)]))
            if smooth_widths is not None:
                assert isinstance(widths, ParameterScales)
                occam = (  # each about its widths' mode: where they were fitted
                    log_occam(normal, refitted_at, widths, prior, scale_prior),
                    log_occam(normal, full, smooth_widths, prior, scale_prior),
                )
                return hypotheses_with_own_widths(
                    normal, grids, full, box, (widths, smooth_widths), scale_prior, table[best],
                    occam,
                )
            pool = with_smooth_hypothesis(grids, full, box)
        components = select_components(pool)
        mixture = mixture_posterior(normal, components, widths, scale_prior, table[best])
        if not (offered and prior.scale_per_parameter and isinstance(widths, ShrinkagePrior)):
            return mixture
        marginals = {m: marginal_log_evidence(g) for m, g in pool.items()}
        if marginals[full] < max(marginals.values()) - BEHIND_NATS:
            return mixture
        # A third hypothesis: smooth functions with a scale per parameter (marginalised),
        # at the smooth hypothesis's prior share, against the shared scale at even odds.
        draws = draw_scales(
            normal, full, prior, scale_prior, grids[full],
            float(np.log(smooth_prior_share(box))),
        )
        if draws is None:
            return mixture
        return join_hypotheses(
            mixture, pool_log_evidence(pool), draws.posteriors, draws.log_weights
        )

    return posterior, table


def _constrained(normal: NormalEquations, orders: Orders) -> bool:
    try:
        check_constrained(normal, orders)
    except IllPosedError:
        return False
    return True
