"""The compiled form of a schedule: frozen steps, each knowing where it was written.

A YAML schedule is checked and compiled (:mod:`.compile`) into a :class:`Schedule`
holding a tuple of steps. What steps exist is not fixed here: each kind of step is
declared once, with its fields, parser, duration, interlock effect and executor, as a
:class:`~.kinds.StepKind`, and a :class:`~.kinds.KindRegistry` lists the kinds a
schedule may use (the standard ones: :mod:`reach_receiver.run.steps`). Nothing here
does I/O. Every step carries its :class:`Where` (file and line), so that a failure at run
time names the line of the schedule that asked for it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .kinds import KindRegistry


@dataclass(frozen=True)
class Where:
    """Where a step or value was written: file and 1-based line."""

    file: str
    line: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}"


@dataclass(frozen=True)
class Step:
    """Base of every step: where it was written."""

    where: Where


@dataclass(frozen=True)
class Unparsed(Step):
    """Stands for a step that could not be read at all, so later checks assume nothing.

    Never part of a returned schedule: it exists only alongside a reported problem.
    """


@dataclass(frozen=True)
class Schedule:
    """A compiled schedule: its steps, the kinds they were compiled with, and its sources.

    ``files`` holds ``(path, text)`` of the schedule and every file it includes, and
    ``variables`` the values its variables took, so that a run records how it was made.
    """

    name: str
    steps: tuple[Step, ...]
    files: tuple[tuple[str, str], ...]
    variables: tuple[tuple[str, object], ...] = ()
    kinds: KindRegistry | None = field(default=None, compare=False, repr=False)
