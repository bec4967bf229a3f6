"""Alarms: thresholds held for a while, with hysteresis; a log line and a hook per change.

Each :class:`~reach_receiver.config.monitoring.AlarmRule` watches every series of its
metric (those with its labels). For one series the alarm is *raised* once its values
have been above ``above`` (or below ``below``) without a break for the rule's ``for_s``
(at the first such value when it is 0), and *cleared* only when a value is back inside
by the hysteresis: ``value <= above - hysteresis`` (``value >= below + hysteresis``).
A NaN value of a series that is read (a thermocouple flagged open: its own alarm says
so) changes nothing; a reading of status ``unknown`` (a device powered off, not yet
brought up, or not read by anyone) breaks a condition that was building up and clears
a raised alarm: nobody is told a device is silent while it is switched off.

Every alarm has two names: its text for people (:mod:`.wording`: "TC-08 not answering
for 5 min (since 14:02 UTC; threshold 2 min)") and its *detail*, ``rule: series key``
(:attr:`Alarm.id`), for scripts. Each change is logged with both (``alarm raised:`` at
WARNING, ``alarm cleared:`` at INFO) and handed to the :class:`Hook`.

The hook runs the site's command in a thread of its own with a timeout (then it is
killed), so a mail server that hangs never holds up the daemon; at most
:data:`MAX_PENDING` hook runs wait, later ones are dropped with a log line.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
import queue
import subprocess
import threading
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

from reach_receiver.config.monitoring import AlarmRule

from . import wording
from .readings import ERROR, NOMINAL, UNKNOWN, WARN, Reading

log = logging.getLogger(__name__)

#: Hook runs waiting at most; beyond, events are dropped (and logged).
MAX_PENDING = 32


@dataclass
class Alarm:
    """A raised alarm: its rule, its series, the latest value, since when it holds."""

    rule: AlarmRule
    key: str
    value: float
    raised_at: float
    since: float = math.nan  # the first value out of range (``raised_at`` when not given)
    labels: Mapping[str, str] = field(default_factory=dict)
    note: str = ""  # the latest reading's note (:attr:`Reading.note`)

    def __post_init__(self) -> None:
        if math.isnan(self.since):
            self.since = self.raised_at

    @property
    def id(self) -> str:
        """``rule name: series key``: one alarm per rule and series (the detail)."""
        return f"{self.rule.name}: {self.key}"

    def text(self, now: float | None = None) -> str:
        """The alarm in words at ``now`` (at the time it was raised by default)."""
        return wording.raised(self.rule, self.labels, self.value, self.since,
                              self.raised_at if now is None else now, self.note)

    @property
    def message(self) -> str:
        """The text at the time it was raised, then the detail in brackets."""
        return f"{self.text()} [{self.id}]"

    def as_dict(self, now: float) -> dict[str, object]:
        """For the daemon's ``status`` reply: the text, the detail and the numbers."""
        rule = self.rule
        return {
            "text": self.text(now), "id": self.id, "name": rule.name, "series": self.key,
            "severity": rule.severity, "value": None if math.isnan(self.value) else self.value,
            "above": rule.above, "below": rule.below, "for_s": rule.for_s,
            "since": self.since, "raised_at": self.raised_at,
        }


