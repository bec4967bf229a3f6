"""Timed schedules: a sidereal-daily or daily trigger, and what happens to a missed one.

Each timer of the site file (:mod:`reach_receiver.config.daemon`) has occurrences: every
day at an hour of UTC, or every sidereal day at an hour of local sidereal time (the sky
overhead repeats 3 min 56 s earlier each solar day). The daemon asks :meth:`Timers.due`
on every turn of its main loop; an occurrence that passed since the last turn fires once.

Across a restart, ``timers.json`` in the state directory remembers when each timer last
fired and when the timers were last looked at. An occurrence that passed while the
daemon was down is *missed*: with ``policy: late`` it fires at start if it is at most
``window_s`` old, otherwise (or with ``policy: skip``) it is skipped, with a log line
either way. The first start ever fires nothing from the past.

Each timer remembers its current interval between occurrences, so a turn of the loop
asks astropy for a sidereal time only when an occurrence has passed (twice a sidereal
day): each question costs about 4 ms (:mod:`reach_receiver.schedule.lst`), which every
0.5 s turn would otherwise pay per timer.

A ``timers.json`` that cannot be written (a full disk) keeps its previous contents: the
daemon goes on with the timers' state in memory, logs the failure once, names it in
:attr:`Timers.write_error` and writes again at the next checkpoint.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

from reach_receiver.config.daemon import DaemonSettings, TimerSettings
from reach_receiver.schedule.lst import SIDEREAL_RATE, next_utc_at_lst

from .state_file import read_state, write_state

log = logging.getLogger(__name__)

SIDEREAL_DAY_S = 86_400.0 / SIDEREAL_RATE
#: How often the "last looked at" time is written (s of the daemon's clock).
CHECKPOINT_S = 60.0


@dataclass(frozen=True)
class Trigger:
    """One occurrence of a timer: when it was due, and whether it fires late."""

    timer: TimerSettings
    at: float
    late: bool = False


def previous_occurrence(timer: TimerSettings, now: float, longitude_deg: float) -> float:
    """The timer's latest occurrence at or before ``now`` (Unix seconds)."""
    if timer.at_lst_h is not None:
        after = datetime.fromtimestamp(now - SIDEREAL_DAY_S, tz=timezone.utc)
        found = next_utc_at_lst(after, timer.at_lst_h, longitude_deg).timestamp()
        return found if found <= now else found - SIDEREAL_DAY_S
    minutes = timer.utc_minutes
    if minutes is None:
        raise ValueError(f"timer {timer.name} has no time")
    today = datetime.fromtimestamp(now, tz=timezone.utc).date()
    day = datetime(today.year, today.month, today.day, tzinfo=timezone.utc)
    at = (day + timedelta(minutes=minutes)).timestamp()
    return at if at <= now else at - 86_400.0


class Timers:
    """The site's timers and their state file.

    Parameters
    ----------
    settings
        The site's daemon settings (timers, missed-trigger policy).
    longitude_deg
        The site's east longitude, for sidereal time.
    path
        ``timers.json`` in the state directory.
    """

    def __init__(self, settings: DaemonSettings, longitude_deg: float, path: Path) -> None:
        self.settings = settings
        self.longitude_deg = longitude_deg
        self.path = Path(path)
        self.fired: dict[str, float] = {}
        self.checked: float | None = None
        #: Why the last write of the state file failed (``None``: it is up to date).
        self.write_error: str | None = None
        self._written = -float("inf")
        #: Why the state file could not be read at start (``None``: it was, or was absent).
        self.read_error: str | None = None
        #: Per timer, its occurrence at or before the last ``now`` asked and the next one.
        self._interval: dict[str, tuple[float, float]] = {}
        found, self.read_error = read_state(self.path, _parse_state)
        if found is not None:
            self.fired, self.checked = found

    def start(self, now: float) -> list[Trigger]:
        """At the daemon's start: the occurrences missed while it was down, per the policy."""
        if self.checked is None:  # first start ever: nothing from the past
            self._save(now)
            return []
        policy, window = self.settings.missed_policy, self.settings.missed_window_s
        late: list[Trigger] = []
        for timer in self.settings.timers:
            at = self._interval_at(timer, now)[0]
            if at <= max(self.checked, self.fired.get(timer.name, -float("inf"))):
                continue
            age = now - at
            if policy == "late" and age <= window:
                log.warning("timer %s: missed at %s, run late (%.0f s)", timer.name, _utc(at), age)
                late.append(Trigger(timer, at, late=True))
                self.fired[timer.name] = at
            else:
                why = "policy skip" if policy == "skip" else f"older than {window:g} s"
                log.warning("timer %s: missed at %s, skipped (%s)", timer.name, _utc(at), why)
        self._save(now)
        return late

    def due(self, now: float) -> list[Trigger]:
        """The occurrences that passed since the last call (each fires once)."""
        due: list[Trigger] = []
        for timer in self.settings.timers:
            at = self._interval_at(timer, now)[0]
            since = max(self.checked or now, self.fired.get(timer.name, -float("inf")))
            if since < at <= now:
                log.info("timer %s: due at %s", timer.name, _utc(at))
                due.append(Trigger(timer, at))
                self.fired[timer.name] = at
        if due or now - self._written >= CHECKPOINT_S:
            self._save(now)
        else:
            self.checked = now
        return due

    def next_occurrences(self, now: float) -> dict[str, float]:
        """When each timer fires next."""
        return {t.name: self._interval_at(t, now)[1] for t in self.settings.timers}

    def _interval_at(self, timer: TimerSettings, now: float) -> tuple[float, float]:
        """The timer's occurrence at or before ``now`` and the one after it (remembered)."""
        known = self._interval.get(timer.name)
        if known is not None and known[0] <= now < known[1]:
            return known
        at = previous_occurrence(timer, now, self.longitude_deg)
        if timer.at_lst_h is None:
            following = at + 86_400.0
        else:  # the sidereal day varies by milliseconds: ask rather than add
            after = datetime.fromtimestamp(at + 1.0, tz=timezone.utc)
            following = next_utc_at_lst(after, timer.at_lst_h, self.longitude_deg).timestamp()
        self._interval[timer.name] = (at, following)
        return at, following

    def _save(self, now: float) -> None:
        self.checked = now
        self._written = now  # a failed write is tried again at the next checkpoint
        state = json.dumps({"fired": self.fired, "checked": now})
        self.write_error = write_state(self.path, state, self.write_error)


def _parse_state(data: Any) -> tuple[dict[str, float], float | None]:
    """When each timer last fired and when they were last checked, from the JSON."""
    fired = {str(k): float(v) for k, v in data.get("fired", {}).items()}
    checked = data.get("checked")
    return fired, None if checked is None else float(checked)


def _utc(at: float) -> str:
    return datetime.fromtimestamp(at, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
