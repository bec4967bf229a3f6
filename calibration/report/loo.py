"""The report's leave-one-out: each calibrator held out of the solve, beside its in-sample fit.

A calibrator's in-sample residual (its calibration with the solution it was fitted to)
near the noise says the noise model is right, not that the calibration generalises: a
model with as many smooth terms as the data have degrees of freedom fits the noise too.
Held out (:mod:`calibration.checks.validation`), the calibrator is calibrated by a solution of
the others, with the solution's own procedure:

* its method and basis kind (:func:`calibration.solve.solvers.solver`);
* its orders searched as the solution's were (the default box), or, for a solution of one
  model (fixed orders: an evidence table of at most one entry), those orders;
* on the solution's band and its calibrators (those in the run).

The actual error ``e = T_cal - T`` and its full predicted sd (calibration, radiometer
noise, thermometry) are kept per channel for the figure
(:func:`calibration.report.figures.held_out_residuals`); the table's numbers are
:func:`calibration.checks.validation.held_out`'s, the same as ``reach-cal validate
--leave-one-out``. It costs one solve per calibrator (EDGES-3's four loads, 2868 channels:
about 6 s; ``reach-cal report --no-leave-one-out`` leaves it out).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..checks.validation import HeldOut, LeaveOneOutReport, held_out
from ..choice.model_fit import OrderChoice
from ..core.errors import CalibrationError
from ..model.data import CalibrationData
from ..solve.per_frequency import ChannelSolution
from ..solve.solvers import AnySolution, band_hz, method_name, solver

FloatArray = NDArray[np.float64]

__all__ = ["HeldOutSpectrum", "ReportLeaveOneOut", "report_leave_one_out", "same_procedure"]


@dataclass(frozen=True)
class HeldOutSpectrum:
    """One held-out calibrator: the table's numbers and, when solved, its spectra (K)."""

    result: HeldOut
    residual: FloatArray | None = None
    #: The prediction's calibration part (correlated across channels), sd per channel.
    predicted_calibration: FloatArray | None = None
    #: The rest: radiometer noise, reflections' errors and thermometry, sd per channel.
    predicted_noise: FloatArray | None = None


@dataclass(frozen=True)
class ReportLeaveOneOut:
    """Every calibrator held out in turn, the procedure named, and the time it took."""

    held: tuple[HeldOutSpectrum, ...]
    freq_hz: FloatArray
    procedure: str
    elapsed_s: float

    @property
    def report(self) -> LeaveOneOutReport:
        """The numbers as :mod:`calibration.checks.validation` reports them (for its warnings)."""
        return LeaveOneOutReport(tuple(h.result for h in self.held))


def same_procedure(solution: AnySolution) -> tuple[Callable[[CalibrationData], AnySolution], str]:
    """The solve that made ``solution`` (module docstring), and its description."""
    name = method_name(solution)
    if isinstance(solution, ChannelSolution):
        return solver(name), f"{name} per channel"
    if len(solution.evidence_table) <= 1:
        orders = solution.orders_used
        return (
            solver(name, OrderChoice.fixed(orders), solution.basis.kind),
            f"{name}, fixed orders {','.join(map(str, orders))}",
        )
    return solver(name, None, solution.basis.kind), f"{name}, orders searched as the solution's"


def report_leave_one_out(solution: AnySolution, data: CalibrationData) -> ReportLeaveOneOut:
    """Hold out each of ``solution``'s calibrators in ``data`` in turn (module docstring)."""
    lo, hi = band_hz(solution)
    tol = 1e-9 * hi
    data = data.band(lo - tol, hi + tol)
    names = [n for n in solution.calibrators if n in data.sources] or list(data.names)
    data = data.subset(names)
    solve, procedure = same_procedure(solution)
    start = time.perf_counter()
    held = []
    for name in names:
        others = tuple(n for n in names if n != name)
        try:
            if not others:
                raise CalibrationError("no calibrator is left to solve with")
            part = solve(data.subset(others))
            result = held_out(part, data, name)
        except CalibrationError as err:
            held.append(HeldOutSpectrum(HeldOut(name, others, data.n_channels, refused=str(err))))
            continue
        source = data.sources[name]
        spectrum = part.calibrate(
            data.freq_hz, data.gamma_rec, source, data.channel_width_hz, data.gamma_rec_std,
        )
        residual = spectrum.mean - np.asarray(source.temperature_k, dtype=float)
        noise = np.sqrt(
            spectrum.std**2 - spectrum.std_calibration**2 + source.temperature_std_k**2
        )
        held.append(HeldOutSpectrum(result, residual, spectrum.std_calibration, noise))
    return ReportLeaveOneOut(
        tuple(held), data.freq_hz, procedure, time.perf_counter() - start
    )
