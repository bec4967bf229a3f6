"""Calibration-kit models: the actual reflections of a kit's short, open and load over frequency.

The standard definitions are Keysight's (Agilent application note 1287-11, "Specifying
Calibration Standards and Kits for Agilent Vector Network Analyzers", the model of the
offset transmission line and of the terminations). A standard is a termination ``Z_T``
behind an offset line of delay ``tau`` (s), loss ``L`` (ohm/s at 1 GHz; data sheets quote
Gohm/s) and impedance ``Z0``; with ``omega = 2 pi f`` and ``s = sqrt(f / 1 GHz)``::

    alpha l = L tau s / (2 Z0)                        offset loss, Np                  (K1)
    beta l  = omega tau + alpha l                     offset phase, rad                (K2)
    gamma l = alpha l + j beta l                                                       (K3)
    Zc      = Z0 + (1 - j) L s / (2 omega)            lossy characteristic impedance   (K4)

    open:  Z_T = 1 / (j omega C(f)),  C(f) = C0 + C1 f + C2 f^2 + C3 f^3               (K5)
    short: Z_T = j omega L(f),        L(f) = L0 + L1 f + L2 f^2 + L3 f^3               (K6)
    load:  Z_T = R

and, in the system's reference impedance ``Zr`` (50 ohm)::

    G1 = (Zc - Zr) / (Zc + Zr),   GT = (Z_T - Zr) / (Z_T + Zr),   E = exp(-2 gamma l)  (K7)
    G  = [G1 (1 - E - G1 GT) + E GT] / [1 - G1 (E G1 + GT (1 - E))]                     (K8)

(K8) is the input reflection of a line of impedance ``Zc`` and propagation ``gamma l``
ended in ``Z_T``; a lossless ``Z0 = Zr`` offset reduces it to ``G = GT exp(-2 j omega tau)``.
Coefficients carry the data-sheet units: ``C0`` fF, ``C1`` 1e-27 F/Hz, ``C2`` 1e-36 F/Hz^2,
``C3`` 1e-45 F/Hz^3; ``L0`` pH, ``L1`` 1e-24 H/Hz, ``L2`` 1e-33 H/Hz^2, ``L3`` 1e-42 H/Hz^3.
:data:`IDEAL_KIT` is the textbook kit: short ``-1``, open ``+1``, load ``0`` exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import InvalidDataError

__all__ = [
    "IDEAL_KIT",
    "STANDARD_NAMES",
    "CalKit",
    "LoadStandard",
    "Offset",
    "OpenStandard",
    "ShortStandard",
    "offset_reflection",
]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: The order of :meth:`CalKit.reflections`: the order the standards are measured in.
STANDARD_NAMES = ("short", "open", "load")
REFERENCE_OHM = 50.0
_GHZ = 1e9
_CAPACITANCE_UNITS = (1e-15, 1e-27, 1e-36, 1e-45)  # C0 fF, C1 1e-27 F/Hz, ...
_INDUCTANCE_UNITS = (1e-12, 1e-24, 1e-33, 1e-42)  # L0 pH, L1 1e-24 H/Hz, ...


@dataclass(frozen=True)
class Offset:
    """The offset transmission line in front of a standard's termination (K1-K4).

    ``delay_s`` is the one-way delay, ``loss_gohm_per_s`` the offset loss at 1 GHz in
    Gohm/s (as on Keysight data sheets), ``z0_ohm`` the offset's (lossless) impedance.
    """

    delay_s: float = 0.0
    loss_gohm_per_s: float = 0.0
    z0_ohm: float = REFERENCE_OHM

    def __post_init__(self) -> None:
        if not (np.isfinite(self.delay_s) and np.isfinite(self.loss_gohm_per_s)):
            raise InvalidDataError(f"offset delay and loss must be finite: {self}")
        if self.loss_gohm_per_s < 0 or not self.z0_ohm > 0:
            raise InvalidDataError(f"offset loss must be >= 0 and Z0 > 0: {self}")

    @property
    def is_flush(self) -> bool:
        """No offset at all: the termination sits at the reference plane."""
        return self.delay_s == 0 and self.loss_gohm_per_s == 0


def offset_reflection(
    freq_hz: ArrayLike,
    termination: ArrayLike,
    offset: Offset,
    z_ref_ohm: float = REFERENCE_OHM,
) -> ComplexArray:
    """Reflection ``G`` (K8) of a termination of reflection ``GT`` (K7) behind ``offset``.

    ``termination`` is ``GT`` relative to ``z_ref_ohm`` (not an impedance), broadcast
    against ``freq_hz``. A flush offset returns ``GT`` unchanged.
    """
    f = _frequencies(freq_hz, offset)
    gt = np.asarray(termination, dtype=complex)
    if offset.is_flush:
        return np.asarray(np.broadcast_to(gt, np.broadcast_shapes(gt.shape, f.shape)) + 0j)
    omega = 2 * np.pi * f
    loss = offset.loss_gohm_per_s * _GHZ  # ohm/s
    root = np.sqrt(f / _GHZ)
    alpha_l = loss * offset.delay_s * root / (2 * offset.z0_ohm)  # (K1)
    gamma_l = alpha_l + 1j * (omega * offset.delay_s + alpha_l)  # (K2), (K3)
    zc: complex | ComplexArray = offset.z0_ohm + 0j
    if loss:
        zc = offset.z0_ohm + (1 - 1j) * loss * root / (2 * omega)  # (K4)
    g1 = (zc - z_ref_ohm) / (zc + z_ref_ohm)  # (K7)
    e = np.exp(-2 * gamma_l)
    numerator = g1 * (1 - e - g1 * gt) + e * gt  # (K8)
    denominator = 1 - g1 * (e * g1 + gt * (1 - e))
    return np.asarray(numerator / denominator, dtype=complex)


def _polynomial(
    freq_hz: ArrayLike, coefficients: tuple[float, ...], units: tuple[float, ...]
) -> FloatArray:
    """A data sheet's cubic in frequency, its coefficients in their units, in SI."""
    coef = [c * u for c, u in zip(coefficients, units, strict=True)]
    return np.asarray(np.polynomial.polynomial.polyval(np.asarray(freq_hz, float), coef))


