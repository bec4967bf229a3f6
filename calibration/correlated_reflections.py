"""Reflection errors shared between rows, in the posterior's covariance.

The solver's rows carry the VNA's trace noise as a variance per row
(:mod:`calibration.reflection_noise`): right for each row, for the fit's mean and for the
noise scale ``s^2`` fitted from the rows' scatter. But two kinds of rows share one error:

* **neighbouring channels**: the VNA measures at its sweep's points, which the hand-over
  interpolates onto the spectrometer's channels (cubic splines,
  :mod:`reach_receiver.store.handover`), so one point's error is shared by the
  ``L = step / channel width`` channels around it (REACH: 100 kHz steps, 12.2 kHz
  channels, ``L ~ 8``); a polynomial averages over channels, and an error shared by ``L``
  channels averages ``L`` times less;
* **every calibrator at one channel**: the receiver's reflection ``Gamma_rec`` is one
  measurement, in every calibrator's row.

Left alone, in simulations with trace noise of 4e-4 (7-20 % of each row's variance, as
in a REACH-like run) the calibration error was 1.6x its posterior's with ``L = 8``, and
1.3x with ``L = 1`` where the trace noise dominated the rows.

The estimate keeps its weights ``W = diag(w)``, ``w = 1 / v`` the rows' variances; its
covariance is the sandwich ``A^-1 X^T W C W X A^-1`` (``A = X^T W X + P``) with ``C`` the
rows' true covariance. For a model smooth over ``L`` channels only each row's sum of
covariances with its neighbours matters: ``L`` times its own for errors shared over ``L``
channels (a spline through white points has the same sum as blocks of ``L``). With
``J_i = dT_i / d(Re, Im) Gamma_rec`` and ``sigma_rec`` the receiver's trace noise, rows
``x_i``::

    X^T W C W X = A - H_diag + L (H_src + G_rec)
    H_diag = X^T diag(w^2 v_r) X                      (the reflection part v_r as the rows hold it)
    H_src  = X^T diag(w^2 v_src) X                    (each source's own reflection error)
    G_rec  = sum_f (sigma_rec^2 / 2) sum_{re,im} u_f u_f^T,   u_f = sum_i w_if x_if J_if

and, with the posterior's ``Cov_0 = s^2 A^-1``::

    Cov = Cov_0 + Cov_0 (L (H_src + G_rec) - H_diag) Cov_0 / s^2

:func:`widen` applies it to a posterior, component by component for a model average.
Approximations, stated: ``H`` and ``G`` leave out the marginalised calibrator temperature
offsets (:mod:`calibration.normal_equations`), small beside the reflections'; the mean,
the evidence and ``s^2`` are unchanged.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from .averaging import MixturePosterior, mixture_of
from .conjugate import LinearPosterior
from .normal_equations import weighted_gram
from .polynomial_model import Orders, full_indices

__all__ = ["shared_error_excess", "widen"]

FloatArray = NDArray[np.float64]


def shared_error_excess(
    features: FloatArray,
    weights: FloatArray,
    basis: FloatArray,
    layout: Orders,
    correlation_channels: float,
    source_variance: FloatArray | None,
    receiver_slopes: tuple[FloatArray, FloatArray] | None,
    receiver_std: FloatArray | None,
) -> FloatArray:
    """``L (H_src + G_rec) - H_diag`` of the module docstring, in the ``layout``.

    ``features (M, N, 5)`` and ``weights (M, N)`` are the rows as the fit weighed them;
    ``source_variance (M, N)`` the sources' own reflection variance in K^2,
    ``receiver_slopes`` ``(J_re, J_im)``, each ``(M, N)``, with ``receiver_std (N,)``.
    """
    big_l = float(correlation_channels)
    w2 = weights**2
    excess = np.zeros((sum(layout), sum(layout)))
    if source_variance is not None:
        excess += (big_l - 1.0) * weighted_gram(features, w2 * source_variance, basis, layout)
    if receiver_slopes is not None and receiver_std is not None:
        sigma = np.asarray(receiver_std, dtype=float)
        half_var = np.broadcast_to(sigma**2 / 2.0, weights.shape[1:])
        for slope in receiver_slopes:
            u = np.einsum("mn,mnk,mn->nk", weights, features, slope)[None]  # (1, N, 5)
            excess += big_l * weighted_gram(u, half_var[None], basis, layout)
            excess -= weighted_gram(features, w2 * slope**2 * half_var, basis, layout)
    return excess


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
