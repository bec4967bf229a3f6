"""Fit one polynomial model, or choose the orders by evidence, on built normal equations.

Shared by the thesis solver and the radiometric solver: they differ only in how they build
the :class:`~calibration.normal_equations.NormalEquations` (likelihood) and scale their
priors.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .conjugate import CoefficientPrior, LinearPosterior, ScalePrior, solve
from .errors import IllPosedError
from .normal_equations import NormalEquations
from .order_search import search_orders
from .polynomial_model import Orders, as_orders


@dataclass(frozen=True)
class OrderChoice:
    """Fixed orders, or a search between ``min_orders`` and ``max_orders``."""

    orders: Orders | None = None
    min_orders: Orders = (1, 1, 1, 1, 1)
    max_orders: Orders = (8, 8, 8, 8, 8)
    lookahead: int = 2

    @classmethod
    def fixed(cls, orders: Sequence[int]) -> OrderChoice:
        """Use exactly these orders."""
        o = as_orders(orders)
        return cls(orders=o, min_orders=o, max_orders=o)

    @property
    def largest(self) -> Orders:
        """The largest model the normal equations must hold."""
        return self.orders if self.orders is not None else self.max_orders


def fit(
    normal: NormalEquations,
    choice: OrderChoice,
    prior: CoefficientPrior,
    prior_variance_scale: float,
    scale_prior: ScalePrior | None,
) -> tuple[LinearPosterior, dict[Orders, float]]:
    """Posterior of the chosen (or evidence-best) model and the evidence table.

    ``prior_variance_scale`` divides the kelvin prior variances into ``V_0`` units (the
    NIG prior's coefficient covariance is ``s^2 V_0``).
    """

    def posterior(orders: Orders) -> LinearPosterior:
        mean, var = prior.vectors(orders)
        return solve(normal, orders, mean, var / prior_variance_scale, scale_prior)

    if choice.orders is not None:
        post = posterior(choice.orders)
        return post, {choice.orders: post.log_evidence}

    def log_evidence(orders: Orders) -> float:
        try:
            return posterior(orders).log_evidence
        except IllPosedError:
            return -np.inf

    result = search_orders(
        log_evidence, choice.min_orders, choice.max_orders, lookahead=choice.lookahead
    )
    if not np.isfinite(result.log_evidence):
        raise IllPosedError("no model between the order limits is constrained by the data")
    return posterior(result.best), result.table
