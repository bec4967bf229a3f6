"""Alarms: thresholds with hysteresis on the readings, a log line and a hook per change.

Each :class:`~reach_receiver.config.monitoring.AlarmRule` watches every series of its
metric (those with its labels). For one series the alarm is *raised* when a value is
above ``above`` (or below ``below``) and *cleared* only when it is back inside by the
hysteresis: ``value <= above - hysteresis`` (``value >= below + hysteresis``). A NaN
value changes nothing (a failed read is its device's alarm, not the metric's). Each
change is logged (``alarm raised: ...`` at WARNING or ERROR, ``alarm cleared: ...`` at
INFO) and handed to the :class:`Hook`.

The hook runs the site's command in a thread of its own with a timeout (then it is
killed), so a mail server that hangs never holds up the daemon; at most
:data:`MAX_PENDING` hook runs wait, later ones are dropped with a log line.
"""

from __future__ import annotations

import contextlib
import logging
import math
import queue
import subprocess
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from reach_receiver.config.monitoring import AlarmRule

from .readings import ERROR, NOMINAL, WARN, Reading

log = logging.getLogger(__name__)

#: Hook runs waiting at most; beyond, events are dropped (and logged).
MAX_PENDING = 32


@dataclass(frozen=True)
class Alarm:
    """A raised alarm: its rule, the series, the value that raised it, and when."""

    rule: AlarmRule
    key: str
    value: float
    raised_at: float

    @property
    def id(self) -> str:
        """``rule name: series key``: one alarm per rule and series."""
        return f"{self.rule.name}: {self.key}"

    @property
    def message(self) -> str:
        """One line for logs, ``reach-run --status`` and the hook."""
        limit = (
            f"above {self.rule.above:g}"
            if self.rule.above is not None and self.value > self.rule.above
            else f"below {self.rule.below:g}"
        )
        return f"{self.rule.name}: {self.key} = {self.value:g}, {limit}"


class AlarmBoard:
    """The alarms of a set of rules over a stream of readings (module docstring)."""

    def __init__(self, rules: Sequence[AlarmRule], hook: Hook | None = None) -> None:
        self.rules = [r for r in rules if r.enabled]
        self.hook = hook
        self.active: dict[str, Alarm] = {}
        self.history: list[tuple[str, Alarm, float]] = []  # (raised|cleared, alarm, time)

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
                reading = Reading(reading.metric, reading.value, reading.unit,
                                  reading.timestamp, worst, reading.labels)
            out.append(reading)
        return out

    def _check(self, rule: AlarmRule, reading: Reading) -> bool:
        """Raise or clear ``rule`` for the reading's series; whether it is raised after."""
        alarm_id = f"{rule.name}: {reading.key}"
        raised = self.active.get(alarm_id)
        value = reading.value
        if math.isnan(value):
            return raised is not None
        high = rule.above is not None and value > rule.above
        low = rule.below is not None and value < rule.below
        if raised is None and (high or low):
            alarm = Alarm(rule, reading.key, value, reading.timestamp)
            self.active[alarm_id] = alarm
            self.history.append(("raised", alarm, reading.timestamp))
            level = logging.ERROR if rule.severity == "error" else logging.WARNING
            log.log(level, "alarm raised: %s", alarm.message)
            if self.hook is not None:
                self.hook.fire("raised", alarm.rule.name, alarm.message)
            return True
        if raised is not None:
            inside_high = rule.above is None or value <= rule.above - rule.hysteresis
            inside_low = rule.below is None or value >= rule.below + rule.hysteresis
            if inside_high and inside_low:
                del self.active[alarm_id]
                self.history.append(("cleared", raised, reading.timestamp))
                text = f"{raised.id} back to {value:g}"
                log.info("alarm cleared: %s", text)
                if self.hook is not None:
                    self.hook.fire("cleared", rule.name, text)
                return False
            return True
        return False

    def messages(self) -> list[str]:
        """The raised alarms, one line each."""
        return [alarm.message for alarm in self.active.values()]


def _worse(a: str, b: str) -> str:
    order = (NOMINAL, WARN, ERROR)
    if a not in order:
        return a
    return a if order.index(a) >= order.index(b) else b


class Hook:
    """Runs ``command + [event, name, message]`` off the caller's thread, with a timeout."""

    def __init__(self, command: Sequence[str], timeout_s: float) -> None:
        self.command = list(command)
        self.timeout_s = timeout_s
        self._queue: queue.Queue[list[str] | None] = queue.Queue(MAX_PENDING)
        self._thread = threading.Thread(target=self._run, name="alarm-hook", daemon=True)
        self._thread.start()
        self.completed: list[int | None] = []  # exit codes (None: killed at the timeout)

    def fire(self, event: str, name: str, message: str) -> None:
        """Queue one run of the command; never blocks."""
        try:
            self._queue.put_nowait([*self.command, event, name, message])
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