@dataclass(frozen=True)
class OpenStandard:
    """An open: fringing capacitance ``C(f)`` (K5) behind an offset."""

    c0: float = 0.0
    """fF."""
    c1: float = 0.0
    """1e-27 F/Hz."""
    c2: float = 0.0
    """1e-36 F/Hz^2."""
    c3: float = 0.0
    """1e-45 F/Hz^3."""
    offset: Offset = field(default_factory=Offset)

    def capacitance_f(self, freq_hz: ArrayLike) -> FloatArray:
        """``C(f)`` in farads."""
        return _polynomial(freq_hz, (self.c0, self.c1, self.c2, self.c3), _CAPACITANCE_UNITS)

    def reflection(self, freq_hz: ArrayLike, z_ref_ohm: float = REFERENCE_OHM) -> ComplexArray:
        """Actual reflection: ``GT = (1 - j omega C Zr) / (1 + j omega C Zr)`` (K5, K7), K8."""
        f = _frequencies(freq_hz, self.offset)
        wcz = 2j * np.pi * f * self.capacitance_f(f) * z_ref_ohm
        return offset_reflection(f, (1 - wcz) / (1 + wcz), self.offset, z_ref_ohm)


@dataclass(frozen=True)
class ShortStandard:
    """A short: residual inductance ``L(f)`` (K6) behind an offset."""

    l0: float = 0.0
    """pH."""
    l1: float = 0.0
    """1e-24 H/Hz."""
    l2: float = 0.0
    """1e-33 H/Hz^2."""
    l3: float = 0.0
    """1e-42 H/Hz^3."""
    offset: Offset = field(default_factory=Offset)

    def inductance_h(self, freq_hz: ArrayLike) -> FloatArray:
        """``L(f)`` in henries."""
        return _polynomial(freq_hz, (self.l0, self.l1, self.l2, self.l3), _INDUCTANCE_UNITS)

    def reflection(self, freq_hz: ArrayLike, z_ref_ohm: float = REFERENCE_OHM) -> ComplexArray:
        """Actual reflection: ``GT = (j omega L - Zr) / (j omega L + Zr)`` (K6, K7), K8."""
        f = _frequencies(freq_hz, self.offset)
        jwl = 2j * np.pi * f * self.inductance_h(f)
        return offset_reflection(f, (jwl - z_ref_ohm) / (jwl + z_ref_ohm), self.offset, z_ref_ohm)


@dataclass(frozen=True)
class LoadStandard:
    """A load: resistance ``R`` behind an (optional) offset."""

    resistance_ohm: float = REFERENCE_OHM
    offset: Offset = field(default_factory=Offset)

    def reflection(self, freq_hz: ArrayLike, z_ref_ohm: float = REFERENCE_OHM) -> ComplexArray:
        """Actual reflection: ``GT = (R - Zr) / (R + Zr)`` (K7), K8."""
        gt = (self.resistance_ohm - z_ref_ohm) / (self.resistance_ohm + z_ref_ohm)
        f = _frequencies(freq_hz, self.offset)
        return offset_reflection(f, np.full(f.shape, gt, dtype=complex), self.offset, z_ref_ohm)


@dataclass(frozen=True)
class CalKit:
    """A short-open-load kit as Keysight describes one; ``z_ref_ohm`` the system impedance."""

    short: ShortStandard = field(default_factory=ShortStandard)
    open: OpenStandard = field(default_factory=OpenStandard)
    load: LoadStandard = field(default_factory=LoadStandard)
    z_ref_ohm: float = REFERENCE_OHM
    name: str = ""

    def reflections(self, freq_hz: ArrayLike) -> ComplexArray:
        """Actual reflections, shape ``(3,) + freq.shape``, in :data:`STANDARD_NAMES` order.

        The ``actual`` argument of :func:`calibration.rf.one_port.solve_one_port`.
        """
        f = np.asarray(freq_hz, dtype=float)
        standards = (self.short, self.open, self.load)
        return np.stack([s.reflection(f, self.z_ref_ohm) for s in standards])


#: Short ``-1``, open ``+1``, load ``0`` at every frequency, exactly.
IDEAL_KIT = CalKit(name="ideal")


def _frequencies(freq_hz: ArrayLike, offset: Offset) -> FloatArray:
    f = np.asarray(freq_hz, dtype=float)
    if not np.all(np.isfinite(f)) or np.any(f < 0):
        raise InvalidDataError("calibration-kit frequencies must be finite and >= 0")
    if offset.loss_gohm_per_s and np.any(f == 0):
        raise InvalidDataError("a lossy offset (K4) is undefined at 0 Hz")
    return f
