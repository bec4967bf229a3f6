"""Adaptive calibration: the calibrator and duration that most cut the antenna's error per second.

The open problem of thesis 5.1 ("considerations for how to reduce the time needed on
calibration measurements"): every schedule gives each calibrator the same time, however
little it teaches. After each Dicke cycle the engine knows the posterior, so the
predicted calibration error of the antenna (:mod:`calibration.design.information`,
``V = tr(C A)`` over the band of interest) and what ``t`` more seconds on source ``i``
would make of it (``V'_i(t)``, a rank-limited update of the Gram matrix). The planner:

1. a first pass of ``first_pass_s`` per Dicke position over every calibrator
   (:meth:`AdaptivePlanner.first_pass`);
2. then, at each decision, every candidate ``(i, t)`` with ``t`` in ``durations_s`` is
   scored by its reduction of the predicted variance per second of instrument time, a
   Dicke cycle costing its three positions and the switching and settling overhead::

       gain_i(t) = (V - V'_i(t)) / (3 t + overhead_s)          (A-optimal, greedy)

   and the best is measured next;
3. it stops when the predicted RMS error ``sqrt(V)`` reaches ``target_mk`` ("target"),
   or when no candidate fits in what is left of ``budget_s`` ("budget").

The model (orders) is chosen by evidence (the default solve, with model averaging) at the
first decision and every ``refresh_every`` decisions after; between, the posterior is that
of those orders fixed, refitted to the data so far (no model search). At each refresh the
ratio of the averaged solution's predicted error to the fixed model's (``kappa``, the
model-choice part of the error bar) is kept and applied to every prediction until the next,
so that the stop is on the error bar the final, averaged solution reports.

**Honest stopping.** The rule stops on the predicted error, never on the data's residuals:
in a linear-Gaussian model the posterior covariance does not depend on the measured
values, so a stop on it is ancillary, and the final intervals keep their nominal
coverage. The dependence that remains (the noise scale ``s^2``, the linearisation point,
the model choice) is second order; ``python -m benchmarks.adaptive --coverage`` measures the
coverage of the final intervals over an ensemble of truths (docs/adaptive.md).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..choice.model_fit import OrderChoice
from ..core.errors import CalibrationError
from ..model.data import CalibrationData
from ..model.polynomial_model import Orders
from ..regression.conjugate import CoefficientPrior
from ..solve.radiometric_solver import RadiometricPrior, solve_radiometric
from ..solve.solution import Solution
from .information import AntennaInformation, antenna_information

ComplexArray = NDArray[np.complex128]
FloatArray = NDArray[np.float64]

#: The refits between refreshes: one model under the thesis's wide prior (no scale search;
#: the refresh's ``kappa`` carries the averaged solution's own width).
FIXED_PRIOR = RadiometricPrior(coefficients=CoefficientPrior())

#: Instrument time of one measurement of ``t`` s per Dicke position: source, load, noise source.
POSITIONS = 3
#: Where the antenna's assumed temperature is given (:meth:`AdaptiveSettings.antenna_temperatures`).
ANTENNA_REF_HZ = 75e6


@dataclass(frozen=True)
class AdaptiveSettings:
    """What the adaptive step may do (every duration is seconds per Dicke position)."""

    target_mk: float | None = None  # stop when the predicted antenna error (RMS, band) reaches it
    budget_s: float = 3600.0  # instrument time, overheads included
    first_pass_s: float = 60.0  # the short first pass over every calibrator
    durations_s: tuple[float, ...] = (30.0, 60.0, 120.0, 300.0)  # candidate next durations
    overhead_s: float = 10.0  # switching + settling per measurement (charged to each candidate)
    refresh_every: int = 4  # re-run the model choice every N decisions
    band_hz: tuple[float, float] | None = None  # weighted band of interest (None: whole band)
    antenna_temperature_k: float = 298.0  # the antenna's assumed temperature at ANTENNA_REF_HZ
    antenna_index: float = 0.0  # its spectral index: 0 an ambient load, about -2.5 the sky

    def __post_init__(self) -> None:
        if self.target_mk is not None and not self.target_mk > 0:
            raise ValueError(f"target_mk must be > 0, got {self.target_mk}")
        if not self.budget_s > 0 or not self.first_pass_s > 0:
            raise ValueError("budget_s and first_pass_s must be > 0")
        if not self.durations_s or min(self.durations_s) <= 0:
            raise ValueError("durations_s needs at least one duration, each > 0")
        if self.overhead_s < 0 or self.refresh_every < 1:
            raise ValueError("overhead_s must be >= 0 and refresh_every >= 1")
        if not self.antenna_temperature_k > 0 or not np.isfinite(self.antenna_index):
            raise ValueError("the antenna's temperature must be > 0 K and its index finite")

    def cost_s(self, seconds: float) -> float:
        """Instrument time of one measurement: ``3 t + overhead_s``."""
        return POSITIONS * seconds + self.overhead_s

    def antenna_temperatures(self, freq_hz: FloatArray) -> FloatArray:
        """The antenna's assumed temperature per channel: ``T_0 (f / f_0)^beta`` (K).

        ``T_0 = antenna_temperature_k`` at ``f_0 =`` :data:`ANTENNA_REF_HZ`, ``beta =
        antenna_index``. The sky a global 21-cm antenna sees falls as a power law of index
        about -2.5 (some 2000-3000 K at 75 MHz away from the galactic plane); a load on
        the antenna port is flat.
        The predicted error of the calibrated antenna grows with its temperature (the
        noise-source and gain terms scale with ``T_ant``), so where the time goes depends
        on it.
        """
        freq = np.asarray(freq_hz, dtype=float)
        return np.asarray(
            self.antenna_temperature_k * (freq / ANTENNA_REF_HZ) ** self.antenna_index
        )


@dataclass(frozen=True)
class Candidate:
    """One possible next measurement and what the posterior predicts of it."""

    source: str
    seconds: float
    predicted_mk: float  # the antenna's predicted RMS error after it
    gain_per_s: float  # reduction of the predicted mean-square error, mK^2 per instrument second

    def as_record(self) -> dict[str, Any]:
        """Plain data."""
        return {
            "source": self.source, "seconds": self.seconds,
            "predicted_mk": round(self.predicted_mk, 6), "gain_per_s": self.gain_per_s,
        }


@dataclass(frozen=True)
class Decision:
    """One decision of the planner: the state, every candidate scored, the choice."""

    step: int
    elapsed_s: float
    predicted_mk: float  # the predicted antenna error now
    orders: tuple[int, ...]
    candidates: tuple[Candidate, ...]
    choice: Candidate | None  # None: stop
    stop_reason: str | None  # "target" | "budget" | None
    refreshed: bool = False  # whether the model choice was re-run for it
    model_choice_factor: float = 1.0  # kappa (module docstring)

    def as_record(self) -> dict[str, Any]:
        """JSON-able, for the run file and the log."""
        return {
            "step": self.step,
            "elapsed_s": self.elapsed_s,
            "predicted_mk": round(self.predicted_mk, 6),
            "orders": list(self.orders),
            "candidates": [c.as_record() for c in self.candidates],
            "choice": None if self.choice is None else self.choice.as_record(),
            "stop_reason": self.stop_reason,
            "refreshed": self.refreshed,
            "model_choice_factor": round(self.model_choice_factor, 6),
        }


Solver = Callable[..., Solution]


@dataclass
class AdaptivePlanner:
    """Chooses the next calibrator measurement from the posterior of the data so far.

    ``antenna_s11`` is the antenna's reflection over the data's channels (the band the
    receiver hands over). ``solver`` is the radiometric solver (its keywords: ``orders``, ``prior``,
    ``average``, ``delay_terms``); stateful: the orders between refreshes, ``kappa`` and
    :attr:`decisions`.
    """

    settings: AdaptiveSettings
    antenna_s11: ComplexArray
    solver: Solver = solve_radiometric
    decisions: list[Decision] = field(default_factory=list)
    orders: Orders | None = None
    kappa: float = 1.0
    calls: int = 0  # posteriors computed (decisions and predictions): the refresh cadence

    def first_pass(self, sources: Sequence[str]) -> list[tuple[str, float]]:
        """The first pass: every calibrator once, ``first_pass_s`` per position."""
        if len(sources) < 2:
            raise ValueError("the adaptive step needs at least two calibrators")
        return [(name, self.settings.first_pass_s) for name in sources]

    def information(self, data: CalibrationData) -> tuple[AntennaInformation, bool]:
        """The current model's :class:`AntennaInformation`, refreshing the model if due.

        Returns it and whether the model choice was re-run. A fixed model the data no
        longer determine (a refit raising :class:`CalibrationError`) is replaced by a
        refresh.
        """
        s = self.settings
        refresh = self.orders is None or self.calls % s.refresh_every == 0
        self.calls += 1
        full: Solution | None = None
        if refresh:
            full = self.solver(data)
            self.orders = full.orders_used
        assert self.orders is not None
        try:
            fixed = self.solver(
                data, orders=OrderChoice.fixed(self.orders), prior=FIXED_PRIOR, average=False,
                delay_terms=False,
            )
        except CalibrationError:
            if full is None:
                full = self.solver(data)
                refresh = True
            fixed = full
            self.orders = full.orders
            self.kappa = 1.0  # the averaged solution itself: no correction
        info = self._info(fixed, data)
        if full is not None and full is not fixed:
            v_full = self._info(full, data).variance()
            self.kappa = float(np.sqrt(v_full / info.variance()))
        return info, refresh

    def _info(self, solution: Solution, data: CalibrationData) -> AntennaInformation:
        s = self.settings
        return antenna_information(
            solution, data, self.antenna_s11, s.antenna_temperatures(data.freq_hz), s.band_hz
        )

    def predict_mk(self, data: CalibrationData) -> float:
        """The antenna's predicted RMS calibration error from ``data`` (mK), no decision."""
        info, _ = self.information(data)
        return 1e3 * self.kappa * float(np.sqrt(info.variance()))

    def decide(self, data: CalibrationData, elapsed_s: float) -> Decision:
        """The next measurement (or the stop) after ``elapsed_s`` of instrument time."""
        s = self.settings
        info, refreshed = self.information(data)
        k2 = self.kappa**2
        now = info.variance()
        predicted = 1e3 * np.sqrt(k2 * now)
        stop: str | None = None
        candidates: list[Candidate] = []
        if s.target_mk is not None and predicted <= s.target_mk:
            stop = "target"
        else:
            for i, name in enumerate(info.names):
                for t in s.durations_s:
                    cost = s.cost_s(t)
                    if elapsed_s + cost > s.budget_s:
                        continue
                    after = info.after(i, t)
                    candidates.append(Candidate(
                        name, float(t), float(1e3 * np.sqrt(k2 * after)),
                        float(1e6 * k2 * (now - after) / cost),
                    ))
            if not candidates:
                stop = "budget"
        choice = None if stop else max(candidates, key=lambda c: c.gain_per_s)
        decision = Decision(
            step=len(self.decisions), elapsed_s=float(elapsed_s), predicted_mk=float(predicted),
            orders=tuple(info.orders), candidates=tuple(candidates), choice=choice,
            stop_reason=stop, refreshed=refreshed, model_choice_factor=self.kappa,
        )
        self.decisions.append(decision)
        return decision
