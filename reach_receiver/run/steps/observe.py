"""``observe``: antenna Dicke cycles, periodic test-load checks, each cycle calibrated.

``{cycles: 48, seconds: 200, source: ant, test_load_every: 6, rfi_threshold_sigma: 5}``:
``cycles`` Dicke cycles of ``source`` with ``seconds`` per position; before every
``test_load_every``-th cycle the VNA is checked on its test load (recalibrated as the
step's ``test_load_check`` would). With a solution from an earlier ``calibrate`` step,
each cycle is calibrated at once, through the store's hand-over with that one cycle and
the latest S11s, over the solution's band, and its RFI channels flagged by the engine's
flagger (:func:`calibration.checks.rfi.flag_sky`: its noise level follows the sky's); the
calibrated spectrum is stored as ``<source>_<cycle>``, with its error's parts (the
solution's, shared by every spectrum it calibrates; the radiometer's, independent per
spectrum) and the hand-over it used, which a season's average keeps apart.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibration.checks.rfi import flag_sky
from calibration.checks.rfi_night import flag_night
from calibration.solve.solvers import band_hz
from reach_receiver.config.fields import Fields
from reach_receiver.schedule.parsing import ParseContext
from reach_receiver.schedule.steps import Step, Where
from reach_receiver.schedule.timing import TimingWalk, hms

from ..context import RunContext
from ..kind import RunnableKind
from .spectra import dicke_connections, dicke_cycle
from .vna import TestLoadCheck, check_test_load

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Observe(Step):
    """Antenna Dicke cycles, a test-load check every ``test_load_every`` cycles, RFI flags."""

    cycles: int
    seconds: float
    source: str = "ant"
    test_load_every: int = 6
    rfi_threshold_sigma: float = 5.0


@dataclass(frozen=True)
class CalibratedCycle:
    """What the night's flags need of a calibrated cycle."""

    name: str
    freq_hz: np.ndarray
    mean: np.ndarray
    flags: np.ndarray


def calibrate_cycle(
    run: RunContext, source: str, number: int, name: str, threshold: float
) -> CalibratedCycle | None:
    """Calibrate one stored cycle with the run's solution; store it with its RFI flags."""
    solution = run.solution
    if solution is None:
        return None
    band = band_hz(solution)
    view = run.store.engine_view(band, cycles={source: [number]})
    if view.layout is None or source not in view.others:
        log.warning("observe: %s not calibrated (%s)", name, "; ".join(view.handover.warnings))
        return None
    layout = view.layout
    data = view.others[source]
    spectrum = solution.calibrate(
        layout.freq_hz, layout.gamma_rec, data, layout.channel_width_hz, layout.gamma_rec_std,
    )
    radiometer = spectrum.std_radiometer  # without the S11s' trace noise (shared by cycles)
    assert radiometer is not None  # both solvers separate it
    flags = flag_sky(spectrum.mean, threshold, layout.freq_hz)
    run.store.add_calibrated(
        name, layout.freq_hz, spectrum.mean, spectrum.std, flags, timestamp=run.clock.now(),
        intervals=spectrum.intervals(), handover=view.handover,
        errors={"std_calibration": spectrum.std_calibration, "std_radiometer": radiometer},
    )
    log.info("observe: %s calibrated, %d channels flagged", name, flags.sum())
    return CalibratedCycle(name, np.asarray(layout.freq_hz), np.asarray(spectrum.mean), flags)


def flag_cycles_together(
    run: RunContext, source: str, cycles: Sequence[CalibratedCycle], threshold: float
) -> None:
    """The night's flags of a step's calibrated cycles, stored as ``rfi_night_<source>``."""
    if not cycles:
        return
    freq = cycles[0].freq_hz
    same = [c for c in cycles if c.freq_hz.shape == freq.shape and np.allclose(c.freq_hz, freq)]
    night = flag_night(
        np.stack([c.mean for c in same]), np.stack([c.flags for c in same]), freq, threshold
    )
    summary = night.summary()
    run.store.add_check(
        f"rfi_night_{source}", True, timestamp=run.clock.now(),
        details={"spectra": [c.name for c in same], "threshold_sigma": threshold, **summary},
        arrays={"flags": night.flags},
    )
    log.info(
        "observe: %d cycles flagged together: %d channels at every time, %d spectra whole",
        len(same), summary["channels_flagged_at_every_time"], summary["spectra_flagged_whole"],
    )


class ObserveKind(RunnableKind[Observe]):
    """``observe``."""

    name = "observe"
    step_type = Observe
    keys = ("cycles", "seconds", "source", "test_load_every", "rfi_threshold_sigma")

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> Observe:
        """Cycles, seconds per position (at least one spectrum), source, checks, RFI."""
        return Observe(
            where,
            cycles=f.count("cycles"),
            seconds=ctx.integration(f, "seconds"),
            source=f.choice("source", ctx.sources, "ant") or "ant",
            test_load_every=f.count("test_load_every", 6),
            rfi_threshold_sigma=f.number("rfi_threshold_sigma", 5.0, low=0.0, open_low=True),
        )

    def describe(self, step: Observe) -> str:
        """Cycles, their length, and the checks."""
        return (
            f"observe {step.source}: {step.cycles} Dicke cycles, {hms(step.seconds)} per "
            f"position, test load every {step.test_load_every}"
        )

    def duration(self, step: Observe, walk: TimingWalk) -> float:
        """The cycles and a test-load sweep every ``test_load_every`` of them."""
        spectra = walk.spectra(3 * step.cycles, step.seconds)
        return spectra + walk.sweeps(step.cycles // step.test_load_every)

    def connections(self, step: Observe) -> list[tuple[str, str]]:
        """The Dicke positions, then the test load."""
        return [*dicke_connections((step.source,)), ("test_load", "vna")]

    def rest(self, step: Observe, measured: Sequence[tuple[str, str]]) -> Observe | None:
        """The cycles not taken yet."""
        done = sum(1 for kind, name in measured if (kind, name) == ("dicke", step.source))
        left = step.cycles - done
        return dataclasses.replace(step, cycles=left) if left > 0 else None

    def execute(self, step: Observe, run: RunContext) -> None:
        """Each cycle: the test load when due, the cycle, its calibration; the night's flags."""
        calibrated: list[CalibratedCycle] = []
        for index in range(step.cycles):
            if index and step.test_load_every and index % step.test_load_every == 0:
                check_test_load(run, TestLoadCheck(step.where))
            label = f"cycle {index + 1}/{step.cycles}"
            number = dicke_cycle(run, step.source, step.seconds, label)
            name = f"{step.source}_{index:04d}"
            cycle = calibrate_cycle(run, step.source, number, name, step.rfi_threshold_sigma)
            if cycle is not None:
                calibrated.append(cycle)
        flag_cycles_together(run, step.source, calibrated, step.rfi_threshold_sigma)
