"""VNA kinds: the SOL calibration, the test-load check, and reflection measurements.

==================  =====================================================================
``vna_calibrate``   one-port SOL with the MS2 standards; sweep settings may be given
``test_load_check`` measure MS2-6 against a reference Touchstone file; recalibrate and
                    retry up to ``retries`` times
``s11``             ``{targets: [hot, cold, lna]}``
==================  =====================================================================
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, cast

import numpy as np

from reach_receiver.config.fields import REQUIRED, Fields
from reach_receiver.devices.vna_settings import SweepSettings
from reach_receiver.errors import ConfigError
from reach_receiver.schedule.parsing import ParseContext
from reach_receiver.schedule.steps import Step, Where
from reach_receiver.schedule.timing import TimingWalk
from reach_receiver.store.touchstone import read_touchstone

from ..checks import compare_test_load
from ..context import CheckFailed, RunContext
from ..kind import RunnableKind
from ..measure import take_s11

log = logging.getLogger(__name__)

#: The one-port standards, in the order the SOL calibration connects them.
SOL_STANDARDS = ("short", "open", "load")


@dataclass(frozen=True)
class Sweep:
    """VNA sweep settings; ``None`` keeps the driver's default (REACH's)."""

    f_start_hz: float | None = None
    f_stop_hz: float | None = None
    points: int | None = None
    ifbw_hz: float | None = None
    power_dbm: float | None = None
    averages: int | None = None

    def settings(self) -> SweepSettings:
        """The full settings: the given values over :class:`SweepSettings`' defaults."""
        given = {k: v for k, v in vars(self).items() if v is not None}
        return dataclasses.replace(SweepSettings(), **given)


SWEEP_KEYS = tuple(f.name for f in dataclasses.fields(Sweep))


def _sweep(f: Fields, where: Where) -> Sweep:
    sweep = f.mapping("sweep", SWEEP_KEYS)
    if sweep is None:
        return Sweep()
    given: dict[str, float | int] = {}
    for name in SWEEP_KEYS:
        if not sweep.has(name):
            continue
        if name in ("points", "averages"):
            given[name] = sweep.count(name)
        else:
            given[name] = sweep.number(name, REQUIRED)
    if sweep.failed:
        return Sweep()
    try:
        SweepSettings(**given)  # type: ignore[arg-type]  # validated by its own checks
    except ConfigError as err:
        f.report("sweep", str(err), where.line)
        return Sweep()
    return Sweep(**given)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- vna_calibrate
@dataclass(frozen=True)
class VnaCalibrate(Step):
    """Configure the sweep and run a one-port SOL calibration with the MS2 standards."""

    sweep: Sweep = field(default_factory=Sweep)


def calibrate_vna(run: RunContext) -> None:
    """Configure the run's sweep and calibrate with the MS2 short, open and load."""
    devices = run.instruments

    def connect_standard(standard: str) -> None:
        run.stop.check()
        devices.frontend.connect(standard, "vna")

    devices.vna.configure(run.sweep)
    devices.vna.calibrate_sol(connect_standard)


class VnaCalibrateKind(RunnableKind[VnaCalibrate]):
    """``vna_calibrate``."""

    name = "vna_calibrate"
    step_type = VnaCalibrate
    keys = ("sweep",)
    on_resume = "replay"

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> VnaCalibrate:
        """``sweep``: settings checked against the VNA's limits."""
        return VnaCalibrate(where, _sweep(f, where))

    def describe(self, step: VnaCalibrate) -> str:
        """Three sweeps."""
        return "VNA SOL calibration (3 sweeps)"

    def duration(self, step: VnaCalibrate, walk: TimingWalk) -> float:
        """Three sweeps at its settings, which later sweeps then use."""
        walk.sweep = step.sweep.settings()
        return walk.sweeps(3)

    def connections(self, step: VnaCalibrate) -> list[tuple[str, str]]:
        """The three standards."""
        return [(standard, "vna") for standard in SOL_STANDARDS]

    def execute(self, step: VnaCalibrate, run: RunContext) -> None:
        """Configure, calibrate, record."""
        run.sweep = step.sweep.settings()
        calibrate_vna(run)
        run.store.add_event("vna_calibrated", str(run.sweep), timestamp=run.clock.now())


# --------------------------------------------------------------------------- test_load_check
@dataclass(frozen=True)
class TestLoadCheck(Step):
    """Compare the MS2-6 test load with a reference; recalibrate up to ``retries`` times.

    ``reference`` ``None`` takes the site file's ``references.test_load``. The check
    passes when the ``statistic`` (``max``, ``p95`` or ``rms``) over frequency of
    ``|S11 - S11_ref| / |S11_ref|`` is at most ``tolerance`` (thesis 2.1.1: 5 %).
    """

    __test__ = False  # not a pytest class, whatever its name

    reference: Path | None = None
    tolerance: float = 0.05
    statistic: Literal["max", "p95", "rms"] = "p95"
    retries: int = 2


