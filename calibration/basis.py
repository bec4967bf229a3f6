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
