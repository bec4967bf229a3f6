"""How long a schedule takes: per-step estimates, the dry-run timeline, impossible timing.

Estimates (seconds; ``P`` is the spectrometer's accumulation period, 30 s by default):

==================  =====================================================================
VNA sweep           ``points * averages / ifbw * 1.2 + 2`` (the latest ``vna_calibrate``'s
                    settings, else :class:`SweepSettings`' defaults, REACH's)
``vna_calibrate``   3 sweeps (short, open, load)
``test_load_check`` 1 sweep
``s11``             1 sweep per target
``dicke``           per source 3 positions x (``seconds`` + 2 P): one spectrum discarded
                    after each switch, one straddling the end
``spectrum``        ``seconds`` + 2 P
``tec``             ``wait.hold_s`` when waiting (at least that), else 1
``wait``            its ``seconds``; until the UTC time; until the next LST
``repeat``          ``count x max(period_s, one repetition)``, the last repetition
                    counting only its own duration
``calibrate``       10
``observe``         ``cycles x 3 x (seconds + 2 P)`` + one test-load sweep every
                    ``test_load_every`` cycles
``initialise``      5; ``power``, ``connect``, ``safe`` 1; ``temperatures`` 0
==================  =====================================================================

Only the first repetition of a ``repeat`` is listed (indented) in the timeline; its
duration stands for every repetition. The same walk finds impossible timing: a repeat
whose period is shorter than one repetition, and a ``wait until_utc`` earlier than the
estimated time at which the schedule reaches it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from datetime import datetime, timedelta, timezone

from reach_receiver.devices.vna_settings import SweepSettings
from reach_receiver.errors import ConfigError

from . import steps as s
from .lst import next_utc_at_lst
from .yaml_lines import Problem

SWEEP_OVERHEAD_FACTOR = 1.2
SWEEP_OVERHEAD_S = 2.0
FIXED_DURATIONS_S: dict[type[s.Step], float] = {
    s.Initialise: 5.0,
    s.Power: 1.0,
    s.Connect: 1.0,
    s.Safe: 1.0,
    s.Temperatures: 0.0,
    s.Calibrate: 10.0,
}


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


def _settings(sweep: s.Sweep) -> SweepSettings | None:
    given = {f.name: getattr(sweep, f.name) for f in fields(sweep)}
    try:
        return SweepSettings(**{k: v for k, v in given.items() if v is not None})
    except ConfigError:  # reported by the compiler
        return None


class _Walk:
    def __init__(self, start_utc: datetime, longitude_deg: float, period_s: float) -> None:
        self.start = start_utc
        self.longitude = longitude_deg
        self.period = period_s
        self.sweep = SweepSettings()
        self.entries: list[TimelineEntry] = []
        self.problems: list[Problem] = []

    def steps(self, steps: Sequence[s.Step], t: float, depth: int) -> float:
        for step in steps:
            t += self.step(step, t, depth)
        return t

    def step(self, step: s.Step, t: float, depth: int) -> float:
        index = len(self.entries)
        self.entries.append(TimelineEntry(t, 0.0, "", step.where, depth))
        if isinstance(step, s.Repeat):
            one = self.steps(step.steps, t, depth + 1) - t
            duration, text = self._repeat(step, one)
        else:
            duration, text = self._duration(step, t)
        self.entries[index] = TimelineEntry(t, duration, text, step.where, depth)
        return duration

    def _sweeps(self, count: int) -> float:
        return count * sweep_duration_s(self.sweep)

    def _spectra(self, positions: int, seconds: float) -> float:
        return positions * (seconds + 2 * self.period)

    def _duration(self, step: s.Step, t: float) -> tuple[float, str]:
        if type(step) in FIXED_DURATIONS_S:
            return FIXED_DURATIONS_S[type(step)], describe(step)
        if isinstance(step, s.VnaCalibrate):
            self.sweep = _settings(step.sweep) or self.sweep
            return self._sweeps(3), describe(step)
        if isinstance(step, s.TestLoadCheck):
            return self._sweeps(1), describe(step)
        if isinstance(step, s.MeasureS11):
            return self._sweeps(len(step.targets)), describe(step)
        if isinstance(step, s.MeasureSpectrum):
            return self._spectra(1, step.seconds), describe(step)
        if isinstance(step, s.Dicke):
            return self._spectra(3 * len(step.sources), step.seconds), describe(step)
        if isinstance(step, s.Observe):
            spectra = self._spectra(3 * step.cycles, step.seconds)
            return spectra + self._sweeps(step.cycles // step.test_load_every), describe(step)
        if isinstance(step, s.Tec):
            return (step.wait.hold_s if step.wait else 1.0), describe(step)
        if isinstance(step, s.Wait):
            return self._wait(step, t)
        return 0.0, describe(step)

    def _wait(self, step: s.Wait, t: float) -> tuple[float, str]:
        now = self.start + timedelta(seconds=t)
        if step.seconds is not None:
            return step.seconds, describe(step)
        if step.until_utc is not None:
            until = _utc(step.until_utc)
            if until < now:
                self.problems.append(
                    Problem(
                        step.where.file,
                        step.where.line,
                        "wait.until_utc",
                        f"{until:%Y-%m-%dT%H:%M:%SZ} is before the schedule gets there "
                        f"(estimated {now:%Y-%m-%dT%H:%M:%SZ}, {hms(t)} after the start)",
                    )
                )
                return 0.0, describe(step)
            return (until - now).total_seconds(), describe(step)
        if step.until_lst_h is not None:
            until = next_utc_at_lst(now, step.until_lst_h, self.longitude)
            text = f"{describe(step)} ({until:%Y-%m-%d %H:%M:%S} UTC)"
            return (until - now).total_seconds(), text
        return 0.0, describe(step)

    def _repeat(self, step: s.Repeat, one: float) -> tuple[float, str]:
        period = step.period_s
        if period is not None and period < one:
            self.problems.append(
                Problem(
                    step.where.file,
                    step.where.line,
                    "repeat.period_s",
                    f"period {hms(period)} is shorter than one repetition ({hms(one)} estimated)",
                )
            )
        every = max(period or 0.0, one)
        return (step.count - 1) * every + one, describe(step)


def describe(step: s.Step) -> str:
    """A one-line description of a step for the timeline."""
    if isinstance(step, s.Initialise):
        return f"initialise, rails {', '.join(step.rails) or 'none'} on"
    if isinstance(step, s.Power):
        return "power " + ", ".join(f"{r} {'on' if on else 'off'}" for r, on in step.states)
    if isinstance(step, s.Connect):
        return f"connect {step.source} to the {step.to.upper()}"
    if isinstance(step, s.VnaCalibrate):
        return "VNA SOL calibration (3 sweeps)"
    if isinstance(step, s.TestLoadCheck):
        return f"test-load check ({step.statistic} within {step.tolerance:.1%})"
    if isinstance(step, s.MeasureS11):
        return f"S11 of {', '.join(step.targets)}"
    if isinstance(step, s.MeasureSpectrum):
        return f"spectrum of {step.source} for {hms(step.seconds)}"
    if isinstance(step, s.Dicke):
        return f"Dicke cycles of {', '.join(step.sources)}, {hms(step.seconds)} per position"
    if isinstance(step, s.Temperatures):
        return f"temperatures every {step.period_s:g} s"
    if isinstance(step, s.Tec):
        text = f"TEC setpoint {step.setpoint_c:g} C"
        if step.wait is not None:
            text += f", wait {hms(step.wait.hold_s)} within {step.wait.tolerance_c:g} C"
        return text
    if isinstance(step, s.Wait):
        if step.seconds is not None:
            return f"wait {hms(step.seconds)}"
        if step.until_utc is not None:
            return f"wait until {step.until_utc:%Y-%m-%d %H:%M:%S} UTC"
        if step.until_lst_h is not None:
            return f"wait until LST {step.until_lst_h:.4g} h"
        return "wait"
    if isinstance(step, s.Repeat):
        every = f" every {hms(step.period_s)}" if step.period_s is not None else ""
        return f"repeat {step.count} x{every}"
    if isinstance(step, s.Calibrate):
        return f"calibrate {step.f_lo_hz / 1e6:g}-{step.f_hi_hz / 1e6:g} MHz"
    if isinstance(step, s.Observe):
        return (
            f"observe {step.source}: {step.cycles} Dicke cycles, {hms(step.seconds)} per "
            f"position, test load every {step.test_load_every}"
        )
    if isinstance(step, s.Safe):
        return "safe state"
    return type(step).__name__.lower()


def _utc(time: datetime) -> datetime:
    return time.replace(tzinfo=timezone.utc) if time.tzinfo is None else time


def _walk(
    steps: Sequence[s.Step], start_utc: datetime, longitude_deg: float, period_s: float
) -> tuple[_Walk, float]:
    walk = _Walk(_utc(start_utc), longitude_deg, period_s)
    return walk, walk.steps(steps, 0.0, 0)


def timeline(
    schedule: s.Schedule,
    *,
    start_utc: datetime,
    longitude_deg: float,
    spectrum_period_s: float = 30.0,
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
        The spectrometer's accumulation period.

    Returns
    -------
    list of TimelineEntry
        In order; a repeat's first repetition follows it, one level deeper.
    """
    walk, _ = _walk(schedule.steps, start_utc, longitude_deg, spectrum_period_s)
    return walk.entries


