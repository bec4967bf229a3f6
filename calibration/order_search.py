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

from .noise_waves import N_PARAMETERS
from .polynomial_model import Orders, as_orders


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


def search_orders_jointly(
    log_evidence: Callable[[Orders], float],
    min_orders: Sequence[int],
    max_orders: Sequence[int],
    starts: Iterable[Sequence[int]] = (),
    lookahead: int = 2,
) -> OrderSearchResult:
    """Maximise ``log_evidence`` by steepest ascent over single and paired moves.

    One climb from each of ``starts`` (the smallest model when none is given): the best
    single-parameter move of up to ``lookahead`` terms while one improves, else the best
    move of two parameters by one term each; it ends where neither improves. Every model
    evaluated is in the table, each scored by the same ``log_evidence``.
    """
    lo, hi = as_orders(min_orders), as_orders(max_orders)
    if any(a > b for a, b in zip(lo, hi, strict=True)):
        raise ValueError(f"min_orders {lo} exceed max_orders {hi}")
    table: dict[Orders, float] = {}

    def score(orders: Orders) -> float:
        if orders not in table:
            table[orders] = log_evidence(orders)
        return table[orders]

    for start in [as_orders(s) for s in starts] or [lo]:
        current: Orders = tuple(  # type: ignore[assignment]
            min(max(n, a), b) for n, a, b in zip(start, lo, hi, strict=True)
        )
        current_score = score(current)
        while True:  # single moves while they climb; paired ones before giving up
            best = max(_neighbours(current, lookahead, lo, hi), key=score, default=None)
            if best is None or score(best) <= current_score:
                best = max(_paired_moves(current, lo, hi), key=score, default=None)
            if best is None or score(best) <= current_score:
                break
            current, current_score = best, score(best)
    best_orders = max(table, key=table.__getitem__)
    return OrderSearchResult(best_orders, table[best_orders], table)


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
    if any(a > b for a, b in zip(lo, hi, strict=True)):
        raise ValueError(f"min_orders {lo} exceed max_orders {hi}")
    table: dict[Orders, float] = {}

    def score(orders: Orders) -> float:
        if orders not in table:
            table[orders] = log_evidence(orders)
        return table[orders]

    all_starts = [lo, hi] + [as_orders(s) for s in starts]
    for start in all_starts:
        current = tuple(min(max(n, a), b) for n, a, b in zip(start, lo, hi, strict=True))
        current_score = score(current)  # type: ignore[arg-type]
        while True:
            candidates = list(_neighbours(current, lookahead, lo, hi))  # type: ignore[arg-type]
            best = max(candidates, key=score, default=None)
            if best is None or score(best) <= current_score:
                break
            current, current_score = best, score(best)
    best_orders = max(table, key=table.__getitem__)
    return OrderSearchResult(best_orders, table[best_orders], table)
