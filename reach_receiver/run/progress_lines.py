"""A run's progress as plain lines of at most 80 columns, and how often to show them.

``reach-run`` writes these lines when its standard error is not a terminal, and prints
them again when it follows a job of ``reachd``, which records the same numbers (clock
and real seconds, the step's time left) in the job's events; one format for both, so a
followed job reads as a local run does. An operator over a slow link reads them in an
80-column terminal: a line that would be wider wraps under its indent instead.

Each top-level step gets two lines, what it does and where it stands::

    [  7/10] Dicke cycles of cold, hot, c10open, c10short, 0:02:00 per position
             schedules/quick.yaml:18; 1:34:30 elapsed, about 0:45:11 left

and progress inside a step (spectra of a Dicke position, repetitions, a wait) one line
at each tenth of it, at most one a real second (:class:`Throttle`), so that a long step
shows it is moving without flooding a slow link.
"""

from __future__ import annotations

import textwrap

from reach_receiver.clock import Clock, SystemClock
from reach_receiver.schedule.timing import hms

WIDTH = 80
#: Where progress lines inside a step start (under its text, past ``[  7/10] ``).
INDENT = " " * 9


def fit(line: str, indent: str = INDENT) -> list[str]:
    """``line`` in lines of at most :data:`WIDTH` columns, the later ones indented.

    Broken between words only: a word longer than a line (a path) keeps its line.
    """
    if len(line) <= WIDTH:
        return [line]
    return textwrap.wrap(
        line, WIDTH, subsequent_indent=indent, break_on_hyphens=False, break_long_words=False
    ) or [line]


def pack(chunks: list[str], indent: str = "    ") -> list[str]:
    """``chunks`` joined by spaces within :data:`WIDTH` columns, never broken inside one.

    For lines whose parts belong together (a number and its unit, a parenthesis): a
    chunk that does not fit on the line begins the next one, indented.
    """
    lines: list[str] = []
    for chunk in chunks:
        if lines and len(lines[-1]) + 1 + len(chunk) <= WIDTH:
            lines[-1] += " " + chunk
        else:
            lines.append(indent + chunk if lines else chunk)
    return lines


def real_seconds(clock: Clock, real_s: float) -> float | None:
    """The real seconds worth showing beside a clock's: none on the wall clock."""
    return None if isinstance(clock, SystemClock) else real_s


def step_lines(
    index: int,
    total: int,
    text: str,
    where: str,
    elapsed_s: float | None,
    left_s: float | None,
    real_s: float | None = None,
) -> list[str]:
    """A top-level step: what it does, then where it was written and the time."""
    times = []
    if elapsed_s is not None:
        times.append(f"{hms(elapsed_s)} elapsed")
    if left_s is not None:
        times.append(f"about {hms(left_s)} left")
    if real_s is not None:
        times.append(f"{real_s:.1f} s real")
    first = f"[{index:>3}/{total}] "
    indent = " " * len(first)
    second = f"{indent}{where}" + (f"; {', '.join(times)}" if times else "")
    return [*fit(first + text, indent), *fit(second, indent)]


def update_line(text: str, done: int, total: int, left_s: float | None) -> list[str]:
    """Progress inside a step: ``text: done/total``, and the step's time left."""
    left = f", {hms(left_s)} left in the step" if left_s is not None else ""
    return fit(f"{INDENT}{text}: {done}/{total}{left}")


class Throttle:
    """Whether a progress update is worth a line: a tenth more, a real second later.

    The last update of a task (``done == total``) always is.
    """

    def __init__(self, fraction: float = 0.1, seconds: float = 1.0) -> None:
        self.fraction = fraction
        self.seconds = seconds
        self._last_fraction = -1.0
        self._last_time = float("-inf")

    def new_step(self) -> None:
        """A step begins: its first update is shown."""
        self._last_fraction = -1.0

    def due(self, done: int, total: int, now: float) -> bool:
        """Whether to show ``done`` of ``total`` at (real) time ``now``; noted if so."""
        fraction = done / total if total else 1.0
        if done < total and (
            fraction - self._last_fraction < self.fraction - 1e-9
            or now - self._last_time < self.seconds - 1e-9
        ):
            return False
        self._last_fraction, self._last_time = fraction, now
        return True
