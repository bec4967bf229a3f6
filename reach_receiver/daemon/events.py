"""What a job's followers see: its progress, its log and its end, kept and streamed.

Each job gets an event list (the last :data:`KEEP` events). A follower (the control
socket's ``follow``) first receives what happened so far, then every new event as it
comes, until the job's ``end`` event. :class:`HubProgress` is the run layer's
:class:`~reach_receiver.run.context.Progress` that feeds it, and :class:`HubLog` the
logging handler that adds the receiver's log lines while a job runs.

A follower prints the events as a local run prints its progress
(:mod:`reach_receiver.run.progress_lines`), so a step's event carries the run's clock
and real seconds, and progress inside a step is kept at the lines a local run shows
(a tenth of the step, at most one a real second): a long step neither floods a
follower over a slow link nor pushes the job's first events out of the kept ones.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from reach_receiver.clock import Clock
from reach_receiver.run.progress_lines import Throttle, real_seconds
from reach_receiver.schedule.steps import Step

#: Events kept per job for followers who attach late.
KEEP = 5000


class EventHub:
    """Events per job, and waiting for new ones (thread-safe)."""

    def __init__(self) -> None:
        self._events: dict[int, list[dict[str, Any]]] = {}
        self._dropped: dict[int, int] = {}
        self._changed = threading.Condition()

    def publish(self, job: int, kind: str, **fields: Any) -> None:
        """Add an event to a job's list and wake its followers."""
        event = {"job": job, "kind": kind, "time": time.time(), **fields}
        with self._changed:
            events = self._events.setdefault(job, [])
            events.append(event)
            if len(events) > KEEP:
                del events[: len(events) - KEEP]
                self._dropped[job] = self._dropped.get(job, 0) + 1
            self._changed.notify_all()

    def ended(self, job: int) -> bool:
        """Whether the job's end was published."""
        with self._changed:
            return any(e["kind"] == "end" for e in self._events.get(job, ()))

    def follow(
        self, job: int, stop: threading.Event, poll_s: float = 1.0
    ) -> Iterator[dict[str, Any]]:
        """Every event of ``job``, past and coming, up to its ``end`` (or ``stop``)."""
        seen = 0
        while not stop.is_set():
            with self._changed:
                events = self._events.get(job, [])
                if seen >= len(events):
                    self._changed.wait(poll_s)
                    events = self._events.get(job, [])
                fresh, seen = events[seen:], len(events)
            for event in fresh:
                yield event
                if event["kind"] == "end":
                    return


class HubProgress:
    """The run layer's progress, as events of one job; also keeps the current step."""

    def __init__(
        self,
        hub: EventHub,
        job: int,
        clock: Clock,
        on_step: Callable[[Step], None] | None = None,
        on_started: Callable[[Path], None] | None = None,
    ) -> None:
        self.hub = hub
        self.job = job
        self.clock = clock
        self.on_step = on_step
        self.on_started = on_started
        self.step_text = ""
        self.left_s: float | None = None
        self.start = clock.now()
        self.real_start = time.monotonic()
        self._throttle = Throttle()

    def started(self, directory: Path) -> None:
        """The run's directory."""
        if self.on_started is not None:
            self.on_started(directory)
        self.hub.publish(self.job, "started", run=str(directory))

    def step(self, index: int, total: int, step: Step, text: str, left_s: float | None) -> None:
        """A top-level step begins."""
        self.step_text, self.left_s = text, left_s
        self._throttle.new_step()
        self.hub.publish(
            self.job, "step", index=index, total=total, text=text, where=str(step.where),
            left_s=left_s, elapsed_s=self.clock.now() - self.start,
            real_s=real_seconds(self.clock, time.monotonic() - self.real_start),
        )
        if self.on_step is not None:
            self.on_step(step)

    def update(self, text: str, done: int, total: int, left_s: float | None) -> None:
        """Progress inside the step, as often as a local run shows it."""
        if self._throttle.due(done, total, time.monotonic()):
            self.hub.publish(
                self.job, "progress", text=text, done=done, total=total, left_s=left_s
            )


class HubLog(logging.Handler):
    """Log records of the receiver while a job runs, as that job's ``log`` events."""

    def __init__(self, hub: EventHub, job: int, level: int = logging.INFO) -> None:
        super().__init__(level)
        self.hub = hub
        self.job = job

    def emit(self, record: logging.LogRecord) -> None:
        """Publish one record."""
        try:
            self.hub.publish(
                self.job, "log", level=record.levelname, logger=record.name,
                message=record.getMessage(), created=record.created,
            )
        except Exception:  # a logging handler never raises
            self.handleError(record)
