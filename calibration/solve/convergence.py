"""When the radiometric solver's Gauss-Newton iteration has converged, and a damped step.

The solver (:mod:`calibration.solve.radiometric_solver`) linearises Q's likelihood about an
operating point ``theta_k`` (five parameter curves) and solves the linear problem for the
next, ``theta_{k+1}``. It has converged when a step moves no parameter curve by more than
a small fraction of its own posterior sd anywhere in the band::

    Delta_k = max_{p, f} |theta_{k+1, p}(f) - theta_{k, p}(f)| / sigma_p(f)  <  TOLERANCE

with ``sigma_p(f)`` the sd of parameter ``p`` at channel ``f`` under the linearised
problem's posterior at the largest model, ``sqrt(diag(B_p A_pp^-1 B_p^T))`` for
``A = G + diag(ridge)`` (eq. 3.35's covariance, :mod:`calibration.regression.conjugate`). The
criterion is in the units the answer is judged in: a step below it moves the calibrated
temperatures by a negligible fraction of their error bars.

Gauss-Newton overshoots where the start is far from the solution and T_NS is weakly
pinned (calibrators spanning a few kelvin: the contrast that sets T_NS is small); a step
that increases the misfit ::

    chi2(theta) = sum_if w_if (X_L T_NS0 (Q_if - Q_if(theta)))^2         (eq. 3.27 in Q)

(weights and gain of the current linearisation, so steps are compared on one scale) is
halved until it does not, or keeps T_NS positive. With the hot load among the
calibrators two steps converge; with eight of REACH's twelve at ambient temperatures
spread over ~2 K, two steps left the error 2-7x the noise floor at full resolution,
while the iteration to this criterion brings it to the floor
(``tests/test_solver_convergence.py``, ``benchmarks/calibrator_subsets.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..model.noise_waves import INDEX, DesignTerms, model_q
from ..model.polynomial_model import Orders, coefficient_slices
from ..regression.normal_equations import NormalEquations

FloatArray = NDArray[np.float64]

#: Largest parameter change over its posterior sd at which the iteration has converged.
TOLERANCE = 1e-3
#: Gauss-Newton steps at most (a converging run needs 2-6).
MAX_STEPS = 30
#: Halvings of a step that increases the misfit, at most.
MAX_HALVINGS = 20


@dataclass
class Convergence:
    """What the iteration did (for the last box the solver fitted).

    The steps taken, the last change, the halvings, and whether it met :data:`TOLERANCE`.
    """

    steps: int = 0
    change: float = float("inf")
    halvings: int = 0
    converged: bool = False
    history: list[float] = field(default_factory=list)

    def metadata(self) -> dict[str, object]:
        """The solution's ``metadata["convergence"]``."""
        return {
            "steps": self.steps,
            "change": float(f"{self.change:.3g}"),
            "criterion": f"max |d theta| / posterior sd < {TOLERANCE:g}",
            "halvings": self.halvings,
            "converged": self.converged,
        }

    def warning(self) -> str | None:
        """The sentence a user reads when the fit did not converge (``None`` if it did)."""
        if self.converged:
            return None
        return (
            f"the fit did not converge: after {self.steps} Gauss-Newton steps a step still "
            f"moved a parameter by {self.change:.2g} of its error bar (criterion "
            f"{TOLERANCE:g}); the solution and its error bars are not reliable: add a "
            "calibrator at another temperature (e.g. the hot load) or lower --max-orders"
        )


def curve_std(
    normal: NormalEquations, ridge: FloatArray, basis: FloatArray, largest: Orders
) -> FloatArray:
    """Posterior sd ``(5, n_channels)`` of each parameter curve at the largest model."""
    a = normal.gram + np.diag(ridge)
    scale = np.sqrt(np.maximum(np.diag(a), 1e-300))
    cov = np.linalg.pinv(a / np.outer(scale, scale), hermitian=True) / np.outer(scale, scale)
    out = np.zeros((len(largest), basis.shape[0]))
    for k, s in enumerate(coefficient_slices(largest)):
        b = basis[:, : s.stop - s.start]
        out[k] = np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", b, cov[s, s], b), 0.0))
    return out


def relative_change(new: FloatArray, old: FloatArray, std: FloatArray) -> float:
    """``Delta`` of the module docstring."""
    floor = 1e-12 * np.maximum(np.abs(old), 1.0)  # a parameter the data fix exactly
    return float(np.max(np.abs(new - old) / np.maximum(std, floor)))


def misfit(
    theta: FloatArray, terms: DesignTerms, temps: FloatArray, q: FloatArray,
    weights: FloatArray, gain: FloatArray,
) -> float:
    """``chi2(theta)`` of the module docstring (``inf`` where T_NS is not positive)."""
    if np.any(theta[INDEX["NS"]] <= 0):
        return float("inf")
    r = gain * (q - model_q(theta, terms, temps))
    return float(np.sum(weights * r * r))


class ChiSquare:
    """``misfit`` bound to one linearisation's weights and gain."""

    def __init__(
        self, terms: DesignTerms, temps: FloatArray, q: FloatArray, weights: FloatArray,
        gain: FloatArray,
    ) -> None:
        self.args = (terms, temps, q, weights, gain)

    def __call__(self, theta: FloatArray) -> float:
        """``chi2(theta)``."""
        return misfit(theta, *self.args)


def damped(
    old: FloatArray, proposal: FloatArray, objective: Convergence,
    chi2: ChiSquare,
) -> FloatArray:
    """``old + alpha (proposal - old)``, halving ``alpha`` from 1 while the misfit rises.

    A step is also halved while it takes T_NS to zero or below anywhere (no operating
    point there: Q's model divides by it); if none is found, ``old`` is kept.
    """
    base = chi2(old)
    step = proposal - old
    alpha = 1.0
    for _ in range(MAX_HALVINGS):
        trial = old + alpha * step
        positive = bool(np.all(trial[INDEX["NS"]] > 0))
        if positive and chi2(trial) <= base * (1.0 + 1e-12) + 1e-9:
            return trial
        alpha *= 0.5
        objective.halvings += 1
    trial = old + alpha * step
    return trial if np.all(trial[INDEX["NS"]] > 0) else old
