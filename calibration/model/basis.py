"""Polynomial bases for frequency-dependent noise-wave parameters.

Each noise-wave parameter is a polynomial in frequency (thesis eqs. 3.39-3.40)::

    T_i(nu) = sum_{k=0}^{n_i - 1} c_{ik} B_k(nu)

The thesis uses powers of ``nu / nu_0`` (eq. 3.40). Powers are badly conditioned beyond a
few terms, so the default here is Legendre polynomials of ``x``, the frequency mapped
linearly onto [-1, 1] over the band. Both span the same space, so a solution at given
orders does not depend on the basis, only its coefficients do.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

BasisKind = Literal["legendre", "power"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PolynomialBasis:
    """A polynomial basis on a frequency band.

    Parameters
    ----------
    kind
        ``"legendre"``: Legendre polynomials ``P_k(x)`` with
        ``x = (2 nu - nu_lo - nu_hi) / (nu_hi - nu_lo)``. ``"power"``: the thesis's
        ``(nu / nu_0)^k`` (eq. 3.40) with ``nu_0 = nu_hi``.
    f_lo_hz, f_hi_hz
        Band edges defining the mapping (need not be the data's extreme channels).
    """

    kind: BasisKind
    f_lo_hz: float
    f_hi_hz: float

    def __post_init__(self) -> None:
        if self.kind not in ("legendre", "power"):
            raise ValueError(f"unknown basis kind {self.kind!r}: use 'legendre' or 'power'")
        if not self.f_hi_hz > self.f_lo_hz > 0:
            raise ValueError("basis band needs 0 < f_lo_hz < f_hi_hz")

    @classmethod
    def for_frequencies(cls, freq_hz: FloatArray, kind: BasisKind = "legendre") -> PolynomialBasis:
        """Basis whose band is the span of ``freq_hz``."""
        return cls(kind, float(np.min(freq_hz)), float(np.max(freq_hz)))

    def normalised(self, freq_hz: FloatArray) -> FloatArray:
        """The basis variable: ``x`` in [-1, 1] (Legendre) or ``nu / nu_0`` (power)."""
        f = np.asarray(freq_hz, dtype=float)
        if self.kind == "power":
            return f / self.f_hi_hz
        return (2.0 * f - self.f_lo_hz - self.f_hi_hz) / (self.f_hi_hz - self.f_lo_hz)

    def matrix(self, freq_hz: FloatArray, n_terms: int) -> FloatArray:
        """Basis functions evaluated at ``freq_hz``: shape ``(len(freq_hz), n_terms)``."""
        if n_terms < 0:
            raise ValueError("n_terms must be >= 0")
        x = self.normalised(freq_hz)
        if self.kind == "power":
            return x[:, None] ** np.arange(n_terms)
        return np.asarray(np.polynomial.legendre.legvander(x, max(n_terms - 1, 0))[:, :n_terms])


@dataclass(frozen=True)
class DelayBasis(PolynomialBasis):
    """Polynomials followed by delay (Fourier) terms: structure a polynomial cannot hold.

    A noise wave seen through a line of delay ``tau`` rotates with frequency (thesis
    section 3.1: the correlated noise ``T_cos``, ``T_sin`` are the real and imaginary
    parts of a wave whose phase runs as ``2 pi nu tau``), and a reflection along a cable
    adds a ripple of that period to every noise wave. Columns ``0..K-1`` are this
    band's polynomials (``K = polynomial_terms``), then for each delay ``tau_d``::

        cos(2 pi (nu - nu_c) tau_d),  sin(2 pi (nu - nu_c) tau_d)

    with ``nu_c`` the band's centre. A parameter with ``n <= K`` terms is a polynomial; one
    with ``K + 2 d`` terms carries the first ``d`` delays as well
    (:mod:`calibration.solve.delay_terms` chooses them).
    """

    polynomial_terms: int = 0
    delays_s: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.polynomial_terms < 1 or not self.delays_s:
            raise ValueError("a delay basis needs polynomial_terms >= 1 and one delay or more")
        if not all(np.isfinite(d) and d > 0 for d in self.delays_s):
            raise ValueError(f"delays must be finite and > 0 s: {self.delays_s}")

    @property
    def n_terms(self) -> int:
        """Columns of the whole basis: the polynomials and two per delay."""
        return self.polynomial_terms + 2 * len(self.delays_s)

    def matrix(self, freq_hz: FloatArray, n_terms: int) -> FloatArray:
        """The first ``n_terms`` columns at ``freq_hz``: ``(len(freq_hz), n_terms)``."""
        if n_terms > self.n_terms:
            raise ValueError(f"{n_terms} terms asked of a delay basis of {self.n_terms}")
        poly = super().matrix(freq_hz, min(n_terms, self.polynomial_terms))
        if n_terms <= self.polynomial_terms:
            return poly
        f = np.asarray(freq_hz, dtype=float) - 0.5 * (self.f_lo_hz + self.f_hi_hz)
        phases = 2.0 * np.pi * f[:, None] * np.asarray(self.delays_s)[None, :]
        waves = np.stack([np.cos(phases), np.sin(phases)], axis=-1).reshape(f.size, -1)
        return np.concatenate([poly, waves[:, : n_terms - self.polynomial_terms]], axis=1)
