"""The radiometer noise floor: the Cramer-Rao limit of the calibration error.

For a run whose spectra carry radiometer noise only, the Fisher information of the
noise-wave coefficients ``c`` (for given orders) is::

    F = sum_if J_if J_if^T / var(Q_if),      J_if = dQ_if / dc

and ``J_if = -x_if / (X_L T_NS)`` with ``x_if`` the Gauss-Newton design row of
:mod:`calibration.solve.radiometric_solver`, evaluated at the true parameters. Any unbiased
estimator of a source's calibrated temperature ``T_src(f) = x_src(f)^T c`` then has::

    var(T_src(f)) >= x_src(f)^T F^-1 x_src(f)

The floor of a source is that bound per channel and its root mean square over the band,
the number against which a solution's error is judged ("distance to the floor").

Where the run states the VNA's random errors (the sources' ``gamma_std``, the receiver's
``gamma_rec_std``), they are noise of the data too: each row's variance gains their
part (:mod:`calibration.model.reflection_noise`, as the solver's rows do), and the source's
own per-channel part, which no estimator of smooth parameters removes, adds to its bound.
The calibrators' stated temperature uncertainties (``temperature_std_k``) are marginalised
as the solver marginalises them (one offset per source).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_factor, solve_triangular

from ..model.data import CalibrationData, SourceData
from ..model.noise_waves import design_terms
from ..model.polynomial_model import PolynomialParameters, design_rows
from ..model.reflection_noise import reflection_variance
from ..regression.normal_equations import build_normal_equations
from .radiometric_solver import LinearisedProblem, linearise

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


@dataclass(frozen=True)
class NoiseFloor:
    """Cramer-Rao standard deviation of a calibrated source, per channel and RMS (K)."""

    freq_hz: FloatArray
    std: FloatArray

    @property
    def rms(self) -> float:
        """Root mean square of the per-channel floor over the band."""
        return float(np.sqrt(np.mean(self.std**2)))


def noise_floor(
    data: CalibrationData,
    source: SourceData,
    parameters: PolynomialParameters,
    gamma_rec: ComplexArray | None = None,
    own_reflection: bool = True,
) -> NoiseFloor:
    """Floor of ``source`` calibrated from ``data``, for the model ``parameters``.

    ``parameters`` supplies the orders and the point at which the information is
    evaluated: the truth in a simulation, a solution's posterior mean otherwise.
    ``source`` supplies its reflection and Q (use the noiseless Q when known);
    ``gamma_rec`` defaults to the run's receiver reflection. ``own_reflection``: whether
    the source's own reflection errors (its measured reflection's and the receiver's, used
    in calibrating it) count; yes when the error is judged against its true temperature,
    no when against the temperature its measured reflections imply (the simulated
    receiver's :meth:`~reach_receiver.sim.physics.ReceiverPhysics.calibration_error_k`).
    """
    freq = data.freq_hz
    orders = parameters.orders
    basis = parameters.basis.matrix(freq, max(orders))
    theta = parameters.evaluate(freq)
    rows = _information_rows(data, theta)
    normal = build_normal_equations(
        rows.features,
        rows.weights,
        rows.response,
        basis,
        orders,
        reference=parameters.coefficients,
        offset_variance=offsets if np.any(offsets := data.temperature_variances()) else None,
    )
    chol, _ = cho_factor(normal.gram, lower=True)
    src_terms = design_terms(source.gamma, data.gamma_rec if gamma_rec is None else gamma_rec)
    src_rows = design_rows(src_terms.matrix(source.q), basis, orders)
    z = solve_triangular(chol, src_rows.T, lower=True)
    direct = _own_reflection(data, source, theta, gamma_rec) if own_reflection else 0.0
    return NoiseFloor(freq, np.sqrt(np.sum(z**2, axis=0) + direct))


def channel_noise_floor(
    data: CalibrationData,
    source: SourceData,
    theta: FloatArray,
    gamma_rec: ComplexArray | None = None,
    own_reflection: bool = True,
) -> NoiseFloor:
    """Floor of ``source`` for an estimator that solves each channel alone (thesis 4.7, 4.8).

    The per-channel model has five free parameters at every channel (``theta``, ``(5, N)``
    on ``data``'s channels: the truth, or a
    :class:`~calibration.solve.per_frequency.ChannelSolution`'s mean). Its Fisher information
    at channel ``f`` is the ``5 x 5`` matrix ``F_f = sum_i w_if x_if x_if^T`` of the same
    Gauss-Newton rows as :func:`noise_floor`; each calibrator's temperature uncertainty
    adds to its row's variance (one channel cannot separate an offset from the
    parameters). The bound is ``var T_src(f) >= x_src(f)^T F_f^-1 x_src(f)``, plus the
    source's own reflection part when ``own_reflection``. It lies above the polynomial
    floor: each channel's five parameters are learnt from that channel alone.
    """
    rows = _information_rows(data, theta)
    weights = 1.0 / (1.0 / rows.weights + data.temperature_variances()[:, None])
    x = np.moveaxis(rows.features, 0, 1)  # (N, M, 5)
    fisher = np.einsum("nmp,mn,nmq->npq", x, weights, x)
    src_terms = design_terms(source.gamma, data.gamma_rec if gamma_rec is None else gamma_rec)
    jacobi = np.sqrt(np.diagonal(fisher, axis1=1, axis2=2))  # scaled: no inverse, stable
    chol = np.linalg.cholesky(fisher / (jacobi[:, :, None] * jacobi[:, None, :]))
    src_rows = src_terms.matrix(source.q) / jacobi  # (N, 5)
    z = np.linalg.solve(chol, src_rows[:, :, None])[:, :, 0]
    direct = _own_reflection(data, source, theta, gamma_rec) if own_reflection else 0.0
    return NoiseFloor(data.freq_hz, np.sqrt(np.sum(z**2, axis=1) + direct))


def _information_rows(data: CalibrationData, theta: FloatArray) -> LinearisedProblem:
    """The calibrators' Gauss-Newton rows at ``theta`` and their noiseless ``Q``."""
    temps, _, var_q = data.stacked()
    terms = data.terms()
    noiseless_q = np.asarray((temps - terms.offset(theta)) / (terms.x_l * theta[3]), dtype=float)
    gammas = np.stack([s.gamma for s in data.sources.values()])
    extra = reflection_variance(
        theta[:, None, :], gammas, data.gamma_rec, noiseless_q, data.reflection_errors(),
        data.gamma_rec_std,
    )
    return linearise(terms, temps, noiseless_q, var_q, theta, extra)


def _own_reflection(
    data: CalibrationData, source: SourceData, theta: FloatArray, gamma_rec: ComplexArray | None
) -> FloatArray | float:
    return reflection_variance(
        theta, source.gamma, data.gamma_rec if gamma_rec is None else gamma_rec, source.q,
        source.gamma_std, data.gamma_rec_std,
    )
