"""The noise-wave forward model of a Dicke-switched radiometer.

Power spectral densities at the three Dicke positions (thesis eqs. 3.12, 3.13, 3.20)::

    P_cal = g [ T_cal (1-|G|^2)|F|^2 + T_unc |G|^2 |F|^2
                + T_cos Re(G F) + T_sin Im(G F) + T_0 ]                      (3.20)
    P_L   = g [ T_L (1-|G_rec|^2) + T_0 ]                                     (3.12)
    P_NS  = g [ (T_L + T_NS)(1-|G_rec|^2) + T_0 ]                             (3.13)

with ``F = sqrt(1-|G_rec|^2) / (1 - G G_rec)`` (eq. 3.3), ``G`` the source reflection
coefficient and ``G_rec`` the receiver's. The gain ``g`` and offset ``T_0`` cancel in
``Q = (P_cal - P_L) / (P_NS - P_L)`` (eq. 3.9), leaving the linear calibration equation
(eq. 3.27)::

    X_unc T_unc + X_cos T_cos + X_sin T_sin + X_NS T_NS + X_L T_L = T_cal

with the design terms of eqs. 3.22-3.26, computed by :func:`design_terms`.

Parameter order everywhere in this package: ``PARAMETERS = (unc, cos, sin, NS, L)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.constants import PARAMETER_NAMES

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: The five noise-wave parameters, in the order used by every array in this package.
PARAMETERS: tuple[str, ...] = PARAMETER_NAMES
N_PARAMETERS = len(PARAMETERS)
#: Index of each parameter in :data:`PARAMETERS`.
INDEX = {name: i for i, name in enumerate(PARAMETERS)}


@dataclass(frozen=True)
class DesignTerms:
    """The reflection-dependent design terms of eqs. 3.22-3.25 (all real, same shape).

    ``X_NS = Q X_L`` (eq. 3.26) is formed by :meth:`matrix` because it needs ``Q``.
    """

    x_unc: FloatArray
    x_cos: FloatArray
    x_sin: FloatArray
    x_l: FloatArray

    def matrix(self, q: ArrayLike) -> FloatArray:
        """Stack the five design terms on a last axis in :data:`PARAMETERS` order."""
        q = np.asarray(q, dtype=float)
        return np.stack([self.x_unc, self.x_cos, self.x_sin, q * self.x_l, self.x_l], axis=-1)

    def offset(self, theta: FloatArray) -> FloatArray:
        """``X_unc T_unc + X_cos T_cos + X_sin T_sin + X_L T_L``: everything but the Q term."""
        return (
            self.x_unc * theta[0]
            + self.x_cos * theta[1]
            + self.x_sin * theta[2]
            + self.x_l * theta[4]
        )


def design_terms(gamma_src: ArrayLike, gamma_rec: ArrayLike) -> DesignTerms:
    """Design terms of the calibration equation (thesis eqs. 3.22-3.25).

    ::

        X_unc = -|G|^2 / (1 - |G|^2)                                         (3.22)
        X_L   = |1 - G G_rec|^2 / (1 - |G|^2)                                (3.23)
        X_cos = -Re( G / (1 - G G_rec) * X_L / sqrt(1 - |G_rec|^2) )        (3.24)
        X_sin = -Im( G / (1 - G G_rec) * X_L / sqrt(1 - |G_rec|^2) )        (3.25)

    Arrays broadcast; ``gamma_rec`` usually has the channel axis last.
    """
    g = np.asarray(gamma_src, dtype=complex)
    gr = np.asarray(gamma_rec, dtype=complex)
    mag2 = np.abs(g) ** 2
    denom = 1.0 - g * gr
    x_l = np.abs(denom) ** 2 / (1.0 - mag2)
    corr = g / denom * x_l / np.sqrt(1.0 - np.abs(gr) ** 2)
    x_unc = -mag2 / (1.0 - mag2)
    return DesignTerms(
        x_unc=np.broadcast_to(x_unc, x_l.shape).astype(float),
        x_cos=-corr.real,
        x_sin=-corr.imag,
        x_l=x_l,
    )


def source_temperature(theta: FloatArray, terms: DesignTerms, q: ArrayLike) -> FloatArray:
    """Calibrated temperature of a source from its Q and the parameters (eq. 3.27).

    ``theta`` has the parameter axis first: shape ``(5, ...)`` broadcasting with ``q``.
    """
    q = np.asarray(q, dtype=float)
    return terms.offset(theta) + q * terms.x_l * theta[3]


def model_q(theta: FloatArray, terms: DesignTerms, t_src: ArrayLike) -> FloatArray:
    """The Q a source of temperature ``t_src`` produces: eq. 3.27 solved for Q."""
    return (np.asarray(t_src, dtype=float) - terms.offset(theta)) / (terms.x_l * theta[3])


def q_from_powers(p_src: ArrayLike, p_load: ArrayLike, p_ns: ArrayLike) -> FloatArray:
    """``Q = (P_src - P_L) / (P_NS - P_L)`` (eq. 3.9)."""
    p_src, p_load, p_ns = (np.asarray(p, dtype=float) for p in (p_src, p_load, p_ns))
    return (p_src - p_load) / (p_ns - p_load)


def q_variance(
    p_src: ArrayLike,
    p_load: ArrayLike,
    p_ns: ArrayLike,
    samples_src: ArrayLike,
    samples_load: ArrayLike,
    samples_ns: ArrayLike,
) -> FloatArray:
    """Variance of Q from the radiometer equation, propagated to first order.

    Each spectrum has ``sigma_P = P / sqrt(B tau)`` (``B tau`` = independent samples per
    channel, the ``samples_*`` arguments). Differentiating eq. 3.9::

        var(Q) = [sigma_src^2 + (1 - Q)^2 sigma_L^2 + Q^2 sigma_NS^2] / (P_NS - P_L)^2
    """
    p_src, p_load, p_ns = (np.asarray(p, dtype=float) for p in (p_src, p_load, p_ns))
    q = (p_src - p_load) / (p_ns - p_load)
    var = (
        p_src**2 / np.asarray(samples_src, dtype=float)
        + (1.0 - q) ** 2 * p_load**2 / np.asarray(samples_load, dtype=float)
        + q**2 * p_ns**2 / np.asarray(samples_ns, dtype=float)
    )
    return np.asarray(var / (p_ns - p_load) ** 2, dtype=float)


def dicke_powers(
    theta: FloatArray,
    gamma_src: ArrayLike,
    gamma_rec: ArrayLike,
    t_src: ArrayLike,
    gain: ArrayLike,
    t_offset: ArrayLike,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Noiseless powers ``(P_src, P_L, P_NS)`` of one Dicke cycle (eqs. 3.20, 3.12, 3.13).

    ``theta`` is ``(5, n_channels)`` in :data:`PARAMETERS` order, ``gain`` the system gain
    ``g`` and ``t_offset`` the receiver offset ``T_0`` (both per channel).
    """
    g = np.asarray(gamma_src, dtype=complex)
    gr = np.asarray(gamma_rec, dtype=complex)
    t_src = np.asarray(t_src, dtype=float)
    gain = np.asarray(gain, dtype=float)
    t_offset = np.asarray(t_offset, dtype=float)
    rec_match = 1.0 - np.abs(gr) ** 2
    f = np.sqrt(rec_match) / (1.0 - g * gr)
    mag2 = np.abs(g) ** 2
    gf = g * f
    p_src = gain * (
        t_src * (1.0 - mag2) * np.abs(f) ** 2
        + theta[0] * mag2 * np.abs(f) ** 2
        + theta[1] * gf.real
        + theta[2] * gf.imag
        + t_offset
    )
    p_load = gain * (theta[4] * rec_match + t_offset)
    p_ns = gain * ((theta[4] + theta[3]) * rec_match + t_offset)
    return p_src, np.broadcast_to(p_load, p_src.shape), np.broadcast_to(p_ns, p_src.shape)
