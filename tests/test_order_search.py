"""The order search on synthetic evidence surfaces with known maxima."""

import itertools

import pytest

from calibration.choice.order_search import search_orders


def plateau_surface(orders):
    """A surface whose best model needs two steps in the first parameter at once.

    Moving the first order 1 -> 2 costs a little (an extra useless term), 2 -> 3 gains a
    lot: the thesis's T_cos = 2 x^2 + 190 case.
    """
    first = {1: 0.0, 2: -1.0, 3: 20.0, 4: 19.0, 5: 18.0, 6: 17.0}[orders[0]]
    rest = -sum((n - 2) ** 2 for n in orders[1:])
    return first + rest


def test_lookahead_escapes_plateau_from_the_smallest_model():
    stuck = search_orders(plateau_surface, (1,) * 5, (3,) * 5, lookahead=1)
    # With single steps from (1,...) the climb cannot pass order 2 of the first parameter;
    # the start at the largest model rescues it only because 3 is the maximum here.
    assert stuck.best[0] == 3
    found = search_orders(plateau_surface, (1,) * 5, (6,) * 5, lookahead=2)
    assert found.best == (3, 2, 2, 2, 2)
    assert found.log_evidence == pytest.approx(20.0)


def test_single_step_climb_from_small_model_stalls():
    # Without the extra start at the largest model and without lookahead the climb stalls,
    # which is the failure the search is built to avoid.
    from calibration.choice.order_search import _neighbours

    current = (1, 2, 2, 2, 2)
    neighbours = list(_neighbours(current, 1, (1,) * 5, (6,) * 5))
    assert max(plateau_surface(n) for n in neighbours) < plateau_surface(current)


def test_matches_exhaustive_search_on_a_rugged_surface():
    def surface(o):
        return (
            -((o[0] - 4) ** 2)
            - abs(o[1] - 2) * 3
            + (5 if o[2] == 5 else 0)
            - o[3]
            - (o[4] - 3) ** 2
        )

    best = max(itertools.product(range(1, 7), repeat=5), key=surface)
    result = search_orders(surface, (1,) * 5, (6,) * 5, lookahead=2)
    assert result.best == best
    assert len(result.table) < 6**5  # it did not just enumerate everything


def test_bad_limits_rejected():
    with pytest.raises(ValueError, match="exceed"):
        search_orders(plateau_surface, (3,) * 5, (2,) * 5)
