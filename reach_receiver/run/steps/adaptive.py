"""``calibrate_adaptive``: the calibrators' time spent where it cuts the antenna's error most.

``{sources: "${calibrators}", antenna: ant, target_mk: 5, budget_s: 36000,
first_pass_s: 60, durations_s: [30, 60, 120, 300], overhead_s: 180, refresh_every: 4,
band_hz: [60.0e+6, 120.0e+6], antenna_k: 2500, antenna_index: -2.5}``

Thesis 5.1's open problem, in the loop (:mod:`calibration.design.adaptive`): a first pass
of one Dicke cycle of ``first_pass_s`` per position over every calibrator, then, from the
run's hand-over after each cycle (the same data the ``calibrate`` step solves), the planner
scores every candidate next measurement ``(i, t)`` by the predicted variance of the
calibrated antenna it removes per second of instrument time,
``gain_i(t) = (V - V'_i(t)) / (3 t + overhead_s)`` with ``V = tr(C A)`` over ``band_hz``
(docs/adaptive.md; thesis eqs. 3.27, 3.36, 3.41), measures the best with a Dicke cycle,
and stops when the predicted error ``sqrt(V)`` reaches ``target_mk`` or no candidate fits
in what is left of ``budget_s``. ``target_fraction`` instead sets the target relative to
the error predicted after the first pass (as ``python -m benchmarks.adaptive`` does): 0.5
stops once the antenna's predicted error has halved.

The instrument time is the run clock's across each Dicke cycle (switching and settling
included); the engine's own computing is not charged (a compressed simulated clock would
make it hours). ``overhead_s``, the switching and settling each cycle costs beyond its
``3 t`` of integration, is by default measured: the median over the step's cycles so far
(before any, the schedule timing's two spectra per position,
``6 x devices.spectrometer.period_s``). ``band_hz`` is the band of interest, by
default the site's (``calibration.band_of_interest_hz``, else its calibration band
``calibration.band_hz``); ``antenna_k`` the antenna's assumed temperature at 75 MHz and
``antenna_index`` its spectral index (its design row: 298 K and flat by default, a load;
about 2500 K and -2.5 for the sky, where far more of the time goes to the hot load,
docs/adaptive.md).

Every decision (its step, the instrument time, the predicted error, every candidate with
its predicted error and gain, the choice or the stop) is a check named
``adaptive_decision`` in the run file (:data:`DECISION_CHECK`, details as
:meth:`calibration.design.adaptive.Decision.as_record` plus ``where``), and one log line.
Resumed, the step carries on with what is stored: calibrators already measured are not
measured again in the first pass, and the instrument time goes on from the last decision.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

from reach_receiver.config.fields import Fields
from reach_receiver.schedule.parsing import ParseContext
from reach_receiver.schedule.steps import Step, Where
from reach_receiver.schedule.timing import TimingWalk, hms

from ..context import RunContext
from ..kind import RunnableKind
from .adaptive_run import DECISION_CHECK, run_adaptive
from .spectra import dicke_connections

#: Candidate durations per Dicke position when the step gives none (s).
DEFAULT_DURATIONS_S = (30.0, 60.0, 120.0, 300.0)


@dataclass(frozen=True)
class CalibrateAdaptive(Step):
    """Measure the calibrators adaptively until the antenna's predicted error is reached.

    Every duration is seconds per Dicke position; ``overhead_s`` ``None`` means the
    site's timing (six spectrum periods per cycle).
    """

    sources: tuple[str, ...]
    antenna: str = "ant"
    target_mk: float | None = None
    target_fraction: float | None = None
    budget_s: float = 3600.0
    first_pass_s: float = 60.0
    durations_s: tuple[float, ...] = DEFAULT_DURATIONS_S
    overhead_s: float | None = None
    refresh_every: int = 4
    band_hz: tuple[float, float] | None = None
    antenna_k: float = 298.0
    antenna_index: float = 0.0
    #: Set by :meth:`CalibrateAdaptiveKind.rest`: carry on from the decisions stored.
    resumed: bool = False

    def overhead(self, period_s: float) -> float:
        """Switching and settling per cycle (s): the step's, else six spectrum periods."""
        return self.overhead_s if self.overhead_s is not None else 6 * period_s


def _durations(f: Fields, ctx: ParseContext) -> tuple[float, ...]:
    value = f.raw("durations_s", None)
    if value is None:
        return DEFAULT_DURATIONS_S
    if not isinstance(value, list) or not value:
        f.report("durations_s", "must be a non-empty list of seconds per position, e.g. [60, 300]")
        return DEFAULT_DURATIONS_S
    period = ctx.site.devices.spectrometer.period_s if ctx.site is not None else 0.0
    good = []
    for item in value:
        if isinstance(item, bool) or not isinstance(item, int | float) or not item > 0:
            f.report("durations_s", f"each duration must be a number of seconds > 0, not {item!r}")
        elif item < period:
            f.report("durations_s", f"{item:g} s is shorter than one spectrum ({period:g} s)")
        else:
            good.append(float(item))
    return tuple(good) or DEFAULT_DURATIONS_S


