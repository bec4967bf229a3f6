"""The radiometric solver's Gauss-Newton rows: Q's likelihood linearised about an estimate.

About a current estimate ``Theta_0`` (``Q_0 = Q(Theta_0)``, eq. 3.27 solved for Q) one
Gauss-Newton step is a weighted linear regression in the thesis's own variables
(:mod:`calibration.solve.radiometric_solver` derives it)::

    y_if = T_i - X_L T_NS0 (Q_if - Q0_if)
    x_if = (X_unc, X_cos, X_sin, Q0_if X_L, X_L)
    w_if = 1 / ((X_L T_NS0)^2 var(Q_if) + e_if)

with ``e_if`` the reflections' error in kelvin (:mod:`calibration.model.reflection_noise`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..core.errors import IllPosedError
from ..model.noise_waves import INDEX, DesignTerms, model_q

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LinearisedProblem:
    """Rows of the Gauss-Newton regression about a parameter estimate (module docstring)."""

    features: FloatArray
    weights: FloatArray
    response: FloatArray


def linearise(
    terms: DesignTerms,
    temps: FloatArray,
    q: FloatArray,
    var_q: FloatArray,
    theta0: FloatArray,
    extra_variance_k2: FloatArray | float = 0.0,
) -> LinearisedProblem:
    """Gauss-Newton rows about ``theta0`` (``(5, n_channels)`` parameter curves).

    ``extra_variance_k2`` is added to each row's variance in kelvin (the reflection's
    error, :mod:`calibration.model.reflection_noise`).
    """
    t_ns0 = theta0[INDEX["NS"]]
    if np.any(t_ns0 <= 0):
        raise IllPosedError(
            "cannot linearise about T_NS <= 0 K: the operating point needs a positive "
            "noise-source temperature at every channel"
        )
    q0 = model_q(theta0, terms, temps)
    gain = terms.x_l * t_ns0
    return LinearisedProblem(
        features=terms.matrix(q0),
        weights=1.0 / (gain**2 * var_q + extra_variance_k2),
        response=temps - gain * (q - q0),
    )
