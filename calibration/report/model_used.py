"""What a solution's printers say about its model: the model used, its weight, its warnings.

A model-averaged solution (:mod:`calibration.choice.averaging`) is a mixture; the model that
carries it is its heaviest component (``metadata["orders_used"]``,
:attr:`Solution.orders_used <calibration.solve.solution.Solution.orders_used>`), which need not
be the evidence-best single model (``best_orders``): the smooth-function hypothesis, every
term to the box's edge, enters with its own prior and can hold 0.997 of the weight while a
smaller polynomial has the highest evidence. Every command and figure that names a model
names the one used, through :func:`model_used_line`; the evidence-best is mentioned only
where it differs.

The solvers' warning sentences (``metadata["warnings"]``: noise scale far from 1, orders
at their limit, an unconverged fit, structure left beyond the box) are printed by every
command through :func:`warning_lines`, from files of any age (absent: none, except the
order ceiling, recorded since the search had one).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from ..solve.solution import Solution

__all__ = [
    "distance_line",
    "leading_models",
    "model_used_line",
    "orders_text",
    "orders_used_weight",
    "warning_lines",
]


def orders_text(orders: Sequence[int]) -> str:
    """Orders as ``16,12,12,8,8``."""
    return ",".join(map(str, orders))


def leading_models(solution: Solution, limit: int = 4) -> list[tuple[tuple[int, ...], float]]:
    """The heaviest models of the average with their weights, heaviest first (empty if none)."""
    weights = solution.metadata.get("model_weights") or []
    ranked = sorted(
        ((tuple(int(n) for n in w["orders"]), float(w["weight"])) for w in weights),
        key=lambda item: -item[1],
    )
    return ranked[:limit]


def orders_used_weight(solution: Solution) -> float:
    """The weight of the model used in the average (1 for a single model)."""
    weight = solution.metadata.get("orders_used_weight")
    if weight is not None:
        return float(weight)
    if solution.metadata.get("averaged"):
        for orders, w in leading_models(solution, limit=1_000):
            if orders == solution.orders_used:
                return w
    return 1.0


def model_used_line(solution: Solution) -> str:
    """The model used: ``16,12,12,8,8 (weight 0.997 in the average over 65 models; 56 ...)``.

    The size is the leading model's coefficient count, with the average's weighted mean
    (``metadata["mean_coefficients"]``) and effective count (``effective_coefficients``)
    where recorded and different. Where the evidence-best single model is another, the
    line says it is not the one used.
    """
    meta = solution.metadata
    used = solution.orders_used
    n_models = len(solution.evidence_table)
    delays = tuple(getattr(solution.basis, "delays_s", ()))
    if delays:
        return _delay_line(solution, used, delays)
    size = f"{sum(used)} coefficients"
    mean = meta.get("mean_coefficients")
    if mean is not None and abs(float(mean) - sum(used)) >= 0.05:
        size += f", weighted mean {float(mean):.1f}"
    effective = meta.get("effective_coefficients")
    if effective is not None:
        size += f", effective {float(effective):.1f}"
    if meta.get("averaged") and n_models > 1:
        how = f"weight {orders_used_weight(solution):.3f} in the average over {n_models} models"
    elif n_models > 1:
        how = f"best of {n_models} by evidence"
    else:
        how = "fixed"
    text = f"{orders_text(used)} ({how}; {size})"
    if n_models > 1 and solution.best_orders != used:
        text += (
            f"; the evidence-best single model {orders_text(solution.best_orders)} "
            "carries less weight"
        )
    return text


def _delay_line(solution: Solution, used: tuple[int, ...], delays: tuple[float, ...]) -> str:
    """A model of polynomials and delay terms, fitted after the search (``delay_terms``)."""
    k = int(getattr(solution.basis, "polynomial_terms", 0))
    listed = ", ".join(f"{d * 1e9:.1f}" for d in delays)
    parts = [
        f"{min(n, k)}" + (f"+{n - k}" if n > k else "") for n in used
    ]
    return (
        f"{','.join(parts)} (polynomial terms + cos/sin terms at delays {listed} ns, "
        f"fitted after the search of {len(solution.evidence_table)} polynomial models; "
        f"{sum(used)} coefficients)"
    )


def _sentences(metadata: Mapping[str, Any]) -> list[str]:
    sentences = [str(s) for s in metadata.get("warnings") or []]
    ceiling = metadata.get("orders_at_ceiling") or []
    if ceiling and not any("limit" in s or "ceiling" in s for s in sentences):
        sentences.append(
            f"{', '.join(map(str, ceiling))} ended at the order limit "
            f"{metadata.get('order_limits')}: the data may want more terms than the model "
            "holds; its error bars miss that part (raise --max-orders, up to 16)"
        )
    return list(dict.fromkeys(sentences))


def warning_lines(metadata: Mapping[str, Any]) -> list[str]:
    """Every warning sentence of a solution's metadata, once each, as ``warning: ...``."""
    return [f"warning: {s}" for s in _sentences(metadata)]


def distance_line(predicted: float, floor: float, actual: float | None) -> str:
    """The distance to the noise floor, predicted and (where the truth is known) actual.

    Without a truth the distance is the predicted error's: it holds only if the model is
    right (a model that misses structure predicts an error near the floor and makes one
    many times it), so the line says so.
    """
    text = f"distance to floor: predicted {predicted / floor:.3f}"
    if actual is not None:
        return f"{text}, actual {actual / floor:.3f} (error vs the simulation's truth)"
    return (
        f"{text} (the predicted error's: it holds only if the model is right; "
        "`reach-cal validate RUN --leave-one-out` tests that)"
    )
