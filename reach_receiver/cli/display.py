"""What ``reach-run`` shows while a run goes: each step, and progress inside long ones.

Two faces of one :class:`~reach_receiver.run.context.Progress`:

* on a terminal, rich's live progress bar for the current step (which source and
  position, spectra so far, time left in the step) under the plain lines of each
  top-level step;
* otherwise (a pipe, a log, ``nohup``), plain lines within 80 columns
  (:mod:`reach_receiver.run.progress_lines`, which a followed job prints too): two per
  top-level step, and inside a step a line at each tenth of its progress, at most one
  a real second.

Writing to a terminal that went away (SSH dropped: SIGHUP, then EIO or EPIPE on every
write) must not stop the run from reaching its safe state, so a failed write silences
the display instead of raising.
"""

from __future__ import annotations

import contextlib
import sys
import time
from pathlib import Path
from typing import TextIO

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, TextColumn
from rich.progress import Progress as RichProgress

from reach_receiver.clock import Clock
from reach_receiver.run.progress_lines import (
    Throttle,
    real_seconds,
    step_lines,
    update_line,
)
from reach_receiver.schedule.steps import Step
from reach_receiver.schedule.timing import hms


class PlainProgress:
    """Progress as plain lines on a stream (stderr by default), within 80 columns.

    The lines are :mod:`reach_receiver.run.progress_lines`', which a job followed
    through ``reachd`` prints too.
    """

    def __init__(self, clock: Clock, stream: TextIO | None = None) -> None:
        self.clock = clock
        self.stream = stream or sys.stderr
        self.start = clock.now()
        self.real_start = time.monotonic()
        self._broken = False
        self._throttle = Throttle()

    def _write(self, lines: list[str]) -> None:
        if self._broken:
            return
        try:
            print("\n".join(lines), file=self.stream, flush=True)
        except (OSError, ValueError):  # the terminal went away, or the stream was closed
            self._broken = True

    def started(self, directory: Path) -> None:
        """Say where the run's files go."""
        self._write([f"run directory: {directory}"])

    def step(self, index: int, total: int, step: Step, text: str, left_s: float | None) -> None:
        """Two lines per top-level step: what, then where, time elapsed and left."""
        real = real_seconds(self.clock, time.monotonic() - self.real_start)
        self._throttle.new_step()
        self._write(step_lines(
            index, total, text, str(step.where), self.clock.now() - self.start, left_s, real
        ))

    def update(self, text: str, done: int, total: int, left_s: float | None) -> None:
        """A line at each tenth of the step's progress, at most one a real second."""
        if self._throttle.due(done, total, time.monotonic()):
            self._write(update_line(text, done, total, left_s))


class RichProgressDisplay:
    """Progress on a terminal: step lines, and a live bar for the current step."""

    def __init__(self, clock: Clock, console: Console | None = None) -> None:
        self.plain = PlainProgress(clock, sys.stderr)
        self.console = console or Console(stderr=True)
        self.bar = RichProgress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[left]}"),
            console=self.console,
            transient=True,
        )
        self.task = self.bar.add_task("", total=1, left="", visible=False)
        self._started = False
        self._broken = False

    def __enter__(self) -> RichProgressDisplay:
        try:
            self.bar.start()
            self._started = True
        except OSError:
            self._broken = True
        return self

    def __exit__(self, *exc: object) -> None:
        if self._started:
            with contextlib.suppress(OSError):
                self.bar.stop()

    def started(self, directory: Path) -> None:
        """Say where the run's files go."""
        self.plain.started(directory)

    def step(self, index: int, total: int, step: Step, text: str, left_s: float | None) -> None:
        """The plain display's step lines above the bar; the bar is reset."""
        if self._broken:
            return
        real = real_seconds(self.plain.clock, time.monotonic() - self.plain.real_start)
        elapsed = self.plain.clock.now() - self.plain.start
        lines = step_lines(index, total, text, str(step.where), elapsed, left_s, real)
        try:
            self.bar.update(self.task, visible=False)
            self.bar.console.print("\n".join(lines), markup=False, highlight=False)
        except OSError:
            self._broken = True

    def update(self, text: str, done: int, total: int, left_s: float | None) -> None:
        """Move the bar."""
        if self._broken:
            return
        left = f"{hms(left_s)} left" if left_s is not None else ""
        try:
            self.bar.update(
                self.task, description=text, completed=done, total=total, left=left, visible=True
            )
        except OSError:
            self._broken = True
