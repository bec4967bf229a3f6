"""The receiver's channel grid and an S11 sweep carried onto it.

Both the receiver's hand-over to the engine (``reach_receiver/store/handover.py``) and the
archive's re-calibration (:mod:`calibration.season.recalibrate`) turn a run file's raw
records into the engine's inputs the same way: the band's channels of the iTPM's grid
(channel ``k`` centred at ``k * channel_width_hz``), and each source's VNA sweep
interpolated onto them, Re and Im by cubic splines (the REACH sources' reflections are
smooth on the VNA's grid; ``tests/test_s11_interpolation_real.py`` measures the error on
EDGES-3's sweeps).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["band_channels", "interpolate_s11"]


def band_channels(channel_width_hz: float, band_hz: tuple[float, float]) -> slice:
    """Channels ``k`` whose centres ``k * channel_width_hz`` lie in ``band_hz`` (1e-9 slack)."""
    first = math.ceil(band_hz[0] / channel_width_hz - 1e-9)
    last = math.floor(band_hz[1] / channel_width_hz + 1e-9)
    return slice(first, last + 1)


def interpolate_s11(
    freq_s11: NDArray[Any], s11: NDArray[Any], freq_hz: NDArray[Any]
) -> NDArray[np.complex128] | None:
    """The reflection at ``freq_hz``; ``None`` when the sweep does not cover them."""
    from scipy.interpolate import CubicSpline
    f_s11 = np.asarray(freq_s11, dtype=float)
    f = np.asarray(freq_hz, dtype=float)
    if f_s11.size < 4 or f.min() < f_s11[0] or f.max() > f_s11[-1]:
        return None
    gamma = np.asarray(s11, dtype=complex)
    real = CubicSpline(f_s11, gamma.real)(f)
    imag = CubicSpline(f_s11, gamma.imag)(f)
    return np.asarray(real + 1j * imag, dtype=complex)
