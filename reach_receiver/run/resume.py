"""Carry an interrupted run on: what is left of its schedule, and what it had measured.

An interrupted run file (closed by recovery after a crash or a power cut, or by a stop)
says how far it got: every step's start and end is a ``step`` event with the step's path
(:func:`~reach_receiver.run.session.record_step`), and every measurement is numbered in
the order it was stored. From them:

* a step that ended is skipped, unless its kind replays it (``on_resume = "replay"``:
  initialise, power, connect, temperatures, the TEC, the VNA calibration, whose effects a
  restart lost);
* the step that was interrupted continues with what is left of it (its kind's
  :meth:`~reach_receiver.schedule.kinds.StepKind.rest`: the sources, targets or cycles it
  had not stored yet); inside a ``repeat``, the interrupted repetition continues the same
  way and the repetitions still to come follow;
* the steps it had not reached run as written.

The resumed run is a new run file. It starts with copies of the interrupted run's
measurements (each marked with where it came from), so that it holds the whole schedule's
data exactly once and its calibration sees all of it; the interrupted file is never
changed.
"""

from __future__ import annotations

import io
import json
import logging
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import h5py

from reach_receiver.schedule.kinds import KindRegistry
from reach_receiver.schedule.steps import Schedule, Step
from reach_receiver.store import HandOver, RunContents, RunStore, read_run_file
from reach_receiver.store.parts import as_str

from .context import STEP_EVENT

log = logging.getLogger(__name__)

Path_ = tuple[int, ...]
#: The attribute in which a calibration records its hand-over (by measurement number).
HANDOVER = "handover"

#: Measurement kinds a resumed run copies from the run it continues.
CARRIED_KINDS = ("s11", "dicke", "spectrum", "temperatures", "check", "solution", "calibrated")


@dataclass
class StepLog:
    """How far a run got: the steps that ended, those that started, what each measured."""

    done: set[Path_] = field(default_factory=set)
    started: set[Path_] = field(default_factory=set)
    measured: dict[Path_, list[tuple[str, str]]] = field(default_factory=dict)

    @classmethod
    def of(cls, contents: RunContents) -> StepLog:
        """Read the step events and measurements of a run file."""
        log = cls()
        open_steps: list[Path_] = []
        for m in contents.measurements:
            if m.kind == "event" and m.name == STEP_EVENT:
                record = json.loads(str(m.attrs["message"]))
                path = tuple(int(i) for i in record["path"])
                if record["state"] == "started":
                    log.started.add(path)
                    log.measured.setdefault(path, [])
                    open_steps.append(path)
                elif record["state"] == "done":
                    log.done.add(path)
                    if path in open_steps:
                        open_steps.remove(path)
            elif m.kind in CARRIED_KINDS:
                for path in open_steps:
                    log.measured[path].append((m.kind, m.name))
        return log


def remaining(
    steps: Sequence[Step], kinds: KindRegistry, log: StepLog, scope: Path_ = ()
) -> list[Step]:
    """The steps a resumed run executes (module docstring)."""
    out: list[Step] = []
    for index, step in enumerate(steps):
        path = (*scope, index)
        kind = kinds.of(step)
        if path in log.done:
            if kind.on_resume == "replay":
                out.append(step)
        elif path in log.started and kind.children(step):
            inner = [p for p in log.started if len(p) > len(path) and p[: len(path)] == path]
            repetitions = [p[len(path)] for p in inner]
            current = max(repetitions, default=0)
            out += remaining(kind.children(step), kinds, log, (*path, current))
            rest = kind.after_repetitions(step, current + 1)
            if rest is not None:
                out.append(rest)
        elif path in log.started:
            rest = kind.rest(step, log.measured.get(path, []))
            if rest is not None:
                out.append(rest)
        else:
            out.append(step)
    return out


def resumed_schedule(schedule: Schedule, run_file: Path) -> Schedule:
    """``schedule`` reduced to what its interrupted run in ``run_file`` left to do."""
    if schedule.kinds is None:
        raise ValueError("the schedule was compiled without its kinds")
    log = StepLog.of(read_run_file(run_file))
    steps = remaining(schedule.steps, schedule.kinds, log)
    return replace(schedule, steps=tuple(steps))


def carry(store: RunStore, run_file: Path) -> int:
    """Copy the measurements of an interrupted run into a new run's store; how many.

    The copies get the new run's numbers; a carried calibration's hand-over, which
    names the measurements it used by number, is renumbered to name the copies
    (:func:`_renumbered_copy`), so that the new run's merge reads the right ones.
    """
    contents = read_run_file(run_file)
    numbers: dict[int, int] = {}
    for m in contents.measurements:
        if m.kind in CARRIED_KINDS:
            with h5py.File(m.file, "r") as f:
                group = f[m.location]
                origin = f"{contents.path}#{m.sequence}"
                if HANDOVER in group.attrs:
                    with _renumbered_copy(group, numbers) as copy:
                        numbers[m.sequence] = store.add_copy(copy, origin=origin)
                else:
                    numbers[m.sequence] = store.add_copy(group, origin=origin)
    return len(numbers)


@contextmanager
def _renumbered_copy(group: Any, numbers: dict[int, int]) -> Iterator[Any]:
    """``group`` copied in memory with its hand-over naming the new numbers.

    A hand-over naming a measurement that was not carried (none is left out today:
    every kind a calibration uses is carried) is dropped, and the merge chooses the
    measurements again by the hand-over's rule.
    """
    with h5py.File(io.BytesIO(), "w") as memory:
        group.copy(group, memory, name="copy")
        copy = memory["copy"]
        try:
            handover = HandOver.from_json(as_str(group.attrs[HANDOVER])).renumbered(numbers)
            copy.attrs[HANDOVER] = handover.to_json()
        except KeyError as err:
            del copy.attrs[HANDOVER]
            log.warning("carried %s without its hand-over: measurement %s was not carried",
                        group.name, err)
        yield copy
