"""What ``reach-run`` shows while a run goes: each step, and progress inside long ones.

Two faces of one :class:`~reach_receiver.run.context.Progress`:

* on a terminal, rich's live progress bar for the current step (which source and
  position, spectra so far, time left in the step) under one line per top-level step;
* otherwise (a pipe, a log, ``nohup``), plain lines: one per top-level step, and inside a
  step a line at each tenth of its progress, at most one a real second.

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
from reach_receiver.schedule.steps import Step
from reach_receiver.schedule.timing import hms


class PlainProgress:
    """Progress as plain lines on a stream (stderr by default)."""

    def __init__(self, clock: Clock, stream: TextIO | None = None) -> None:
        self.clock = clock
        self.stream = stream or sys.stderr
        self.start = clock.now()
        self.real_start = time.monotonic()
        self._broken = False
        self._last_fraction = -1.0
        self._last_line = 0.0

    def _write(self, line: str) -> None:
        if self._broken:
            return
        try:
            print(line, file=self.stream, flush=True)
        except (OSError, ValueError):  # the terminal went away, or the stream was closed
            self._broken = True

    def started(self, directory: Path) -> None:
        """Say where the run's files go."""
        self._write(f"run directory: {directory}")

    def step(self, index: int, total: int, step: Step, text: str, left_s: float | None) -> None:
        """One line per top-level step: position, time elapsed and left, where."""
        elapsed = hms(self.clock.now() - self.start)
        left = f", about {hms(left_s)} left" if left_s is not None else ""
        real = time.monotonic() - self.real_start
        self._last_fraction = -1.0
        self._write(
            f"[{index:>3}/{total}] {elapsed} elapsed{left} ({real:.1f} s real) | "
            f"{text}  ({step.where})"
        )

    def update(self, text: str, done: int, total: int, left_s: float | None) -> None:
        """A line at each tenth of the step's progress, at most one a real second."""
        fraction = done / total if total else 1.0
        now = time.monotonic()
        if fraction - self._last_fraction < 0.1 and done < total:
            return
        if now - self._last_line < 1.0 and done < total:
            return
        self._last_fraction, self._last_line = fraction, now
        left = f", {hms(left_s)} left in the step" if left_s is not None else ""
        self._write(f"        {text}: {done}/{total}{left}")


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
        """A step line above the bar; the bar is reset."""
        if self._broken:
            return
        elapsed = hms(self.plain.clock.now() - self.plain.start)
        left = f", about {hms(left_s)} left" if left_s is not None else ""
        try:
            self.bar.update(self.task, visible=False)
            self.bar.console.print(
                f"[bold][{index:>3}/{total}][/bold] {elapsed} elapsed{left} | {text}  "
                f"[dim]({step.where})[/dim]",
                highlight=False,
            )
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
