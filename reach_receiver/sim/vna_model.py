"""One-port error model of the simulated VNA.

The port sees a true reflection ``G(f)``; the raw reading passes it through the one-port
error model (Pozar, *Microwave Engineering*, 4th ed., sec. 4.6; scikit-rf's ``OnePort``)::

    m = e00 + e10e01 G / (1 - e11 G)

with directivity ``e00``, source match ``e11`` and reflection tracking ``e10e01``.
:class:`ErrorModel` makes these terms smooth, seeded complex functions of frequency that
drift with time. The model itself, its solution from measured standards and the
correction are the calibration engine's (:mod:`calibration.rf.one_port`), so the simulated
instrument and offline calibration share one implementation.
:func:`sweep_duration_s` gives the simulated sweep time. No I/O: the SCPI server is
:class:`reach_receiver.sim.vna.VnaSimulator`, which re-exports these names.
"""

from __future__ import annotations

import threading

import numpy as np
from numpy.typing import NDArray

from calibration.rf.one_port import OnePortTerms

ComplexArray = NDArray[np.complex128]


def sweep_duration_s(points: int, averages: int, ifbw_hz: float) -> float:
    """Simulated sweep time: one IF-bandwidth reciprocal per point and average."""
    return points * averages / ifbw_hz


def _smooth(coef: ComplexArray, x: NDArray[np.float64]) -> ComplexArray:
    """A complex polynomial in ``x`` in [-1, 1] bounded by 1 in magnitude."""
    weights = coef / np.arange(1, coef.size + 1)
    return np.polynomial.polynomial.polyval(x, weights) / np.sum(np.abs(weights))


class ErrorModel:
    """Directivity ``e00``, source match ``e11`` and tracking ``e10e01`` of the port, drifting.

    Each term is ``A exp(-2 pi i f tau) (1 + a s(f)) (1 + d(t) s'(f))`` with seeded smooth
    shapes ``s``, ``s'`` (|s| <= 1 over 0.3 MHz-1.3 GHz) and ``d(t) = rate (t - t0) +``
    forced drift: about -30 dB directivity, -20 dB source match, 0.8 tracking.
    """

    _AMPLITUDE = (10 ** (-30 / 20), 10 ** (-20 / 20), 0.8)
    _DELAY_S = (0.2e-9, 0.8e-9, 4e-9)
    _RIPPLE = (0.3, 0.3, 0.1)

    def __init__(self, seed: int, drift_rate_per_s: float, t0: float) -> None:
        rng = np.random.default_rng((seed, 1))
        self._shape = rng.normal(size=(3, 4)) + 1j * rng.normal(size=(3, 4))
        self._drift_shape = rng.normal(size=(3, 4)) + 1j * rng.normal(size=(3, 4))
        self.drift_rate_per_s = drift_rate_per_s
        self._t0 = t0
        self._forced = 0.0
        self._lock = threading.Lock()

    def drift_now(self, amount: float) -> None:
        """Add ``amount`` to the fractional drift at once."""
        with self._lock:
            self._forced += amount

    def drift(self, t: float) -> float:
        """Fractional drift ``d(t)`` of the error terms at clock time ``t``."""
        with self._lock:
            return self.drift_rate_per_s * (t - self._t0) + self._forced

    def terms(self, freq_hz: NDArray[np.float64], t: float) -> OnePortTerms:
        """``(e00, e11, e10e01)`` at ``freq_hz`` and clock time ``t``."""
        x = (np.asarray(freq_hz) - 650e6) / 650e6
        d = self.drift(t)
        out = []
        for i in range(3):
            base = self._AMPLITUDE[i] * np.exp(-2j * np.pi * freq_hz * self._DELAY_S[i])
            base = base * (1 + self._RIPPLE[i] * _smooth(self._shape[i], x))
            out.append(base * (1 + d * _smooth(self._drift_shape[i], x)))
        return OnePortTerms(out[0], out[1], out[2])

    def measure(self, freq_hz: NDArray[np.float64], truth: ComplexArray, t: float) -> ComplexArray:
        """Noise-free raw reading ``m = e00 + e10e01 G / (1 - e11 G)``."""
        return self.terms(freq_hz, t).embed(truth)
