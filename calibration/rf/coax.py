"""Lossy coaxial cables as two-ports, for cables whose S-parameters were not measured.

A uniform line of characteristic impedance ``Zc`` and propagation ``gamma l``, seen in a
reference impedance ``Zr`` (50 ohm), is the symmetric, reciprocal two-port (Pozar,
*Microwave Engineering*, 4th ed., sec. 2.3 and table 4.2 converted to S)::

    S11 = S22 = (Zc^2 - Zr^2) tanh(gamma l) / D
    S21 = S12 = 2 Zc Zr sech(gamma l) / D,    D = (Zc^2 + Zr^2) tanh(gamma l) + 2 Zc Zr   (C1)

(:func:`line_s_parameters`; written with ``tanh`` and ``sech`` so that a long, lossy line
does not overflow). Two ways to get ``Zc`` and ``gamma l``:

* :class:`DataSheetCoax`, from a data sheet: length, velocity factor ``v_f`` and the loss
  ``L`` in dB/m at a reference frequency, scaled as ``(f / f_ref)^n`` (``n = 1/2`` for a
  conductor-loss (skin-effect) dominated cable, ``n = 1`` for dielectric loss)::

      alpha = L (f / f_ref)^n / (20 log10 e),   beta = 2 pi f / (v_f c),   Zc = Z0 (real)  (C2)

  With ``Z0 = Zr`` this is :class:`calibration.model.reflections.Cable`'s model exactly (its
  ``round_trip`` is ``S21^2``), which could be built on it.
* :class:`PhysicalCoax`, from the geometry and materials (the model of Alan Rogers'
  ``cabl2`` used by edges-cal, and of :func:`calibration.io.edges_text.coax_power_gain`):
  per unit length, with skin depth ``delta = 1 / sqrt(pi f mu0 sigma)``::

      R = 1 / (2 pi a sigma_a delta_a) + 1 / (2 pi b sigma_b delta_b)
      L = mu0 ln(b/a) / (2 pi) + R / omega          (internal inductance of the skin layer)
      C = 2 pi eps0 eps_r / ln(b/a),    G = omega C tan_d
      Zc = sqrt((R + j omega L) / (G + j omega C))
      gamma = sqrt((R + j omega L) (G + j omega C))                                 (C3)

  :func:`calibration.io.edges_text.coax_power_gain` is, in terms of this module and
  :mod:`calibration.model.source_temperatures`, ``available_gain(s, deembed_reflection(g, s), g)``
  with ``s = PhysicalCoax(**UT141C).s_parameters(f)`` (``tests/test_source_temperatures.py``
  holds the two equal), and could be rewritten so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import InvalidDataError

__all__ = ["DataSheetCoax", "PhysicalCoax", "line_s_parameters"]

ComplexArray = NDArray[np.complex128]
FloatArray = NDArray[np.float64]

SPEED_OF_LIGHT_M_S = 299_792_458.0
MU0_H_PER_M = 1.25663706212e-6
EPS0_F_PER_M = 8.8541878128e-12
DB_PER_NEPER = 20 * np.log10(np.e)
REFERENCE_OHM = 50.0


def line_s_parameters(
    zc_ohm: ArrayLike, gamma_l: ArrayLike, z_ref_ohm: float = REFERENCE_OHM
) -> ComplexArray:
    """S-parameters (C1), shape ``(n, 2, 2)``, of a line ``Zc``, ``gamma l`` (each ``(n,)``)."""
    zc = np.asarray(zc_ohm, dtype=complex)
    gl = np.asarray(gamma_l, dtype=complex)
    zc, gl = np.broadcast_arrays(zc, gl)
    e = np.exp(-gl)
    tanh = (1 - e * e) / (1 + e * e)
    sech = 2 * e / (1 + e * e)
    d = (zc**2 + z_ref_ohm**2) * tanh + 2 * zc * z_ref_ohm
    s = np.empty((*gl.shape, 2, 2), dtype=complex)
    s[..., 0, 0] = s[..., 1, 1] = (zc**2 - z_ref_ohm**2) * tanh / d
    s[..., 0, 1] = s[..., 1, 0] = 2 * zc * z_ref_ohm * sech / d
    return s


def _frequencies(freq_hz: ArrayLike) -> FloatArray:
    f = np.asarray(freq_hz, dtype=float)
    if not (np.all(np.isfinite(f)) and np.all(f > 0)):
        raise InvalidDataError("cable models need finite frequencies > 0")
    return f


@dataclass(frozen=True)
class DataSheetCoax:
    """A cable from its data sheet (C2): length, velocity factor, loss at a frequency."""

    length_m: float
    velocity_factor: float
    loss_db_per_m: float
    """Loss per metre at ``ref_freq_hz``, dB (a positive number)."""
    ref_freq_hz: float = 100e6
    loss_exponent: float = 0.5
    """``n`` of ``(f / f_ref)^n``: 0.5 for skin-effect loss, 1 for dielectric loss."""
    z0_ohm: float = REFERENCE_OHM

    def __post_init__(self) -> None:
        ok = (self.length_m >= 0 and 0 < self.velocity_factor <= 1 and self.loss_db_per_m >= 0
              and self.ref_freq_hz > 0 and self.z0_ohm > 0 and np.isfinite(self.loss_exponent))
        if not ok:
            raise InvalidDataError(f"not a physical cable: {self}")

    def propagation(self, freq_hz: ArrayLike) -> ComplexArray:
        """``gamma l = alpha l + j beta l`` (C2), in nepers and radians."""
        f = _frequencies(freq_hz)
        alpha = self.loss_db_per_m * (f / self.ref_freq_hz) ** self.loss_exponent / DB_PER_NEPER
        beta = 2 * np.pi * f / (self.velocity_factor * SPEED_OF_LIGHT_M_S)
        return np.asarray((alpha + 1j * beta) * self.length_m, dtype=complex)

    def s_parameters(self, freq_hz: ArrayLike, z_ref_ohm: float = REFERENCE_OHM) -> ComplexArray:
        """S-parameters (C1), shape ``(n, 2, 2)``."""
        return line_s_parameters(self.z0_ohm, self.propagation(freq_hz), z_ref_ohm)


@dataclass(frozen=True)
class PhysicalCoax:
    """A cable from its geometry and materials (C3); SI units, radii in metres."""

    a: float
    """Inner conductor radius."""
    b: float
    """Outer conductor (inner) radius."""
    eps_r: float
    sigma_in: float
    """Inner conductor's conductivity, S/m."""
    sigma_out: float
    tan_d: float
    length: float
    """Length, metres."""

    def __post_init__(self) -> None:
        ok = (0 < self.a < self.b and self.eps_r >= 1 and self.sigma_in > 0
              and self.sigma_out > 0 and self.tan_d >= 0 and self.length >= 0)
        if not ok:
            raise InvalidDataError(f"not a physical coaxial cable: {self}")

    def line_constants(self, freq_hz: ArrayLike) -> tuple[ComplexArray, ComplexArray]:
        """``(Zc, gamma l)`` of (C3)."""
        f = _frequencies(freq_hz)
        omega = 2 * np.pi * f
        log_ratio = np.log(self.b / self.a)
        resistance = sum(
            np.sqrt(np.pi * f * MU0_H_PER_M / sigma) / (2 * np.pi * radius)  # 1/(sigma delta)
            for radius, sigma in ((self.a, self.sigma_in), (self.b, self.sigma_out))
        )
        inductance = MU0_H_PER_M * log_ratio / (2 * np.pi) + resistance / omega
        capacitance = 2 * np.pi * EPS0_F_PER_M * self.eps_r / log_ratio
        series = resistance + 1j * omega * inductance
        shunt = omega * capacitance * (self.tan_d + 1j)
        zc = np.asarray(np.sqrt(series / shunt), dtype=complex)
        return zc, np.asarray(np.sqrt(series * shunt) * self.length, dtype=complex)

    def s_parameters(self, freq_hz: ArrayLike, z_ref_ohm: float = REFERENCE_OHM) -> ComplexArray:
        """S-parameters (C1), shape ``(n, 2, 2)``."""
        return line_s_parameters(*self.line_constants(freq_hz), z_ref_ohm)
