"""Looking beyond the polynomial box: delay terms and the misfit that remains.

After the order search, the radiometric solver holds its fit to the radiometer noise in
binned residuals (:mod:`calibration.solve.delay_terms`): where structure remains, delay terms
join the polynomials if the evidence wants them, and the covariance is to be inflated by
the binned misfit beyond what the fitted ``s^2`` carries. This module builds the rows
that test needs (declared temperature offsets and the reflections' errors shared over
channels included) and applies what it found to the posterior and the metadata.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..model.basis import PolynomialBasis
from ..model.data import CalibrationData
from ..model.reflection_noise import reflection_variance
from ..regression.conjugate import LinearPosterior, ScalePrior
from ..regression.normal_equations import evaluate_coefficients
from .delay_terms import Rows, extend
from .linearisation import LinearisedProblem, linearise

FloatArray = NDArray[np.float64]


def beyond_box(
    data: CalibrationData,
    posterior: LinearPosterior,
    basis: PolynomialBasis,
    problem: LinearisedProblem,
    scale_prior: ScalePrior | None,
    search: bool,
    metadata: dict[str, object],
    warnings: list[str],
    grew: bool = False,
) -> tuple[LinearPosterior, PolynomialBasis, float]:
    """The posterior and basis after :func:`~calibration.solve.delay_terms.extend`, inflated.

    The factor the covariance is to be inflated by for the misfit that remains is applied
    by the caller after the identifiability check, which asks what the calibrators
    determine, not how well the model fits. ``grew``: the automatic box was raised past
    its start, as a ripple of a few periods makes it (at a 40 MHz period over 80 MHz the
    search stopped at 8-12 terms, inside its box, with its error 0.6-3x its error bar):
    the delays are tried as where the search ended at its ceiling.
    """
    terms = data.terms()
    temps, q, var_q = data.stacked()
    gammas = np.stack([s.gamma for s in data.sources.values()])
    gamma_std = data.reflection_errors()
    declared = data.temperature_variances()
    offsets = declared if np.any(declared > 0) else None
    correlation = float(data.reflection_correlation_channels)

    def _shared(extra: FloatArray | float) -> FloatArray | None:
        arr = np.broadcast_to(np.asarray(extra, dtype=float), q.shape)
        return arr if np.any(arr > 0) else None

    def relinearise(theta: FloatArray) -> Rows:
        extra = reflection_variance(
            theta[:, None, :], gammas, data.gamma_rec, q, gamma_std, data.gamma_rec_std
        )
        p = linearise(terms, temps, q, var_q, theta, extra)
        return Rows(p.features, p.weights, p.response, offsets, _shared(extra), correlation)

    b = basis.matrix(data.freq_hz, max(posterior.orders))
    theta = evaluate_coefficients(posterior.mean, b, posterior.orders)
    start = reflection_variance(
        theta[:, None, :], gammas, data.gamma_rec, q, gamma_std, data.gamma_rec_std
    )
    rows = Rows(problem.features, problem.weights, problem.response, offsets, _shared(start),
                correlation)
    ext = extend(
        rows, theta, posterior.mean.size, data.freq_hz, basis, scale_prior, relinearise,
        search, at_ceiling=grew or bool(metadata.get("orders_at_ceiling")),
        noise_scale=float(posterior.noise_variance),
    )
    if ext is None:
        return posterior, basis, 1.0
    metadata.update(ext.metadata)
    warnings.extend(ext.warnings)
    if ext.model is not None:
        posterior, basis = ext.model.posterior, ext.model.basis
    return posterior, basis, max(ext.inflation, 1.0)
