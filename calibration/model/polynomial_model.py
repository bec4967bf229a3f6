"""Noise-wave parameters as polynomials: coefficient layout and evaluation.

The five parameters (order :data:`~calibration.model.noise_waves.PARAMETERS`) each have their own
number of terms ``n = (n_unc, n_cos, n_sin, n_NS, n_L)`` (thesis eq. 3.39). Their
coefficients are concatenated into one vector ``c`` of length ``sum(n)``; the design row
of source ``i`` at channel ``f`` is the Kronecker-like product of its five design terms
with the basis functions (eq. 3.40)::

    T_i(f) = sum_k X_k(i, f) sum_j c_kj B_j(f)
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .basis import PolynomialBasis
from .noise_waves import N_PARAMETERS, PARAMETERS

FloatArray = NDArray[np.float64]
Orders = tuple[int, int, int, int, int]


def as_orders(orders: Sequence[int]) -> Orders:
    """Validate a sequence of five term counts (each >= 0)."""
    values = tuple(int(n) for n in orders)
    if len(values) != N_PARAMETERS or any(n < 0 for n in values):
        raise ValueError(
            f"orders must be {N_PARAMETERS} term counts >= 0 for {PARAMETERS}, got {orders}"
        )
    return values  # type: ignore[return-value]


def coefficient_slices(orders: Sequence[int]) -> list[slice]:
    """Slice of each parameter's coefficients in the concatenated vector."""
    edges = np.concatenate([[0], np.cumsum(orders)])
    return [slice(int(a), int(b)) for a, b in itertools.pairwise(edges)]


def full_indices(orders: Sequence[int], max_orders: Sequence[int]) -> NDArray[np.intp]:
    """Positions of an ``orders`` model's coefficients inside a ``max_orders`` vector.

    Read-only and cached: the order search asks for the same few hundred per solve.
    """
    return _full_indices(tuple(map(int, orders)), tuple(map(int, max_orders)))


@functools.lru_cache(maxsize=4096)
def _full_indices(orders: tuple[int, ...], max_orders: tuple[int, ...]) -> NDArray[np.intp]:
    starts = np.concatenate([[0], np.cumsum(max_orders)[:-1]])
    idx = np.concatenate(
        [np.arange(s, s + n) for s, n in zip(starts, orders, strict=True)]
    ).astype(np.intp)
    idx.flags.writeable = False
    return idx


def design_rows(
    features: FloatArray, basis_matrix: FloatArray, orders: Sequence[int]
) -> FloatArray:
    """Full design matrix rows: ``features (..., n_ch, 5)`` x basis ``(n_ch, n_max)``.

    Returns ``(..., n_ch, sum(orders))``. Only used for small problems and for applying a
    solution to one source; the solvers never form the full matrix for all calibrators.
    """
    blocks = [features[..., k : k + 1] * basis_matrix[:, :n] for k, n in enumerate(orders)]
    return np.concatenate(blocks, axis=-1)


@dataclass(frozen=True)
class PolynomialParameters:
    """Coefficients of the five noise-wave polynomials on a basis."""

    basis: PolynomialBasis
    orders: Orders
    coefficients: FloatArray

    def __post_init__(self) -> None:
        object.__setattr__(self, "orders", as_orders(self.orders))
        coeffs = np.asarray(self.coefficients, dtype=float)
        if coeffs.shape[-1] != sum(self.orders):
            raise ValueError(
                f"{coeffs.shape[-1]} coefficients for orders {self.orders} "
                f"(need {sum(self.orders)})"
            )
        object.__setattr__(self, "coefficients", coeffs)

    @property
    def n_max(self) -> int:
        """Largest number of terms of any parameter."""
        return max(self.orders)

    def evaluate(self, freq_hz: FloatArray) -> FloatArray:
        """Parameter values ``(..., 5, n_channels)`` at ``freq_hz`` (K)."""
        b = self.basis.matrix(np.asarray(freq_hz, dtype=float), self.n_max)
        out = [
            self.coefficients[..., s] @ b[:, : s.stop - s.start].T
            for s in coefficient_slices(self.orders)
        ]
        return np.stack(out, axis=-2)

    def truncated(self, orders: Sequence[int]) -> PolynomialParameters:
        """The leading ``orders[k]`` terms of each parameter (a sub-model of these orders)."""
        orders = as_orders(orders)
        if any(n > m for n, m in zip(orders, self.orders, strict=True)):
            raise ValueError(f"orders {orders} exceed the parameters' {self.orders}")
        kept = [self.coefficients[..., s.start : s.start + n]
                for s, n in zip(coefficient_slices(self.orders), orders, strict=True)]
        return PolynomialParameters(self.basis, orders, np.concatenate(kept, axis=-1))

    def per_parameter(self) -> dict[str, FloatArray]:
        """Coefficients of each parameter by name."""
        return {
            name: self.coefficients[..., s]
            for name, s in zip(PARAMETERS, coefficient_slices(self.orders), strict=True)
        }
