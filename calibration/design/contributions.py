"""Which calibrators earn their time, and the times a target error needs.

From one solution's :class:`~calibration.design.information.AntennaInformation`
(``V = tr(C A)``, the antenna's predicted mean-square calibration error over the band):

* **share** of calibrator ``i``: its part of ``V = sum_i tr(C A C G_i) / s^2 + (prior)``,
  normalised over the calibrators (:meth:`AntennaInformation.shares`);
* **without it**: ``V_-i = tr((Lambda - G_i / s^2)^-1 A)``, the predicted error had it not
  been measured (``inf`` where the others cannot determine the model);
* **a plan** for a new run of the same receiver: seconds per Dicke position ``T_i`` for
  every calibrator such that ``V(T) = tr((Lambda_0 + sum_i G_i(T_i) / s^2)^-1 A)`` reaches
  the target, ``Lambda_0 = Lambda - sum_i G_i(tau_i) / s^2`` being what the run's
  calibrators did not give (prior, widening). Greedy, as the adaptive step chooses: from
  ``first_pass_s`` each, the addition of a candidate duration to one calibrator that
  most reduces ``V`` per second of instrument time (``3 t``; each calibrator is measured
  once, its overhead paid once), until the target. Beside it, the round-robin: one
  common ``T`` for all (bisection), the same overheads.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .adaptive import POSITIONS, AdaptiveSettings
from .information import AntennaInformation

#: The most greedy additions a plan makes before it gives up on the target.
MAX_PLAN_STEPS = 2000


@dataclass(frozen=True)
class Contribution:
    """One calibrator: its time, its share of the antenna's information, ``V`` without it."""

    source: str
    seconds: float
    share: float
    without_mk: float

    def as_record(self) -> dict[str, object]:
        """Plain data."""
        return {
            "source": self.source, "seconds": self.seconds, "share": round(self.share, 6),
            "without_mk": self.without_mk if np.isfinite(self.without_mk) else None,
        }


def contributions(info: AntennaInformation, kappa: float = 1.0) -> list[Contribution]:
    """Every calibrator's :class:`Contribution` (``kappa`` scales the predicted errors)."""
    shares = info.shares()
    out = []
    for i, name in enumerate(info.names):
        seconds = info.seconds.copy()
        seconds[i] = 0.0
        without = info.variance(info.precision_with(seconds))
        out.append(Contribution(
            name, float(info.seconds[i]), float(shares[i]), 1e3 * kappa * float(np.sqrt(without))
        ))
    return out


@dataclass(frozen=True)
class Plan:
    """Seconds per Dicke position for each calibrator, and what the plan predicts."""

    seconds: dict[str, float]
    instrument_s: float
    predicted_mk: float
    reached: bool
    round_robin_seconds: float  # the common T of the round-robin to the same target
    round_robin_instrument_s: float

    def as_record(self) -> dict[str, object]:
        """Plain data."""
        return {
            "seconds": self.seconds, "instrument_s": self.instrument_s,
            "predicted_mk": self.predicted_mk, "reached": self.reached,
            "round_robin_seconds": self.round_robin_seconds,
            "round_robin_instrument_s": self.round_robin_instrument_s,
        }


def _instrument_s(seconds: Sequence[float] | np.ndarray, overhead_s: float) -> float:
    t = np.asarray(seconds, dtype=float)
    return float(POSITIONS * np.sum(t) + overhead_s * np.count_nonzero(t))


def plan(
    info: AntennaInformation, target_mk: float, settings: AdaptiveSettings | None = None,
    kappa: float = 1.0,
) -> Plan:
    """The times per calibrator for ``target_mk`` (module docstring), within ``budget_s``."""
    s = settings or AdaptiveSettings()
    target = (target_mk / (1e3 * kappa)) ** 2
    n = len(info.names)
    base = info.precision_with(np.zeros(n))

    def variance(seconds: np.ndarray) -> float:
        lam = base.copy()
        for i, t in enumerate(seconds):
            lam += info.gram(i, float(t)) / info.noise_variance
        return info.variance(lam)

    times = np.full(n, s.first_pass_s)
    now = variance(times)
    for _ in range(MAX_PLAN_STEPS):
        if now <= target:
            break
        best: tuple[float, int, float, float] | None = None
        for i in range(n):
            for t in s.durations_s:
                trial = times.copy()
                trial[i] += t
                if _instrument_s(trial, s.overhead_s) > s.budget_s:
                    continue
                v = variance(trial)
                gain = (now - v) / (POSITIONS * t)
                if best is None or gain > best[0]:
                    best = (gain, i, t, v)
        if best is None:
            break
        _, i, t, now = best
        times[i] += t
    rr = _round_robin(variance, n, target, s)
    return Plan(
        seconds={name: float(t) for name, t in zip(info.names, times, strict=True)},
        instrument_s=_instrument_s(times, s.overhead_s),
        predicted_mk=1e3 * kappa * float(np.sqrt(now)),
        reached=bool(now <= target),
        round_robin_seconds=rr,
        round_robin_instrument_s=_instrument_s(np.full(n, rr), s.overhead_s),
    )


def _round_robin(variance: object, n: int, target: float, s: AdaptiveSettings) -> float:
    """The common seconds per position that reach ``target`` (bisection on a log scale)."""
    assert callable(variance)
    lo, hi = s.first_pass_s, s.first_pass_s
    while variance(np.full(n, hi)) > target:
        lo, hi = hi, hi * 2
        if _instrument_s(np.full(n, hi), s.overhead_s) > 1e3 * s.budget_s:
            return float("inf")
    for _ in range(30):
        mid = np.sqrt(lo * hi)
        lo, hi = (mid, hi) if variance(np.full(n, mid)) > target else (lo, mid)
    return float(hi)
