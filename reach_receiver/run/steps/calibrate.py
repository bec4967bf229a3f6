"""``calibrate``: the calibration engine inside the loop.

``{f_lo_hz: 50e6, f_hi_hz: 130e6, solver: radiometric, benchmark: previous.h5,
tolerance: 0.05}``. The run's measurements so far go to the solver ``solver`` names
(:mod:`calibration.solve.solvers`: ``radiometric``, ``thesis``, ``least-squares`` or
``bayesian``; default the site's ``calibration.solver``, else ``radiometric``) through the store's
hand-over (:mod:`reach_receiver.store.handover`: every Dicke cycle of each source, the
latest calibrated S11s, the calibrators' thermocouple temperatures), the same hand-over
that ``reach-cal solve run.h5`` reads, so the two give the same solution. The band is
the site's (``calibration.band_hz``) unless the step gives one. The solution is stored
with the hand-over it was made from, verified against a benchmark solution if one is
given (thesis 2.1.3: every parameter's band-averaged value within 5 %), compared with
the previous solution on the validation source (the antenna when measured) for a drift of
the receiver (:mod:`reach_receiver.run.drift`: the ``calibration drift`` alarm under
``reachd``), and summarised by its distance to the noise floor on that source.

``mts``, ``cables`` and ``rfi`` (each ``true`` by default) apply the corrections the site
file's ``calibration`` section describes (:mod:`reach_receiver.store.corrections`: the
MTS paths de-embedded and embedded, the cable-based sources' temperatures through their
cables, RFI channels dropped) to the hand-over's data before the solve; ``false`` leaves
one out. What was done is stored in the solution's hand-over (``corrections``).

``vna_accuracy: DRAWS`` (0 by default) carries the VNA's data-sheet accuracy (thesis table
2.3) onto the validation source as a systematic error, from ``DRAWS`` refits with every
reflection moved by a draw of it (:mod:`calibration.checks.vna_systematics`; about 60 ms a draw
for 12 calibrators x 6554 channels); the run summary states it beside the floor.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from calibration import CalibrationData
from calibration.checks.vna_systematics import ReflectionSystematics, reflection_systematics
from calibration.core.errors import FileFormatError, IllPosedError
from calibration.io.solution_file import read_solution
from calibration.model.data import SourceData
from calibration.model.reflection_noise import reflection_variance
from calibration.solve.per_frequency import ChannelSolution
from calibration.solve.solvers import (
    METHODS,
    AnySolution,
    method_name,
    refit,
    solution_noise_floor,
    solver,
)
from reach_receiver.config.fields import Fields
from reach_receiver.schedule.parsing import ParseContext
from reach_receiver.schedule.steps import Step, Where
from reach_receiver.schedule.timing import TimingWalk
from reach_receiver.store import HandOver, read_run_file
from reach_receiver.store.corrections import ALL_CORRECTIONS, Chosen, correct
from reach_receiver.store.handover import ANTENNA, RECEIVER

from ..checks import compare_with_benchmark
from ..context import CheckFailed, RunContext
from ..drift import check_drift
from ..kind import RunnableKind

FloatArray = NDArray[np.float64]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Calibrate(Step):
    """Solve the noise-wave parameters from the data taken so far.

    With a ``benchmark`` solution file, the new solution is verified against it: every
    parameter's band-averaged value within ``tolerance`` (thesis 2.1.3: 5 %). ``f_lo_hz``
    and ``f_hi_hz`` default to the site's band, ``solver`` (one of
    :data:`calibration.solve.solvers.METHODS`) to the site's solver.
    """

    benchmark: Path | None = None
    tolerance: float = 0.05
    f_lo_hz: float | None = None
    f_hi_hz: float | None = None
    corrections: Chosen = ALL_CORRECTIONS
    solver: str | None = None
    vna_accuracy: int = 0


@dataclass(frozen=True)
class CalibrationOutcome:
    """A calibration made during a run, and how it fares on the validation source.

    ``floor_std_k`` is the Cramer-Rao floor of the validation source's calibrated
    temperature per channel, ``floor_k`` its RMS over the band, ``predicted_k`` the RMS
    of the solution's calibration error (posterior); both hold the VNA's trace noise on
    the validation source's and the receiver's reflections where the run file states it
    (a per-channel error of the calibrated source that no calibration removes), and
    neither its radiometer noise.
    The floor is that of the solution's own kind of model
    (:func:`calibration.solve.solvers.solution_noise_floor`: polynomial or per channel).
    """

    solution: AnySolution
    data: CalibrationData
    validation: SourceData
    handover: HandOver
    floor_std_k: FloatArray
    predicted_k: float
    systematics: ReflectionSystematics | None = None
    #: :attr:`CalibratedSpectrum.model_choice_share` of the validation source.
    model_choice_share: float = 0.0

    @property
    def floor_k(self) -> float:
        """RMS over the band of the per-channel floor."""
        return float(np.sqrt(np.mean(self.floor_std_k**2)))

    @property
    def systematic_k(self) -> float | None:
        """RMS over the band of the VNA's data-sheet error on the validation source."""
        if self.systematics is None:
            return None
        return float(np.sqrt(np.mean(self.systematics.std_k(self.validation.name) ** 2)))


