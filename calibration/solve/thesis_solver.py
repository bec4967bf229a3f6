"""The thesis's solver (EXCALIBRATE, thesis chapter 3), kept faithfully as the baseline.

Likelihood (eq. 3.33): the calibrator temperatures are the data,
``T_cal = X Theta + sigma`` with ``X = (X_unc, X_cos, X_sin, X_NS, X_L)`` (eq. 3.28),
``X_NS = Q X_L`` built from the *measured* Q, and one homoscedastic noise variance
``sigma^2`` for every row. Prior: normal-inverse-gamma (eq. 3.34) with the thesis defaults
of section 4.4::

    a = 1                                                      (eq. 4.1)
    b = (a + 1) sigma_p^2,  sigma_p = 1 K                      (eq. 4.2, in kelvin)

so that the prior mode of ``sigma^2`` is ``sigma_p^2``. Evidence eq. 3.35, posterior
eq. 3.38, predictive eq. 3.42, error term ``Sigma* = (b*/a*) V*`` (eq. 4.3).

Known shortcomings, kept on purpose because this is the published method: the noise is
really in Q (so the regressor ``X_NS`` is noisy: errors-in-variables), its variance differs
by calibrator and channel, and one ``sigma`` cannot describe it. See
:mod:`calibration.solve.radiometric_solver` for the solver that fixes this.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..choice.model_fit import OrderChoice
from ..choice.model_size import fit_extending
from ..model.basis import BasisKind, PolynomialBasis
from ..model.data import CalibrationData
from ..model.polynomial_model import Orders
from ..regression.conjugate import CoefficientPrior, ScalePrior
from ..regression.normal_equations import NormalEquations, build_normal_equations
from .identifiability import check_determined, require_temperature_contrast
from .solution import Solution


@dataclass(frozen=True)
class ThesisPrior:
    """The thesis's prior: ``a`` (eq. 4.1), expected noise ``sigma_p`` (eq. 4.2), coefficients."""

    a: float = 1.0
    sigma_p_k: float = 1.0
    coefficients: CoefficientPrior = field(default_factory=CoefficientPrior)

    @property
    def scale_prior(self) -> ScalePrior:
        """``IG(a, b)`` with ``b = (a + 1) sigma_p^2`` (eq. 4.2)."""
        return ScalePrior(self.a, (self.a + 1.0) * self.sigma_p_k**2)


def solve_thesis(
    data: CalibrationData,
    orders: OrderChoice | None = None,
    prior: ThesisPrior | None = None,
    basis_kind: BasisKind = "legendre",
    allow_prior_dominated: bool = False,
) -> Solution:
    """Noise-wave parameters by the thesis's conjugate-prior method.

    ``orders=None`` chooses the orders by evidence (section 4.2.3, with the search of
    :mod:`calibration.choice.order_search`). ``basis_kind="power"`` uses the thesis's
    ``(nu/nu_0)^k`` (eq. 3.40); the default Legendre basis spans the same space.
    ``allow_prior_dominated`` lets the prior fix directions the data leave free (the
    thesis's single-load posteriors of fig. 4.3); otherwise that is an error.
    """
    choice = orders or OrderChoice()
    prior = prior or ThesisPrior()
    basis = PolynomialBasis.for_frequencies(data.freq_hz, basis_kind)
    temps, q, _ = data.stacked()
    features = data.terms().matrix(q)
    weights = np.ones_like(temps)

    def build(largest: Orders) -> NormalEquations:
        _, var0 = prior.coefficients.vectors(largest)
        return build_normal_equations(
            features,
            weights,
            temps,
            basis.matrix(data.freq_hz, max(largest)),
            largest,
            ridge=prior.sigma_p_k**2 / var0,
        )

    if not allow_prior_dominated:
        require_temperature_contrast(data)
    result = fit_extending(
        build,
        choice,
        prior.coefficients,
        prior.sigma_p_k**2,
        prior.scale_prior,
        allow_prior_dominated,
    )
    posterior = result.posterior
    solution = Solution(
        method="thesis",
        basis=basis,
        posterior=posterior,
        measurement_model="homoscedastic",
        evidence_table=result.table,
        calibrators=tuple(data.names),
        metadata={
            "sigma_k": float(np.sqrt(posterior.noise_variance)),
            **result.limits_metadata(noise_is_scale=False),
        },
    )
    dominated = check_determined(solution, data, prior.coefficients, allow_prior_dominated)
    return replace(solution, metadata={**solution.metadata, "prior_dominated": dominated})
