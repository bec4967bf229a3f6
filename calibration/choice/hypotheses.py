"""The two hypotheses of the default choice, each weighed under its own prior widths.

The polynomials of the order box (every model equally likely) and the smooth functions
(every term of the box under widths fitted at the largest model) are joined by
:func:`~calibration.choice.averaging.join_hypotheses` at the prior odds of one model of
the box (:func:`~calibration.choice.averaging.smooth_prior_share`).
"""

from __future__ import annotations

import numpy as np

from ..model.polynomial_model import Orders
from ..regression.conjugate import LinearPosterior, ScalePrior, solve
from ..regression.normal_equations import NormalEquations
from .averaging import (
    join_hypotheses,
    mixture_posterior,
    pool_log_evidence,
    select_components,
    smooth_prior_share,
)
from .scale_fit import ParameterScales


def hypotheses_with_own_widths(
    normal: NormalEquations,
    grids: dict[Orders, np.ndarray],
    full: Orders,
    n_models: int,
    widths: tuple[ParameterScales, ParameterScales],
    scale_prior: ScalePrior | None,
    log_evidence: float,
    occam: tuple[float, float] = (0.0, 0.0),
) -> LinearPosterior:
    """The two hypotheses of :func:`with_smooth_hypothesis`, each under its own widths.

    The polynomials under the widths refitted at their evidence-best model (the first of
    ``widths``; ``grids`` holds their evidences), every model of the box (``n_models``)
    equally likely; the smooth functions, ``full``, under the widths fitted at the largest
    model (the second), their own fit under that hypothesis. Prior
    odds :func:`~calibration.choice.averaging.smooth_prior_share` (that of one model of the box).
    ``occam`` is what
    marginalising each hypothesis's widths adds to its evidence
    (:func:`~calibration.choice.scale_fit.log_occam`, at the model where the polynomials' widths
    were refitted and at ``full``).

    Measured with and without it (``benchmarks/README.md``, "What the model-choice runs
    showed"): at the widths' modes alone the smooth functions, which fit their five
    widths to every term of the box, won runs of exact quadratics 6-10 nats below the
    best polynomial, and their decay shrank the real quadratic terms (the issue's case:
    median error / floor 1.002, RMS 1.106); with the widths marginalised, 0.907 and
    1.082.
    """
    polynomials = {
        m: np.asarray(g) - np.log(n_models) + occam[0] for m, g in grids.items()
    }
    mixture = mixture_posterior(
        normal, select_components(polynomials), widths[0], scale_prior, log_evidence
    )
    variances = widths[1].variances(full)[0]
    smooth = solve(normal, full, np.zeros_like(variances), variances, scale_prior)
    share = smooth_prior_share(n_models)
    odds = float(np.log(share / (1.0 - share)))
    return join_hypotheses(
        mixture, pool_log_evidence(polynomials), [smooth],
        np.array([smooth.log_evidence + odds + occam[1]]),
    )
