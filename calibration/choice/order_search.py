"""Choosing the polynomial orders of the five noise-wave parameters by evidence.

The thesis (section 4.2.3) climbs the evidence surface in ``n``-space by raising one order
at a time. That stalls where a single extra term does not help but two do: a parameter
whose odd terms vanish (``T_cos = 2 x^2 + 190`` in the thesis's own test) sits on a
plateau at two terms. Section 4.5 notes the refactor "to avoid getting trapped at local
minima"; this search does so by

* considering moves of up to ``lookahead`` terms up or down in each parameter,
* climbing from several starts (the smallest model, the largest model, and a given one),

and keeps every evaluated model's log evidence: the table behind an "Occam's cliff" plot.

That climb still moves one parameter at a time, and stalls where the evidence wants one
parameter up and another down together (it stopped at (2,3,3,3,3) with (3,3,3,2,3) better
and never evaluated). :func:`search_orders_jointly` (the radiometric solver's search) adds
every move of two parameters by one term each to the neighbourhood, so that it ends only
at a model no single or paired move improves.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ..model.noise_waves import N_PARAMETERS
from ..model.polynomial_model import Orders, as_orders, coefficient_slices
from ..regression.normal_equations import NormalEquations
from ..regression.shrinkage import ShrinkagePrior


@dataclass(frozen=True)
class OrderSearchResult:
    """The best orders, their log evidence, and every model evaluated on the way."""

    best: Orders
    log_evidence: float
    table: dict[Orders, float]


def _neighbours(
    orders: Orders, lookahead: int, lo: Sequence[int], hi: Sequence[int]
) -> Iterable[Orders]:
    for k in range(N_PARAMETERS):
        for step in range(-lookahead, lookahead + 1):
            n = orders[k] + step
            if step == 0 or not lo[k] <= n <= hi[k]:
                continue
            yield (*orders[:k], n, *orders[k + 1 :])  # type: ignore[misc]


def _paired_moves(orders: Orders, lo: Sequence[int], hi: Sequence[int]) -> Iterable[Orders]:
    """Every move of two parameters by one term each."""
    for k in range(N_PARAMETERS):
        for m in range(k + 1, N_PARAMETERS):
            for dk in (-1, 1):
                for dm in (-1, 1):
                    moved = list(orders)
                    moved[k] += dk
                    moved[m] += dm
                    if lo[k] <= moved[k] <= hi[k] and lo[m] <= moved[m] <= hi[m]:
                        yield tuple(moved)  # type: ignore[misc]


#: Scores many models in one call: one log evidence per model, in order.
ManyEvidences = Callable[[Sequence[Orders]], Sequence[float]]


def _climb(
    log_evidence: Callable[[Orders], float],
    lo: Orders,
    hi: Orders,
    starts: Sequence[Orders],
    moves: Sequence[Callable[[Orders], Iterable[Orders]]],
    many: ManyEvidences | None = None,
) -> OrderSearchResult:
    """Steepest ascent from each start: the best of the first kind of move that improves.

    ``moves`` are tried in turn at each step (cheap ones first); the climb ends where none
    improves. Every model evaluated is in the table, each scored by ``log_evidence``, or
    a step's new candidates all at once by ``many`` (the same values, batched).
    """
    if any(a > b for a, b in zip(lo, hi, strict=True)):
        raise ValueError(f"min_orders {lo} exceed max_orders {hi}")
    table: dict[Orders, float] = {}

    def score(orders: Orders) -> float:
        if orders not in table:
            table[orders] = log_evidence(orders)
        return table[orders]

    def candidates(found: Iterable[Orders]) -> list[Orders]:
        found = list(found)
        fresh = [o for o in dict.fromkeys(found) if o not in table]
        if many is not None and len(fresh) > 1:
            table.update(zip(fresh, (float(v) for v in np.asarray(many(fresh))), strict=True))
        return found

    for start in starts:
        current: Orders = tuple(  # type: ignore[assignment]
            min(max(n, a), b) for n, a, b in zip(start, lo, hi, strict=True)
        )
        current_score = score(current)
        while True:
            for move in moves:
                best = max(candidates(move(current)), key=score, default=None)
                if best is not None and score(best) > current_score:
                    break
            else:
                break
            current, current_score = best, score(best)
    best_orders = max(table, key=table.__getitem__)
    return OrderSearchResult(best_orders, table[best_orders], table)


def search_orders_jointly(
    log_evidence: Callable[[Orders], float],
    min_orders: Sequence[int],
    max_orders: Sequence[int],
    starts: Iterable[Sequence[int]] = (),
    lookahead: int = 2,
    many: ManyEvidences | None = None,
) -> OrderSearchResult:
    """Maximise ``log_evidence`` by steepest ascent over single and paired moves.

    One climb from each of ``starts`` (the smallest model when none is given): the best
    single-parameter move of up to ``lookahead`` terms while one improves, else the best
    move of two parameters by one term each; it ends where neither improves. ``many``,
    if given, scores each step's new candidates in one call (:func:`_climb`).
    """
    lo, hi = as_orders(min_orders), as_orders(max_orders)
    return _climb(
        log_evidence, lo, hi, [as_orders(s) for s in starts] or [lo],
        [lambda o: _neighbours(o, lookahead, lo, hi), lambda o: _paired_moves(o, lo, hi)],
        many,
    )


def search_orders(
    log_evidence: Callable[[Orders], float],
    min_orders: Sequence[int],
    max_orders: Sequence[int],
    starts: Iterable[Sequence[int]] = (),
    lookahead: int = 2,
) -> OrderSearchResult:
    """Maximise ``log_evidence`` over orders in ``[min_orders, max_orders]``.

    Steepest ascent with ``lookahead``-term moves from ``min_orders``, ``max_orders`` and
    any extra ``starts``. A model that cannot be solved should return ``-inf``.
    """
    lo, hi = as_orders(min_orders), as_orders(max_orders)
    return _climb(
        log_evidence, lo, hi, [lo, hi, *(as_orders(s) for s in starts)],
        [lambda o: _neighbours(o, lookahead, lo, hi)],
    )


#: A term this many posterior sd from zero in the largest model's fit starts the climb.
START_SIGMAS = 3.0


def significant_orders(
    normal: NormalEquations, prior: ShrinkagePrior, lo: Orders, hi: Orders,
    sigmas: float = START_SIGMAS,
) -> Orders:
    """Where the climb starts: each parameter up to its last clearly measured term.

    In the reference fit of the largest model (under the grid's widest prior, so the data
    decide), the last term of each parameter whose coefficient is ``sigmas`` marginal
    standard deviations from zero, clipped to ``[lo, hi]``. A term that clear is one the
    evidence keeps, so the climb starts near its end and mostly steps around it instead of
    walking up from the smallest model. Measured over the benchmark's ensembles
    (``benchmarks.model_choice``, 84 runs): the climb ended at the same model as from the
    smallest one in 74, a better one in 5 and a worse one in 5, with 63 evaluations on
    average instead of 88; on REACH-like truths 64 instead of 179, the same model in 12
    of 12. (At 2 sigma it started too high and ended worse in 25 of 84.)
    """
    ridge = 1.0 / prior.widest_variances(normal.max_orders)
    try:
        covariance = np.linalg.inv(normal.gram + np.diag(ridge))
    except np.linalg.LinAlgError:
        return lo
    z = np.abs(normal.reference) / np.sqrt(np.maximum(np.diag(covariance), np.finfo(float).tiny))
    orders = []
    for k, part in enumerate(coefficient_slices(normal.max_orders)):
        clear = np.flatnonzero(z[part][1:] > sigmas)
        n = 2 + int(clear[-1]) if clear.size else 1
        orders.append(min(max(n, lo[k]), hi[k]))
    return as_orders(orders)
