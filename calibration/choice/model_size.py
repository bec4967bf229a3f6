"""The order box the data support, and the model a solution actually used.

**The box** (:func:`fit_extending`). Limits given by the user (``OrderChoice.max_orders``,
``--max-orders``) are honoured: the search never goes beyond them. The automatic box
starts at 8 terms a parameter; a parameter's limit is raised by ``extend_step`` (4), to at
most ``ceiling`` (16), where the evidence-best model reaches it and the calibrators
identify the raised box (``build`` cuts what they do not). The docs say: *"--max-orders
is a hard limit. Without it the box starts at 8 terms a parameter and a parameter's limit
is raised by 4, up to 16, where the best model reaches it; a parameter still at its limit
is named in a warning."*

A further gate was measured and left out: raising a limit only where the largest fit
measures the parameter's top terms at 3 sigma (:func:`edge_measured`). On simulated runs
it never bound; on EDGES-3 it moved the box from ``T_unc`` to ``T_cos``/``T_sin`` and the
held-out short's error from 6.4 K to 54 K.

**The model used** (:func:`model_size_metadata`): the averaged posterior's leading model
and its weight, the weighted mean number of coefficients, and the effective number the
data determine (``sum_m w_m tr(I - V_0^-1 Cov_m)``, the hat matrix's trace), for the
solution's metadata, so that what is printed is the model used.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np

from ..model.noise_waves import PARAMETERS
from ..model.polynomial_model import Orders, as_orders, coefficient_slices
from ..regression.conjugate import CoefficientPrior, LinearPosterior, ScalePrior
from ..regression.normal_equations import NormalEquations
from ..regression.shrinkage import ShrinkagePrior
from .averaging import MixturePosterior
from .model_checks import fit_warnings
from .model_fit import OrderChoice, Prior, _fit

#: A parameter's limit is raised only where a term at its edge is this many posterior sd
#: from zero (the climb's start uses the same figure: ``order_search.START_SIGMAS``).
EDGE_SIGMAS = 3.0


def edge_measured(normal: NormalEquations, prior: Prior, limits: Orders) -> list[bool]:
    """For each parameter, whether the data measure its top two terms within ``limits``.

    In the largest model's fit under the prior's widest widths (the data decide), the
    parameter's term at its limit or the one below is :data:`EDGE_SIGMAS` posterior sd
    from zero. A parameter of one term counts as measured (its level always is).
    """
    if isinstance(prior, ShrinkagePrior):
        variances = prior.widest_variances(normal.max_orders)
    elif isinstance(prior, CoefficientPrior):
        variances = prior.vectors(normal.max_orders)[1]
    else:
        return [True] * len(limits)
    try:
        covariance = np.linalg.inv(normal.gram + np.diag(1.0 / variances))
    except np.linalg.LinAlgError:
        return [False] * len(limits)
    sd = np.sqrt(np.maximum(np.diag(covariance), np.finfo(float).tiny))
    z = np.abs(normal.reference) / sd
    out = []
    for k, part in enumerate(coefficient_slices(normal.max_orders)):
        n = min(limits[k], part.stop - part.start)
        top = z[part][max(n - 2, 1) : n]
        out.append(n <= 1 or bool(np.any(top >= EDGE_SIGMAS)))
    return out


def model_size_metadata(posterior: LinearPosterior) -> dict[str, object]:
    """The model the posterior is: leading orders, their weight, mean and effective size.

    ``orders_used``: the orders of the heaviest model (of a mixture; else the posterior's
    own), ``orders_used_weight`` its weight; ``mean_coefficients`` the weighted mean
    number of coefficients.
    """
    if isinstance(posterior, MixturePosterior) and posterior.components:
        weights = posterior.model_weights()
        lead, weight = next(iter(weights.items()))
        mean = sum(sum(o) * w for o, w in weights.items())
    else:
        lead, weight, mean = posterior.orders, 1.0, float(sum(posterior.orders))
    return {
        "orders_used": list(lead),
        "orders_used_weight": round(float(weight), 6),
        "mean_coefficients": round(float(mean), 3),
    }


@dataclass(frozen=True)
class FitResult:
    """A fit with its evidence table, the normal equations it used and the order limits."""

    posterior: LinearPosterior
    table: dict[Orders, float]
    normal: NormalEquations
    max_orders: Orders
    at_ceiling: tuple[str, ...]
    skipped: dict[Orders, str]
    #: Parameters whose limit the data wanted raised but do not measure at the edge.
    held: tuple[str, ...] = ()

    def limits_metadata(self, noise_is_scale: bool = True) -> dict[str, object]:
        """The order limits searched, the parameters left at the ceiling, models skipped.

        With the model used (:func:`model_size_metadata`), where the box was held
        below what the evidence asked for ``orders_held`` (:func:`fit_extending`), and
        ``warnings`` on the noise scale and the limits
        (:func:`~calibration.choice.model_checks.fit_warnings`). ``noise_is_scale`` False: the
        posterior's noise variance is the thesis solver's sigma^2 in K^2, not a scale on
        the radiometer equation, and is not judged against 1.
        """
        out: dict[str, object] = {
            "order_limits": list(self.max_orders),
            "orders_at_ceiling": list(self.at_ceiling),
            "skipped_models": [
                {"orders": list(o), "reason": r} for o, r in self.skipped.items()
            ],
            **model_size_metadata(self.posterior),
        }
        if self.held:
            out["orders_held"] = list(self.held)
        out["warnings"] = self.warnings(out, noise_is_scale)
        return out

    def warnings(
        self, metadata: dict[str, object] | None = None, noise_is_scale: bool = True
    ) -> list[str]:
        """Sentences on the noise scale and the limits (:func:`model_checks.fit_warnings`)."""
        meta = self.limits_metadata(noise_is_scale) if metadata is None else metadata
        model = "radiometric" if noise_is_scale else "homoscedastic"
        return fit_warnings(
            SimpleNamespace(posterior=self.posterior, metadata=meta, measurement_model=model)
        )


def fit_extending(
    build: Callable[[Orders], NormalEquations],
    choice: OrderChoice,
    prior: Prior,
    prior_variance_scale: float,
    scale_prior: ScalePrior | None,
    allow_prior_dominated: bool = False,
    average: bool = True,
    smooth: Callable[[], bool] = lambda: True,
) -> FitResult:
    """``model_fit.fit`` on ``build(limits)``, raising limits as the data ask.

    ``build`` makes the normal equations for given largest orders (the solvers' likelihood),
    or for smaller ones where the data identify no more (their ``max_orders``): a
    parameter cut so is not raised again. Only an automatic box grows
    (``choice.grows``), by the rule of the module docstring; given limits are honoured.
    With a :class:`ShrinkagePrior` the evidence table is that of the last normal
    equations alone, so that every entry is computed the same way. ``smooth()``, asked
    after each ``build``, says whether the smooth-function hypothesis may join.
    """
    largest = choice.largest
    table: dict[Orders, float] = {}
    best: tuple[Orders, ...] = ()
    capped: set[int] = set()  # parameters a build cut below what it was asked for
    while True:
        normal = build(largest)
        asked, largest = largest, normal.max_orders
        kept = normal.identified.box if normal.identified is not None else largest
        capped |= {k for k, (n, m) in enumerate(zip(kept, asked, strict=True)) if n < m}
        skipped: dict[Orders, str] = {}
        posterior, part = _fit(
            normal,
            replace(choice, max_orders=largest) if choice.orders is None else choice,
            prior,
            prior_variance_scale,
            scale_prior,
            allow_prior_dominated,
            starts=best,
            average=average,
            skipped=skipped,
            smooth=smooth(),  # asked after build(): it may depend on the new equations
        )
        if isinstance(prior, ShrinkagePrior):
            table = dict(part)
        else:
            table.update(part)
        chosen = max(part, key=part.__getitem__)
        best = (chosen,)
        hit = [
            k
            for k, (n, m) in enumerate(zip(chosen, largest, strict=True))
            if n == m and choice.orders is None
        ]
        grow = [
            k for k in hit
            if choice.grows and largest[k] < choice.ceiling and k not in capped
        ]
        held: list[int] = []  # by a gate such as edge_measured (module docstring): none
        if not grow:
            at_edge = tuple(PARAMETERS[k] for k in hit if k not in held)
            return FitResult(
                posterior(), table, normal, largest, at_edge, skipped,
                tuple(PARAMETERS[k] for k in held),
            )
        largest = as_orders(
            [
                min(m + choice.extend_step, choice.ceiling) if k in grow else m
                for k, m in enumerate(largest)
            ]
        )
