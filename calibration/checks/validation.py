"""Leave-one-out validation: each calibrator, held out of the solve, calibrated as a test source.

For each calibrator ``k`` of a run, the parameters are solved from the others and ``k`` is
calibrated with them (eq. 3.27, :meth:`calibration.solve.solution.Solution.calibrate`). Its
known temperature ``T_k`` makes the calibration error measurable::

    e_kf = T_cal,kf - T_kf                                             (actual error)
    s_kf^2 = x_kf^T Cov(c) x_kf + sigma_meas,kf^2 + sigma_T,k^2        (predicted variance)

with the calibration part ``x^T Cov(c) x`` (the solution's own posterior, eq. 3.42), the
held-out source's radiometer noise ``sigma_meas`` (eq. 3.41; the thesis solver's
homoscedastic sigma) and the held-out load's thermometry uncertainty ``sigma_T``
(``SourceData.temperature_std_k``). Honest error bars give ``rms(e) / rms(s) ~ 1`` and put
68% / 95% of the channels' errors inside the central intervals ``+- z s`` (Student-t with
the posterior's dof). A solve the engine refuses (a
:class:`~calibration.core.errors.CalibrationError`, e.g. ``T_NS`` undetermined when every
remaining calibrator has one temperature) is reported as refused, with its message.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

from ..choice.model_checks import fit_warnings
from ..core.errors import CalibrationError
from ..model.data import CalibrationData
from ..solve.solution import Solution
from ..solve.solvers import AnySolution

__all__ = ["HeldOut", "LeaveOneOutReport", "held_out", "leave_one_out"]

FloatArray = NDArray[np.float64]
LEVELS = (0.68, 0.95)


@dataclass(frozen=True)
class HeldOut:
    """One held-out calibrator: its actual calibration error against the predicted one (K).

    ``refused`` holds the engine's message when the solve without it was refused; the
    numbers are then NaN. ``ratio`` is ``rms_error_k / rms_predicted_k``; ``inside_68``
    and ``inside_95`` the fractions of channels whose error lies inside the central
    68% / 95% predictive intervals.
    """

    name: str
    calibrators: tuple[str, ...]
    n_channels: int
    rms_error_k: float = float("nan")
    mean_error_k: float = float("nan")
    rms_predicted_calibration_k: float = float("nan")
    rms_predicted_k: float = float("nan")
    ratio: float = float("nan")
    inside_68: float = float("nan")
    inside_95: float = float("nan")
    orders: tuple[int, ...] = ()
    refused: str | None = None

    def as_dict(self) -> dict[str, object]:
        """Plain data (JSON-ready: lists for tuples; ``None`` for NaN)."""
        out = asdict(self)
        out["calibrators"] = list(self.calibrators)
        out["orders"] = list(self.orders)
        return {k: (None if isinstance(v, float) and np.isnan(v) else v) for k, v in out.items()}


@dataclass(frozen=True)
class LeaveOneOutReport:
    """Every calibrator held out in turn, in the run's order."""

    results: tuple[HeldOut, ...]

    def lines(self) -> list[str]:
        """A table for the terminal: one row per held-out calibrator."""
        header = (
            f"{'held out':<10} {'actual':>10} {'pred cal':>10} {'pred full':>10} "
            f"{'ratio':>7} {'in 68%':>7} {'in 95%':>7}  orders"
        )
        rows = [header]
        for r in self.results:
            if r.refused is not None:
                rows.append(f"{r.name:<10} refused: {r.refused}")
                continue
            rows.append(
                f"{r.name:<10} {r.rms_error_k:>10.4g} {r.rms_predicted_calibration_k:>10.4g} "
                f"{r.rms_predicted_k:>10.4g} {r.ratio:>7.3f} {r.inside_68:>7.3f} "
                f"{r.inside_95:>7.3f}  {','.join(map(str, r.orders))}"
            )
        return rows

    def warnings(self, solution: object | None = None) -> list[str]:
        """Warnings: held-out errors far from their prediction (and ``solution``'s own).

        :func:`calibration.choice.model_checks.fit_warnings`: with ``solution``, also its noise
        scale far from 1 and orders at their limit.
        """
        return fit_warnings(solution, loo=self)


def _rms(values: FloatArray) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def held_out(solution: AnySolution, data: CalibrationData, name: str) -> HeldOut:
    """Calibrate ``data``'s calibrator ``name`` with ``solution`` and score it (module doc)."""
    from scipy import stats
    source = data.sources[name]
    spectrum = solution.calibrate(
        data.freq_hz, data.gamma_rec, source,
        data.channel_width_hz, data.gamma_rec_std,
    )
    error = spectrum.mean - np.asarray(source.temperature_k, dtype=float)
    predicted = np.sqrt(spectrum.std**2 + source.temperature_std_k**2)
    inside = []
    for level in LEVELS:
        q = 0.5 + 0.5 * level
        z = stats.norm.ppf(q) if np.isinf(spectrum.dof) else stats.t.ppf(q, spectrum.dof)
        inside.append(float(np.mean(np.abs(error) <= z * predicted)))
    rms_predicted = _rms(predicted)
    return HeldOut(
        name=name,
        calibrators=solution.calibrators,
        n_channels=data.n_channels,
        rms_error_k=_rms(error),
        mean_error_k=float(np.mean(error)),
        rms_predicted_calibration_k=_rms(spectrum.std_calibration),
        rms_predicted_k=rms_predicted,
        ratio=_rms(error) / rms_predicted,
        inside_68=inside[0],
        inside_95=inside[1],
        orders=tuple(solution.orders_used) if isinstance(solution, Solution) else (),
    )


def leave_one_out(
    data: CalibrationData, solve: Callable[[CalibrationData], AnySolution]
) -> LeaveOneOutReport:
    """Solve without each calibrator in turn (with ``solve``) and score it as held out."""
    results = []
    for name in data.names:
        others = tuple(n for n in data.names if n != name)
        try:
            if not others:
                raise CalibrationError("no calibrator is left to solve with")
            results.append(held_out(solve(data.subset(others)), data, name))
        except CalibrationError as err:
            results.append(HeldOut(name, others, data.n_channels, refused=str(err)))
    return LeaveOneOutReport(tuple(results))
