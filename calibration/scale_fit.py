"""Each parameter's own prior scale, set by the data (type-II maximum likelihood).

The hierarchical prior of :mod:`calibration.shrinkage` gives the higher Legendre terms of
all five parameters one scale ``tau``. When their structures differ in size (a T_NS with
a 30-sigma slope beside a T_cos whose terms sit at 2-5 sigma), the shared scale follows
the large one and charges the small parameter's terms an Occam factor of
``log(tau / posterior sd)`` sized for the large one: real terms of the small parameter
are dropped, and the bias they leave lies outside the error bars.

Here each parameter ``k`` has its own scale, with the decay ``rho`` shared::

    c_k0 ~ N(0, constant_sd^2),    c_kj ~ N(0, (tau_k rho^(j-1))^2)   (j >= 1)

and ``(tau_1..tau_5)`` maximise the evidence of the largest model, for each ``rho`` of
the prior's grid, the best ``rho`` kept (empirical Bayes: MacKay 1992, *Neural Comput.*
4, 415, "evidence approximation"; Tipping 2001 for one scale per group). The largest
model holds every term any candidate can use, so its evidence sees each parameter's
whole structure; the orders are then chosen, and averaged, under these fixed widths.
Measured on the random-truth ensemble of ``benchmarks/model_choice.py``. Fitted scales
make the error bars overconfident where the data pin them weakly (four loads);
:mod:`calibration.parameter_scales` marginalises them instead.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from .conjugate import ScalePrior, solve
from .errors import IllPosedError
from .noise_waves import N_PARAMETERS
from .normal_equations import NormalEquations
from .parameter_scales import variances
from .polynomial_model import as_orders
from .shrinkage import ShrinkagePrior

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ParameterScales:
    """Fitted widths: ``tau_k`` per parameter (K), the shared decay, the constants' sd."""

    tau_k: tuple[float, ...]
    decay: float
    constant_sd_k: float

    def variances(self, orders: Sequence[int]) -> FloatArray:
        """Prior variance of every coefficient of ``orders``, shape ``(1, P)``.

        One row: the shape of :meth:`ShrinkagePrior.variances` with a one-point grid, so
        the mixture of :mod:`calibration.averaging` takes either.
        """
        log_tau = np.log(np.asarray(self.tau_k))[None, :]
        return variances(as_orders(orders), log_tau, self.decay, self.constant_sd_k)


def fit_scales(
    normal: NormalEquations, prior: ShrinkagePrior, scale_prior: ScalePrior | None
) -> ParameterScales:
    """The ``tau_k`` and decay maximising the largest model's evidence (module docstring).

    ``tau_k`` is searched in ``log`` between the prior's ``tau_min_k`` and ``tau_max_k``
    (bounded quasi-Newton from the middle of the range), once per decay.
    """
    orders = normal.max_orders
    zeros = np.zeros(sum(orders))
    bounds = [(np.log(prior.tau_min_k), np.log(prior.tau_max_k))] * N_PARAMETERS
    start = np.full(N_PARAMETERS, 0.5 * (bounds[0][0] + bounds[0][1]))
    best: tuple[float, ParameterScales] | None = None
    for decay in prior.decays:

        def scales(log_tau: FloatArray, decay: float = decay) -> ParameterScales:
            return ParameterScales(tuple(np.exp(log_tau)), decay, prior.constant_sd_k)

        def negative(log_tau: FloatArray, scales=scales) -> float:  # type: ignore[no-untyped-def]
            variances = scales(log_tau).variances(orders)[0]
            try:
                return -solve(normal, orders, zeros, variances, scale_prior).log_evidence
            except IllPosedError:
                return np.inf

        result = minimize(negative, start, method="L-BFGS-B", bounds=bounds)
        if np.isfinite(result.fun) and (best is None or result.fun < best[0]):
            best = (float(result.fun), scales(result.x))
    if best is None:
        raise IllPosedError("no prior scale gives the largest model a finite evidence")
    return best[1]