def _band(f: Fields, ctx: ParseContext) -> tuple[float, float] | None:
    value = f.raw("band_hz", None)
    if value is None:
        return None
    numbers = isinstance(value, list) and len(value) == 2 and all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in value
    )
    if not numbers or not 0 < value[0] < value[1]:
        f.report("band_hz", f"must be [low, high] in Hz with 0 < low < high, not {value!r}")
        return None
    site_band = ctx.site.band_hz if ctx.site is not None else None
    if site_band is not None and (value[0] >= site_band[1] or value[1] <= site_band[0]):
        f.report(
            "band_hz",
            f"[{value[0]:g}, {value[1]:g}] lies outside the site's calibration band "
            f"[{site_band[0]:g}, {site_band[1]:g}] (calibration.band_hz)",
        )
        return None
    return float(value[0]), float(value[1])


class CalibrateAdaptiveKind(RunnableKind[CalibrateAdaptive]):
    """``calibrate_adaptive``."""

    name = "calibrate_adaptive"
    step_type = CalibrateAdaptive
    keys = (
        "sources", "antenna", "target_mk", "target_fraction", "budget_s", "first_pass_s",
        "durations_s", "overhead_s", "refresh_every", "band_hz", "antenna_k", "antenna_index",
    )

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> CalibrateAdaptive:
        """Every key checked here, so that a bad value stops the run before anything moves."""
        sources = tuple(f.names("sources", ctx.sources, "source"))
        antenna = f.choice("antenna", ctx.sources, "ant") or "ant"
        if antenna in sources:
            f.report("antenna", f"{antenna!r} is also among the sources (the calibrators)")
        if len(set(sources)) < 2 and not f.failed:
            f.report("sources", "needs at least two different calibrators")
        target = f.number("target_mk", None, low=0.0, open_low=True) if f.has("target_mk") else None
        fraction = f.fraction("target_fraction", 0.5) if f.has("target_fraction") else None
        if target is not None and fraction is not None:
            f.report("target_fraction", "give target_mk or target_fraction, not both")
        first = ctx.integration(f, "first_pass_s") if f.has("first_pass_s") else 60.0
        budget = f.seconds("budget_s", 3600.0)
        overhead = f.number("overhead_s", None, low=0.0) if f.has("overhead_s") else None
        period = ctx.site.devices.spectrometer.period_s if ctx.site is not None else 0.0
        step = CalibrateAdaptive(
            where,
            sources=tuple(dict.fromkeys(sources)),
            antenna=antenna,
            target_mk=target,
            target_fraction=fraction,
            budget_s=budget,
            first_pass_s=first,
            durations_s=_durations(f, ctx),
            overhead_s=overhead,
            refresh_every=f.count("refresh_every", 4),
            band_hz=_band(f, ctx),
            antenna_k=f.number("antenna_k", 298.0, low=0.0, open_low=True),
            antenna_index=f.number("antenna_index", 0.0, low=-5.0, high=5.0),
        )
        cost = 3 * first + step.overhead(period)
        if not f.failed and cost * len(step.sources) > budget:
            f.report(
                "budget_s",
                f"{budget:g} s does not hold the first pass ({len(step.sources)} cycles of "
                f"about {cost:g} s); raise budget_s or lower first_pass_s",
            )
        return step

    def describe(self, step: CalibrateAdaptive) -> str:
        """Sources, target and budget."""
        target = f"to {step.target_mk:g} mK" if step.target_mk is not None else "no target"
        if step.target_fraction is not None:
            target = f"to {step.target_fraction:g} of the first pass's error"
        return (
            f"adaptive calibration of {len(step.sources)} calibrators for {step.antenna}, "
            f"{target}, budget {hms(step.budget_s)}"
        )

    def duration(self, step: CalibrateAdaptive, walk: TimingWalk) -> float:
        """The budget: the step never measures beyond it."""
        return step.budget_s

    def connections(self, step: CalibrateAdaptive) -> list[tuple[str, str]]:
        """Each calibrator's three Dicke positions."""
        return dicke_connections(step.sources)

    def rest(
        self, step: CalibrateAdaptive, measured: Sequence[tuple[str, str]]
    ) -> CalibrateAdaptive | None:
        """The step, resumed: it reads what is stored (cycles, decisions) and carries on."""
        return dataclasses.replace(step, resumed=True)

    def execute(self, step: CalibrateAdaptive, run: RunContext) -> None:
        """First pass, then the planner's choices until the target or the budget."""
        run_adaptive(step, run)

__all__ = ["DECISION_CHECK", "CalibrateAdaptive", "CalibrateAdaptiveKind"]
