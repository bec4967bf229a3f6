"""Where to look for a ripple: delays proposed by periodograms of a fit's residuals.

Used by :mod:`calibration.solve.delay_terms` (step 2 of its docstring). Two views of the
residual about curves ``theta``: the Gauss-Newton rows' (``sum_i |FFT_f(w_i r_i)|^2``,
each calibrator's rows weighted by the radiometer noise) and the noise waves' own,
solved channel by channel. Delays below 1.5 / band are left to the polynomials.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from .delay_terms import Rows

FloatArray = NDArray[np.float64]
#: Periodogram peaks proposed per view.
CANDIDATES = 3


def candidate_delays(
    rows: Rows, theta: FloatArray, freq_hz: FloatArray, exclude: tuple[float, ...] = ()
) -> list[float]:
    """Delays (s) of the residuals' largest periodogram peaks (module docstring)."""
    residual = rows.response - np.einsum("mnk,kn->mn", rows.features, theta)
    u = rows.weights * residual
    return _peaks(u / np.sqrt(np.sum(rows.weights, axis=1, keepdims=True)), freq_hz, exclude)


def parameter_candidates(
    rows: Rows, theta: FloatArray, freq_hz: FloatArray, exclude: tuple[float, ...] = ()
) -> list[float]:
    """Delays (s) of the largest periodogram peaks of the residual *noise waves*.

    A ripple on ``T_cos`` reaches calibrator ``i``'s rows through ``X_cos``, whose phase
    turns with that calibrator's own cable, so the rows' periodogram peaks at the sums
    and differences of the two delays (a 50 ns ripple was proposed at 28 and 128 ns).
    Solved channel by channel for the five parameters (``M >= 5`` calibrators), the
    residual is the parameters' own: each parameter's residual curve, scaled by its
    median sd over channels (a constant, which does not modulate it), proposes delays.
    ``[]`` with fewer than five calibrators.
    """
    f, w = rows.features, rows.weights
    if f.shape[0] < f.shape[2]:
        return []
    residual = rows.response - np.einsum("mnk,kn->mn", f, theta)
    gram = np.einsum("mnk,mn,mnl->nkl", f, w, f)
    rhs = np.einsum("mnk,mn->nk", f, w * residual)
    try:
        delta = np.linalg.solve(gram, rhs[..., None])[..., 0]  # (N, 5)
        sd = np.sqrt(np.abs(np.diagonal(np.linalg.inv(gram), axis1=1, axis2=2)))
    except np.linalg.LinAlgError:
        return []
    scale = np.median(sd, axis=0)
    return _peaks((delta / np.where(scale > 0, scale, 1.0)).T, freq_hz, exclude)


def _peaks(u: FloatArray, freq_hz: FloatArray, exclude: tuple[float, ...]) -> list[float]:
    """The :data:`CANDIDATES` largest peaks of ``sum_i |FFT(u_i)|^2`` over delay."""
    n = u.shape[1]
    pad = 8 * n
    power = np.sum(np.abs(np.fft.rfft(u, n=pad, axis=1)) ** 2, axis=0)
    step = float(np.median(np.diff(freq_hz)))
    delays = np.fft.rfftfreq(pad, d=step)
    band = float(freq_hz[-1] - freq_hz[0])
    resolution = 1.0 / band
    power[delays < 1.5 * resolution] = 0.0
    for d in exclude:
        power[np.abs(delays - d) < resolution] = 0.0
    found: list[float] = []
    for _ in range(CANDIDATES):
        k = int(np.argmax(power))
        if power[k] <= 0:
            break
        found.append(float(delays[k]))
        power[np.abs(delays - delays[k]) < resolution] = 0.0
    return found


def union(lists: list[list[float]], resolution: float) -> list[float]:
    """The candidates of every list, in turn, those within ``resolution`` of one kept once."""
    out: list[float] = []
    for group in lists:
        for tau in group:
            if all(abs(tau - t) >= resolution for t in out):
                out.append(tau)
    return out
