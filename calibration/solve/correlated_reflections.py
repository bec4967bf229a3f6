"""Reflection errors shared by neighbouring channels, in the posterior's covariance.

The solver's rows carry the VNA's trace noise as a variance per row
(:mod:`calibration.model.reflection_noise`): right for each row, for the fit's mean and for the
noise scale ``s^2`` fitted from the rows' scatter. But the VNA measures at its sweep's
points, which the hand-over interpolates onto the spectrometer's channels (cubic splines,
:mod:`reach_receiver.store.handover`), so one point's error is shared by the
``L = step / channel width`` channels around it (REACH: 100 kHz steps, 12.2 kHz channels,
``L ~ 8``); a polynomial averages over channels, and an error shared by ``L`` channels
averages ``L`` times less. With trace noise of 4e-4 on the calibrators' reflections alone
(the receiver's exact), shared over 8 channels, the solution's error was 1.85x its
posterior's; with this correction 1.14 (16 truths, ``tests/test_correlated_reflections.py``).
The Cramer-Rao floor (:mod:`calibration.solve.noise_floor`) still treats the rows as
independent, so it sits that much low beside a widened posterior (+5 % on a simulated
REACH run).

The estimate keeps its weights ``W = diag(w)``, ``w = 1 / v`` the rows' variances; its
covariance is the sandwich ``A^-1 X^T W C W X A^-1`` (``A = X^T W X + P``) with ``C`` the
rows' true covariance. For a model smooth over ``L`` channels only each row's sum of
covariances with its neighbours matters: ``L`` times its own for errors shared over ``L``
channels (a spline through white points has the same sum as blocks of ``L``). With
``v_src`` each source's own reflection variance in its rows::

    X^T W C W X = A + (L - 1) H_src,      H_src = X^T diag(w^2 v_src) X

(with the calibrators' temperature offsets marginalised, ``W`` is the fit's ``C^-1``
with their projection, in ``A`` and ``H_src`` alike: leaving it out of ``H_src`` overstated
the widening sixfold on a run with thermocouple errors)

and, with the posterior's ``Cov_0 = s^2 A^-1``::

    Cov = Cov_0 + (L - 1) Cov_0 H_src Cov_0 / s^2

:func:`widen` applies it to a posterior, component by component for a model average.

Not here: the receiver's reflection. Its error is one reading in every calibrator's row
and in every source calibrated with the solution, and in a calibrated source the two
largely cancel (the noise waves absorb a wrong ``Gamma_rec`` the way the source's
calibration reapplies it). The rows keep its variance each, and a calibrated source its
own share (:meth:`calibration.solve.solution.Solution.calibrate`): a calibrated antenna's
predictive then matches its error (0.93-0.94 actual / predicted in the test's ensembles),
but the noise-wave parameters' own error bars leave out its sharing between calibrators
and channels (up to 1.7x too small where the receiver's trace noise is shared over 8
channels). The mean, the evidence and ``s^2`` are unchanged.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from ..choice.averaging import MixturePosterior, mixture_of
from ..model.polynomial_model import Orders, full_indices
from ..regression.conjugate import LinearPosterior
from ..regression.normal_equations import sandwich_gram

__all__ = ["shared_error_excess", "widen"]

FloatArray = NDArray[np.float64]


def shared_error_excess(
    features: FloatArray,
    weights: FloatArray,
    basis: FloatArray,
    layout: Orders,
    correlation_channels: float,
    source_variance: FloatArray,
    offset_variance: FloatArray | None = None,
) -> FloatArray:
    """``(L - 1) H_src`` of the module docstring, in the ``layout``.

    ``features (M, N, 5)`` and ``weights (M, N)`` are the rows as the fit weighed them,
    ``source_variance (M, N)`` the sources' own reflection variance in K^2, and
    ``offset_variance`` the calibrators' marginalised temperature offsets, whose
    projection the fit's ``C^-1`` holds
    (:func:`calibration.regression.normal_equations.sandwich_gram`).
    """
    excess = float(correlation_channels) - 1.0
    return excess * sandwich_gram(
        features, weights, source_variance, basis, layout, offset_variance
    )


def _widened(
    post: LinearPosterior, excess: FloatArray, layout: Orders
) -> LinearPosterior:
    idx = full_indices(post.orders, layout)
    scale = post.scale + post.scale @ excess[np.ix_(idx, idx)] @ post.scale / post.noise_variance
    return replace(post, scale=0.5 * (scale + scale.T))


def widen(posterior: LinearPosterior, excess: FloatArray, layout: Orders) -> LinearPosterior:
    """``posterior`` with the shared errors' covariance (module docstring).

    ``excess`` is :func:`shared_error_excess` in ``layout`` (every model's coefficients
    are a sub-block of it).
    """
    if isinstance(posterior, MixturePosterior):
        parts = [_widened(p, excess, layout) for p in posterior.components]
        return mixture_of(parts, posterior.weights, posterior.log_evidence, posterior.n_rows)
    return _widened(posterior, excess, layout)