def check_test_load(run: RunContext, check: TestLoadCheck) -> None:
    """Measure the test load against its reference; recalibrate and retry on failure."""
    reference = check.reference or run.site.references.get("test_load")
    if reference is None:
        raise ConfigError("test_load_check: no reference file (step or site references)")
    ref_freq, ref_s11, _ = read_touchstone(Path(reference))
    detail = ""
    for attempt in range(check.retries + 1):
        run.stop.check()
        measured = take_s11(run.instruments.frontend, run.instruments.vna, "test_load")
        inside = (measured.freq_hz >= ref_freq[0]) & (measured.freq_hz <= ref_freq[-1])
        f = measured.freq_hz[inside]
        ref = np.interp(f, ref_freq, ref_s11.real) + 1j * np.interp(f, ref_freq, ref_s11.imag)
        verdict = compare_test_load(measured.s11[inside], ref, f, check.tolerance, check.statistic)
        detail = (
            f"{verdict.statistic} deviation {100 * verdict.value:.2f} % "
            f"(tolerance {100 * check.tolerance:.0f} %), attempt {attempt + 1}"
        )
        run.store.add_s11(
            f"test_load_{attempt}",
            measured.freq_hz,
            measured.s11,
            timestamp=measured.timestamp,
            settings=vars(run.sweep),
            calibrated=True,
        )
        run.record_check(
            "test_load",
            verdict.passed,
            detail,
            {
                "statistic": verdict.statistic,
                "value": verdict.value,
                "tolerance": check.tolerance,
                "attempt": attempt + 1,
                "worst_hz": verdict.worst_hz,
            },
        )
        if verdict.passed:
            return
        if attempt < check.retries:
            log.warning("test load check failed (%s); recalibrating the VNA", detail)
            calibrate_vna(run)
    raise CheckFailed(f"test-load check failed after {check.retries} recalibrations: {detail}")


class TestLoadCheckKind(RunnableKind[TestLoadCheck]):
    """``test_load_check``."""

    __test__ = False

    name = "test_load_check"
    step_type = TestLoadCheck
    keys = ("reference", "tolerance", "statistic", "retries")

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> TestLoadCheck:
        """The reference (relative to the schedule), tolerance, statistic, retries."""
        reference = f.text("reference", None)
        statistic = f.choice("statistic", ("max", "p95", "rms"), "p95") or "p95"
        return TestLoadCheck(
            where,
            reference=ctx.path(f.file, reference) if reference else None,
            tolerance=f.fraction("tolerance", 0.05),
            statistic=cast(Literal["max", "p95", "rms"], statistic),
            retries=f.count("retries", 2, minimum=0),
        )

    def describe(self, step: TestLoadCheck) -> str:
        """The statistic and the tolerance."""
        return f"test-load check ({step.statistic} within {step.tolerance:.1%})"

    def duration(self, step: TestLoadCheck, walk: TimingWalk) -> float:
        """One sweep (a failure adds recalibrations)."""
        return walk.sweeps(1)

    def connections(self, step: TestLoadCheck) -> list[tuple[str, str]]:
        """The test load, then the standards of a recalibration."""
        return [("test_load", "vna"), *((standard, "vna") for standard in SOL_STANDARDS)]

    def execute(self, step: TestLoadCheck, run: RunContext) -> None:
        """Check, recalibrating as allowed."""
        check_test_load(run, step)


# --------------------------------------------------------------------------- s11
@dataclass(frozen=True)
class MeasureS11(Step):
    """Measure the reflection of each target (a source name or ``lna``)."""

    targets: tuple[str, ...]


class MeasureS11Kind(RunnableKind[MeasureS11]):
    """``s11``."""

    name = "s11"
    step_type = MeasureS11
    keys = ("targets",)

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> MeasureS11:
        """``targets``: sources and ``lna``."""
        return MeasureS11(where, tuple(f.names("targets", ctx.s11_targets, "S11 target")))

    def describe(self, step: MeasureS11) -> str:
        """The targets."""
        return f"S11 of {', '.join(step.targets)}"

    def duration(self, step: MeasureS11, walk: TimingWalk) -> float:
        """One sweep per target."""
        return walk.sweeps(len(step.targets))

    def connections(self, step: MeasureS11) -> list[tuple[str, str]]:
        """Each target to the VNA."""
        return [(target, "vna") for target in step.targets]

    def rest(self, step: MeasureS11, measured: Sequence[tuple[str, str]]) -> MeasureS11 | None:
        """The targets not measured yet."""
        done = {name for kind, name in measured if kind == "s11"}
        left = tuple(t for t in step.targets if t not in done)
        return dataclasses.replace(step, targets=left) if left else None

    def execute(self, step: MeasureS11, run: RunContext) -> None:
        """Measure and store each target's reflection."""
        for index, target in enumerate(step.targets):
            run.stop.check()
            run.progress.update(f"S11 of {target}", index, len(step.targets), None)
            m = take_s11(run.instruments.frontend, run.instruments.vna, target)
            run.store.add_s11(
                target,
                m.freq_hz,
                m.s11,
                timestamp=m.timestamp,
                settings=vars(m.settings),
                calibrated=m.calibrated,
            )