class AlarmBoard:
    """The alarms of a set of rules over a stream of readings (module docstring)."""

    def __init__(self, rules: Sequence[AlarmRule], hook: Hook | None = None) -> None:
        self.rules = [r for r in rules if r.enabled]
        self.hook = hook
        self.active: dict[str, Alarm] = {}
        self.history: list[tuple[str, Alarm, float]] = []  # (raised|cleared, alarm, time)
        self._onset: dict[str, float] = {}  # out of range since, not raised yet

    def update(self, readings: Iterable[Reading]) -> list[Reading]:
        """Check each reading against the rules; return them with statuses upgraded."""
        out = []
        for reading in readings:
            worst = reading.status
            for rule in self.rules:
                if rule.metric != reading.metric or not rule.labels.items() <= \
                        reading.labels.items():
                    continue
                if self._check(rule, reading):
                    worst = _worse(worst, ERROR if rule.severity == "error" else WARN)
            if worst != reading.status:
                reading = dataclasses.replace(reading, status=worst)
            out.append(reading)
        return out

    def _check(self, rule: AlarmRule, reading: Reading) -> bool:
        """Raise or clear ``rule`` for the reading's series; whether it is raised after."""
        alarm_id = f"{rule.name}: {reading.key}"
        raised = self.active.get(alarm_id)
        value, t = reading.value, reading.timestamp
        if reading.status == UNKNOWN:
            self._onset.pop(alarm_id, None)
            if raised is not None:
                self._clear(alarm_id, raised, value, t, unknown=True)
            return False
        if math.isnan(value):
            return raised is not None
        high = rule.above is not None and value > rule.above
        low = rule.below is not None and value < rule.below
        if raised is not None:
            raised.value = value
            raised.note = reading.note
            inside_high = rule.above is None or value <= rule.above - rule.hysteresis
            inside_low = rule.below is None or value >= rule.below + rule.hysteresis
            if inside_high and inside_low:
                self._clear(alarm_id, raised, value, t)
                return False
            return True
        if not (high or low):
            self._onset.pop(alarm_id, None)
            return False
        since = self._onset.setdefault(alarm_id, t)
        if t - since < rule.for_s:
            return False
        del self._onset[alarm_id]
        alarm = Alarm(rule, reading.key, value, t, since, dict(reading.labels), reading.note)
        self.active[alarm_id] = alarm
        self.history.append(("raised", alarm, t))
        log.warning("alarm raised: %s", alarm.message)
        if self.hook is not None:
            self.hook.fire("raised", rule.name, alarm.text(), alarm.id)
        return True

    def _clear(self, alarm_id: str, alarm: Alarm, value: float, t: float,
               unknown: bool = False) -> None:
        del self.active[alarm_id]
        self.history.append(("cleared", alarm, t))
        text = wording.cleared(alarm.rule, alarm.labels, value, alarm.since, t, unknown,
                               alarm.note)
        log.info("alarm cleared: %s [%s]", text, alarm.id)
        if self.hook is not None:
            self.hook.fire("cleared", alarm.rule.name, text, alarm.id)

    def messages(self, now: float | None = None) -> list[str]:
        """The raised alarms in words, one line each (their durations at ``now``)."""
        return [alarm.text(now) for alarm in self.active.values()]

    def details(self, now: float) -> list[dict[str, object]]:
        """The raised alarms with their text, detail and numbers (:meth:`Alarm.as_dict`)."""
        return [alarm.as_dict(now) for alarm in self.active.values()]

    def ids(self) -> list[str]:
        """The raised alarms' details, ``rule: series key``."""
        return list(self.active)


def _worse(a: str, b: str) -> str:
    order = (NOMINAL, WARN, ERROR)
    if a not in order:
        return a
    return a if order.index(a) >= order.index(b) else b


class Hook:
    """Runs ``command + [event, name, text, detail]`` off the caller's thread, with a timeout.

    ``event`` is ``raised`` or ``cleared``, ``name`` the rule's, ``text`` the alarm in
    words and ``detail`` its ``rule: series key``.
    """

    def __init__(self, command: Sequence[str], timeout_s: float) -> None:
        self.command = list(command)
        self.timeout_s = timeout_s
        self._queue: queue.Queue[list[str] | None] = queue.Queue(MAX_PENDING)
        self._thread = threading.Thread(target=self._run, name="alarm-hook", daemon=True)
        self._thread.start()
        self.completed: list[int | None] = []  # exit codes (None: killed at the timeout)

    def fire(self, event: str, name: str, text: str, detail: str = "") -> None:
        """Queue one run of the command; never blocks."""
        try:
            self._queue.put_nowait([*self.command, event, name, text, detail])
        except queue.Full:
            log.error("alarm hook: %d runs waiting; dropped: %s %s", MAX_PENDING, event, name)

    def _run(self) -> None:
        while (argv := self._queue.get()) is not None:
            try:
                process = subprocess.Popen(argv, stdin=subprocess.DEVNULL,
                                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            except OSError as err:
                log.error("alarm hook %s cannot run: %s", argv[0], err)
                self.completed.append(None)
                continue
            try:
                _, err_text = process.communicate(timeout=self.timeout_s)
            except subprocess.TimeoutExpired:
                process.kill()
                process.communicate()
                log.error("alarm hook %s killed after %g s", argv[0], self.timeout_s)
                self.completed.append(None)
                continue
            if process.returncode:
                detail = err_text.decode(errors="replace").strip()[-200:]
                log.error("alarm hook %s exited %d: %s", argv[0], process.returncode, detail)
            self.completed.append(process.returncode)

    def close(self, timeout_s: float = 1.0) -> None:
        """Stop after the runs already queued (waiting at most ``timeout_s`` for them)."""
        with contextlib.suppress(queue.Full):
            self._queue.put_nowait(None)
        self._thread.join(timeout=timeout_s)