def result_line(outcome: CalibrationOutcome) -> str:
    """The calibration in one line for the log: orders, noise scale, distance to floor."""
    solution = outcome.solution
    if isinstance(solution, ChannelSolution):
        model = f"{method_name(solution)} per channel"
    else:
        model = (f"orders {solution.best_orders}, noise scale s^2 "
                 f"{solution.posterior.noise_variance:.3f}")
    return (f"calibrated: {model}, distance to floor {outcome.predicted_k / outcome.floor_k:.3f}"
            f" on {outcome.validation.name!r} (floor {1e3 * outcome.floor_k:.3f} mK)")


def benchmark_solution(path: Path) -> AnySolution:
    """A benchmark solution: a solution file (``reach-cal solve``) or an earlier run file."""
    try:
        return read_solution(path)
    except FileFormatError:
        previous = read_run_file(path).solution()
        if previous is None:
            raise CheckFailed(f"{path} holds no calibration solution") from None
        return previous


def calibrate(
    run: RunContext,
    band_hz: tuple[float, float],
    chosen: Chosen = ALL_CORRECTIONS,
    method: str = "radiometric",
    vna_draws: int = 0,
) -> CalibrationOutcome:
    """Solve the run so far over ``band_hz`` with ``method``, corrected as asked.

    ``vna_draws > 0`` carries the VNA's data-sheet accuracy (table 2.3) onto the
    validation source by that many refits (:mod:`calibration.checks.vna_systematics`).
    """
    view = run.store.engine_view(band_hz)
    handover = view.handover
    if RECEIVER not in handover.s11:
        raise CheckFailed("calibrate needs the LNA's S11: add 'lna' to an s11 step before it")
    data = view.data
    if data is None or len(data.sources) < 2:
        why = "; ".join(handover.warnings)
        raise CheckFailed(
            "calibrate needs at least two calibrators with spectra, S11 and temperatures; "
            f"have {list(handover.calibrators)}" + (f" ({why})" if why else "")
        )
    site = run.site
    data, others, report = correct(
        data, dict(view.others), handover, site.corrections, site.source, chosen
    )
    if report:
        handover = dataclasses.replace(handover, corrections=report)
    try:
        solution = solver(method)(data)
    except IllPosedError as err:  # e.g. a per-channel solver with fewer than 5 calibrators
        raise CheckFailed(f"the {method} solver cannot solve this run: {err}") from err
    validation = others.get(ANTENNA) or data.sources[data.names[0]]
    spectrum = solution.calibrate(data.freq_hz, data.gamma_rec, validation)
    reflections = reflection_variance(
        solution.evaluate(data.freq_hz), validation.gamma, data.gamma_rec, validation.q,
        validation.gamma_std, data.gamma_rec_std,
    )
    return CalibrationOutcome(
        solution=solution,
        data=data,
        validation=validation,
        handover=handover,
        floor_std_k=solution_noise_floor(solution, data, validation).std,
        predicted_k=float(np.sqrt(np.mean(spectrum.std_calibration**2 + reflections))),
        model_choice_share=spectrum.model_choice_share,
        systematics=(
            reflection_systematics(
                data, {validation.name: validation}, refit(solution), 0, vna_draws
            )
            if vna_draws
            else None
        ),
    )


