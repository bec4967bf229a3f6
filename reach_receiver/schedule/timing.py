"""How long a schedule takes: the dry-run timeline and impossible timing.

Each kind estimates its own duration (:meth:`~.kinds.StepKind.duration`) with the help
of a :class:`TimingWalk`, which knows two shared costs (``P`` is the spectrometer's
accumulation period, from the site file):

==================  =====================================================================
VNA sweep           ``points * averages / ifbw * 1.2 + 2`` (the latest ``vna_calibrate``'s
                    settings, else :class:`SweepSettings`' defaults, REACH's)
integration         ``seconds + 2 P`` per position: one spectrum discarded after each
                    switch, one straddling the end
==================  =====================================================================

Only the first repetition of a ``repeat`` is listed (indented) in the timeline; its
duration stands for every repetition. The same walk finds impossible timing, which kinds
report through :meth:`TimingWalk.report` (a repeat whose period is shorter than one
repetition, a ``wait until_utc`` earlier than the schedule gets there). While a
schedule is checked, the walk also refuses a schedule lasting more than
:data:`~.limits.MAX_DURATION_S` (at the step that passes it) and counts the steps it
visits (:class:`~.limits.Budget`), so that huge durations and repeats nested in repeats
stop the check instead of overflowing a date or running for hours.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import PurePath

from reach_receiver.config.yaml_lines import Problem
from reach_receiver.devices.vna_settings import SweepSettings

from . import steps as s
from .kinds import KindRegistry
from .limits import MAX_DURATION_S, Budget, LimitExceeded, duration_text

SWEEP_OVERHEAD_FACTOR = 1.2
SWEEP_OVERHEAD_S = 2.0


@dataclass(frozen=True)
class TimelineEntry:
    """One line of the dry-run timeline: when a step starts (s from the schedule's start)."""

    start_s: float
    duration_s: float
    description: str
    where: s.Where
    depth: int


def sweep_duration_s(settings: SweepSettings) -> float:
    """Estimated time of one VNA sweep: ``points * averages / ifbw * 1.2 + 2`` s."""
    return settings.nominal_duration_s() * SWEEP_OVERHEAD_FACTOR + SWEEP_OVERHEAD_S


def hms(seconds: float) -> str:
    """``h:mm:ss`` (hours unbounded, rounded to the second)."""
    total = round(seconds)
    sign = "-" if total < 0 else ""
    hours, rest = divmod(abs(total), 3600)
    return f"{sign}{hours}:{rest // 60:02d}:{rest % 60:02d}"


def as_utc(time: datetime) -> datetime:
    """A datetime in UTC; a naive one is taken to be UTC."""
    return time.replace(tzinfo=timezone.utc) if time.tzinfo is None else time


class TimingWalk:
    """Walks a step list in order, asking each kind for its duration.

    Attributes
    ----------
    t
        Seconds from the schedule's start at which the current step starts.
    sweep
        The VNA settings in force (a ``vna_calibrate`` step changes them).
    budget
        While checking: counts the steps visited, and bounds the duration.
    """

    def __init__(
        self,
        kinds: KindRegistry,
        start_utc: datetime,
        longitude_deg: float,
        spectrum_period_s: float,
        budget: Budget | None = None,
    ) -> None:
        self.kinds = kinds
        self.start = as_utc(start_utc)
        self.longitude_deg = longitude_deg
        self.period_s = spectrum_period_s
        self.sweep = SweepSettings()
        self.t = 0.0
        self.entries: list[TimelineEntry] = []
        self.problems: list[Problem] = []
        self.budget = budget
        self._depth = 0

    @property
    def now_utc(self) -> datetime:
        """The estimated UTC at which the current step starts."""
        return self.start + timedelta(seconds=self.t)

    def sweeps(self, count: int) -> float:
        """Seconds that ``count`` sweeps at the current settings take."""
        return count * sweep_duration_s(self.sweep)

    def spectra(self, positions: int, seconds: float) -> float:
        """Seconds that ``positions`` integrations of ``seconds`` each take."""
        return positions * (seconds + 2 * self.period_s)

    def report(self, step: s.Step, key: str, message: str) -> None:
        """Record impossible timing at the step's line."""
        self.problems.append(Problem(step.where.file, step.where.line, key, message))

    def walk(self, steps: Sequence[s.Step]) -> float:
        """Walk ``steps`` from :attr:`t`; return their total duration (``t`` is restored)."""
        start = self.t
        for step in steps:
            self.t += self._step(step)
        total, self.t = self.t - start, start
        return total

    def nested(self, steps: Sequence[s.Step]) -> float:
        """Walk steps nested in the current one (one level deeper in the timeline)."""
        self._depth += 1
        try:
            return self.walk(steps)
        finally:
            self._depth -= 1

    def _step(self, step: s.Step) -> float:
        key = self.kinds.of(step).name if self.kinds.knows(step) else "<step>"
        if self.budget is not None:
            self.budget.visit(step.where.file, step.where.line, key)
        index = len(self.entries)
        self.entries.append(TimelineEntry(self.t, 0.0, "", step.where, self._depth))
        if self.kinds.knows(step):
            duration, text = self.kinds.of(step).timing(step, self)
        else:  # a step that could not be read (reported already)
            duration, text = 0.0, type(step).__name__.lower()
        self.entries[index] = TimelineEntry(self.t, duration, text, step.where, self._depth)
        end = self.t + duration
        if self.budget is not None and not (math.isfinite(end) and end <= MAX_DURATION_S):
            message = (
                f"the schedule would last more than {duration_text(MAX_DURATION_S)}"
                f" by the end of this step ({duration_text(end)} estimated)"
            )
            raise LimitExceeded(Problem(step.where.file, step.where.line, key, message))
        return duration


def _walk(
    steps: Sequence[s.Step],
    kinds: KindRegistry,
    start_utc: datetime,
    longitude_deg: float,
    spectrum_period_s: float,
    budget: Budget | None = None,
) -> tuple[TimingWalk, float]:
    walk = TimingWalk(kinds, start_utc, longitude_deg, spectrum_period_s, budget)
    return walk, walk.walk(steps)


def _kinds(schedule: s.Schedule) -> KindRegistry:
    if schedule.kinds is None:
        raise ValueError(f"schedule {schedule.name!r} was built without its step kinds")
    return schedule.kinds


def timeline(
    schedule: s.Schedule,
    *,
    start_utc: datetime,
    longitude_deg: float,
    spectrum_period_s: float,
) -> list[TimelineEntry]:
    """The dry-run timeline: every step with its estimated start and duration.

    Parameters
    ----------
    schedule
        A compiled schedule.
    start_utc
        When it starts (naive datetimes are UTC); fixes ``wait`` until a time or an LST.
    longitude_deg
        The site's east longitude, for LST waits.
    spectrum_period_s
        The spectrometer's accumulation period (the site file's).

    Returns
    -------
    list of TimelineEntry
        In order; a repeat's first repetition follows it, one level deeper.
    """
    kinds = _kinds(schedule)
    walk, _ = _walk(schedule.steps, kinds, start_utc, longitude_deg, spectrum_period_s)
    return walk.entries


def estimated_duration_s(
    schedule: s.Schedule,
    *,
    start_utc: datetime,
    longitude_deg: float,
    spectrum_period_s: float,
) -> float:
    """The schedule's estimated total duration in seconds (see :func:`timeline`)."""
    kinds = _kinds(schedule)
    return _walk(schedule.steps, kinds, start_utc, longitude_deg, spectrum_period_s)[1]


def timing_problems(
    steps: Sequence[s.Step],
    kinds: KindRegistry,
    *,
    start_utc: datetime,
    longitude_deg: float,
    spectrum_period_s: float,
    budget: Budget | None = None,
) -> list[Problem]:
    """Impossible timing: repeat periods shorter than a repetition, waits already past.

    With a ``budget``, a schedule too long or too costly to walk raises
    :class:`~.limits.LimitExceeded` at the step where its bound is passed.
    """
    walk = _walk(steps, kinds, start_utc, longitude_deg, spectrum_period_s, budget)[0]
    return walk.problems


def format_timeline(entries: Sequence[TimelineEntry], width: int = 80) -> str:
    """A table of the timeline (start, duration, step and file:line) and the total.

    Each row fits in ``width`` columns (an operator's terminal over SSH): a long step is
    wrapped under its own column, and its place in the schedule, ``file:line`` with the
    file's name only, follows the step in brackets.
    """
    rows = [(hms(e.start_s), hms(e.duration_s), e.depth, e.description, e.where) for e in entries]
    end = max((e.start_s + e.duration_s for e in entries if e.depth == 0), default=0.0)
    w0 = max([len("start"), *(len(r[0]) for r in rows)])
    w1 = max([len("duration"), len(hms(end)), *(len(r[1]) for r in rows)])
    lead = w0 + w1 + 4
    lines = [f"{'start':>{w0}}  {'duration':>{w1}}  step  where"]
    for start, duration, depth, description, where in rows:
        indent = "  " * depth
        text = f"{description} [{PurePath(where.file).name}:{where.line}]"
        wrapped = textwrap.wrap(
            text, max(20, width - lead - len(indent) - 2), break_on_hyphens=False
        ) or [""]
        lines.append(f"{start:>{w0}}  {duration:>{w1}}  {indent}{wrapped[0]}")
        lines += [" " * (lead + len(indent) + 2) + more for more in wrapped[1:]]
    lines.append(f"{'total':>{w0}}  {hms(end):>{w1}}")
    return "\n".join(lines)