def estimated_duration_s(
    schedule: s.Schedule,
    *,
    start_utc: datetime,
    longitude_deg: float,
    spectrum_period_s: float = 30.0,
) -> float:
    """The schedule's estimated total duration in seconds (see :func:`timeline`)."""
    return _walk(schedule.steps, start_utc, longitude_deg, spectrum_period_s)[1]


def timing_problems(
    steps: Sequence[s.Step],
    *,
    start_utc: datetime,
    longitude_deg: float,
    spectrum_period_s: float = 30.0,
) -> list[Problem]:
    """Impossible timing: repeat periods shorter than a repetition, waits already past."""
    return _walk(steps, start_utc, longitude_deg, spectrum_period_s)[0].problems


def format_timeline(entries: Sequence[TimelineEntry]) -> str:
    """A readable table of the timeline (start, duration, step, file:line) and the total."""
    rows = [("start", "duration", "step", "where")]
    end = 0.0
    for entry in entries:
        rows.append(
            (
                hms(entry.start_s),
                hms(entry.duration_s),
                "  " * entry.depth + entry.description,
                str(entry.where),
            )
        )
        if entry.depth == 0:
            end = entry.start_s + entry.duration_s
    widths = [max(len(row[i]) for row in rows) for i in range(3)]
    lines = [
        f"{a:>{widths[0]}}  {b:>{widths[1]}}  {c:<{widths[2]}}  {d}".rstrip() for a, b, c, d in rows
    ]
    lines.append(f"{'total':>{widths[0]}}  {hms(end):>{widths[1]}}")
    return "\n".join(lines)