class CalibrateKind(RunnableKind[Calibrate]):
    """``calibrate``."""

    name = "calibrate"
    step_type = Calibrate
    keys = (
        "benchmark", "tolerance", "f_lo_hz", "f_hi_hz", "mts", "cables", "rfi", "solver",
        "vna_accuracy",
    )
    needs_devices = False

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> Calibrate:
        """The band and the solver (default the site's), a benchmark and its tolerance."""
        benchmark = f.text("benchmark", None)
        method = f.choice("solver", METHODS, None)
        draws = f.count("vna_accuracy", 0, minimum=0)
        if draws == 1:
            f.report("vna_accuracy", "needs at least 2 draws (64 is typical), or 0 for none")
        low = f.number("f_lo_hz", None, low=0.0, open_low=True) if f.has("f_lo_hz") else None
        high = f.number("f_hi_hz", None, low=0.0, open_low=True) if f.has("f_hi_hz") else None
        band = ctx.site.band_hz if ctx.site is not None else None
        lo = low if low is not None else (band[0] if band else None)
        hi = high if high is not None else (band[1] if band else None)
        if not f.failed and lo is not None and hi is not None and lo >= hi:
            f.report("f_hi_hz", f"must be above f_lo_hz ({lo:g} Hz), not {hi:g}")
        switches = {}
        for key in ("mts", "cables", "rfi"):
            value = f.raw(key, True)
            if not isinstance(value, bool):
                f.report(key, f"must be true or false, not {value!r}")
            switches[key] = value is not False
        return Calibrate(
            where,
            benchmark=ctx.path(f.file, benchmark) if benchmark else None,
            tolerance=f.fraction("tolerance", 0.05),
            f_lo_hz=low,
            f_hi_hz=high,
            corrections=Chosen(**switches),
            solver=method,
            vna_accuracy=draws,
        )

    def describe(self, step: Calibrate) -> str:
        """The band and the solver, when the step sets them."""
        how = f", {step.solver} solver" if step.solver is not None else ""
        if step.f_lo_hz is None and step.f_hi_hz is None:
            return f"calibrate (the site's band{how})"
        lo = "site" if step.f_lo_hz is None else f"{step.f_lo_hz / 1e6:g}"
        hi = "site" if step.f_hi_hz is None else f"{step.f_hi_hz / 1e6:g}"
        return f"calibrate {lo}-{hi} MHz{how}"

    def duration(self, step: Calibrate, walk: TimingWalk) -> float:
        """10 s."""
        return 10.0

    def rest(self, step: Calibrate, measured: Sequence[tuple[str, str]]) -> Calibrate | None:
        """Nothing once its solution is stored."""
        return None if any(kind == "solution" for kind, _ in measured) else step

    def execute(self, step: Calibrate, run: RunContext) -> None:
        """Solve, verify against the benchmark and the previous solution, store, summarise."""
        lo, hi = run.site.band_hz
        band = (step.f_lo_hz or lo, step.f_hi_hz or hi)
        run.progress.update(f"calibrating {band[0] / 1e6:g}-{band[1] / 1e6:g} MHz", 0, 1, None)
        outcome = calibrate(
            run, band, step.corrections, step.solver or run.site.solver, step.vna_accuracy
        )
        verification: dict[str, object] = {}
        if step.benchmark is not None:
            verdict = compare_with_benchmark(
                outcome.solution,
                benchmark_solution(step.benchmark),
                outcome.data.freq_hz,
                step.tolerance,
            )
            verification = {"passed": verdict.passed, **verdict.differences}
            worst = max(verdict.differences, key=verdict.differences.__getitem__)
            detail = (
                f"largest change {worst} {100 * verdict.differences[worst]:.2f} % "
                f"(tolerance {100 * step.tolerance:.0f} %)"
            )
            run.record_check("benchmark_solution", verdict.passed, detail, verification)
        check_drift(run, outcome.solution, outcome.data, outcome.validation)
        run.store.add_solution(
            outcome.solution,
            timestamp=run.clock.now(),
            verification=verification,
            handover=outcome.handover,
        )
        run.solution = outcome.solution
        run.calibration = outcome
        log.info("%s: %s", step.where, result_line(outcome))
