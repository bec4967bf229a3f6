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
    prior: CoefficientPrior,
    prior_variance_scale: float,
    scale_prior: ScalePrior | None,
    allow_prior_dominated: bool = False,
) -> tuple[LinearPosterior, dict[Orders, float]]:
    """Posterior of the chosen (or evidence-best) model and the evidence table.

    ``prior_variance_scale`` divides the kelvin prior variances into ``V_0`` units (the
    NIG prior's coefficient covariance is ``s^2 V_0``). Fixed orders that the data leave
    unconstrained raise :class:`IllPosedError` unless ``allow_prior_dominated``.
    """

    def posterior(orders: Orders) -> LinearPosterior:
        mean, var = prior.vectors(orders)
        return solve(normal, orders, mean, var / prior_variance_scale, scale_prior)

    if choice.orders is not None:
        if not allow_prior_dominated:
            check_constrained(normal, choice.orders)
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
