"""A slow drift of the simulated LNA's noise waves with its temperature (issue 39, item 5).

Off unless :class:`~reach_receiver.sim.physics.PhysicsConfig` is given a
:class:`NoiseWaveDrift`: every simulation without one is unchanged.

An amplifier's noise comes mostly from its transistors' thermal noise, so its noise
temperature grows about in proportion to its physical temperature (Pozar, *Microwave
Engineering*, 4th ed., 10.1: ``T_e`` of a device scales with ``T_0``). The LNA's noise
waves (thesis 3.1: ``T_unc``, ``T_cos``, ``T_sin``, eqs. 3.12-3.13) are therefore taken as

    T_i(f, t) = T_i(f) * (1 + per_k * (T_LNA(t) - T_ref)),     i in unc, cos, sin,

with ``per_k = 1 / 300 K`` by default (proportional at 300 K), and the LNA's temperature

    T_LNA(t) = T_encl(t) + lna_above_enclosure_k
               + min(ramp_k_per_day * max(t - t_start, 0) / 1 d, limit_k),

the enclosure's temperature plus the LNA's own heating plus a slow ramp from ``start_s``
after the simulation starts (a heat sink coming loose, a connector warming), which stops
after ``limit_k`` (never, by default). ``T_L`` and
``T_NS`` (the reference load and the noise diode, in the enclosure) do not drift. The
thermocouple on the LNA (TC-08 port 7) and the LNA board's sensor (MCP9808 0x1A) read
``T_LNA``: the monitor sees the warming that the calibration drift check then flags.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

DAY_S = 86400.0


@dataclass(frozen=True)
class NoiseWaveDrift:
    """The LNA's temperature ramp and how its noise waves follow it (module docstring)."""

    ramp_k_per_day: float = 0.0
    per_k: float = 1.0 / 300.0
    start_s: float = 0.0
    reference_c: float = 27.0
    limit_k: float = math.inf

    def ramp_k(self, elapsed_s: float) -> float:
        """The ramp's share of the LNA's temperature ``elapsed_s`` after the start (K)."""
        ramp = self.ramp_k_per_day * max(elapsed_s - self.start_s, 0.0) / DAY_S
        return min(ramp, self.limit_k)

    def factor(self, lna_c: float) -> float:
        """``1 + per_k (T_LNA - T_ref)``: the noise waves' scale at the LNA's temperature."""
        return 1.0 + self.per_k * (lna_c - self.reference_c)

    def theta(self, theta: FloatArray, lna_c: float) -> FloatArray:
        """The parameters ``(5, n)`` with the noise waves (rows 0-2) scaled for ``lna_c``."""
        out = np.array(theta, dtype=float, copy=True)
        out[:3] *= self.factor(lna_c)
        return out
