"""``repeat``: run a list of steps ``count`` times, optionally one repetition every ``period_s``.

``{count: 20, period_s: 300, steps: [...]}`` (REACH's ``observation_operations``:
``repetitions`` and ``every``). With a period each repetition starts ``period_s`` after
the previous one began; a period shorter than one repetition's estimated duration is a
problem before anything runs. The dry run lists the first repetition, indented.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from reach_receiver.config.fields import REQUIRED, UNRESOLVED, Fields
from reach_receiver.schedule.interlocks import BoardCheck
from reach_receiver.schedule.parsing import ParseContext, compile_steps
from reach_receiver.schedule.steps import Step, Where
from reach_receiver.schedule.timing import TimingWalk, hms

from ..context import RunContext
from ..kind import RunnableKind


@dataclass(frozen=True)
class Repeat(Step):
    """Run ``steps`` ``count`` times, starting a repetition every ``period_s`` if given."""

    count: int
    steps: tuple[Step, ...]
    period_s: float | None = None


class RepeatKind(RunnableKind[Repeat]):
    """``repeat``."""

    name = "repeat"
    step_type = Repeat
    keys = ("count", "period_s", "steps")
    needs_devices = False

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> Repeat:
        """``count``, ``period_s`` (optional) and the nested ``steps``."""
        count = f.count("count")
        period = f.optional_seconds("period_s")
        body = f.raw("steps", REQUIRED)
        inner: list[Step] = []
        if body is not UNRESOLVED:
            inner = compile_steps(body, f.file, f.line("steps"), f"{f.key}.steps", ctx)
        return Repeat(where, count, tuple(inner), period)

    def describe(self, step: Repeat) -> str:
        """Count and period."""
        every = f" every {hms(step.period_s)}" if step.period_s is not None else ""
        return f"repeat {step.count} x{every}"

    def duration(self, step: Repeat, walk: TimingWalk) -> float:
        """``count x max(period_s, one repetition)``, the last counting only its own time."""
        one = walk.nested(step.steps)
        period = step.period_s
        if period is not None and period < one:
            walk.report(
                step,
                "repeat.period_s",
                f"period {hms(period)} is shorter than one repetition ({hms(one)} estimated"
                f" with {walk.period_s:g} s spectra)",
            )
        every = max(period or 0.0, one)
        return (step.count - 1) * every + one

    def children(self, step: Repeat) -> tuple[Step, ...]:
        """The body."""
        return step.steps

    def check_interlocks(self, step: Repeat, board: BoardCheck) -> None:
        """The body, twice when repeated: the second pass starts where the first ended."""
        board.walk(step.steps)
        if step.count > 1:
            board.walk(step.steps)

    def after_repetitions(self, step: Repeat, done: int) -> Repeat | None:
        """The repetitions still to come."""
        left = step.count - done
        return dataclasses.replace(step, count=left) if left > 0 else None

    def execute(self, step: Repeat, run: RunContext) -> None:
        """Each repetition, then the rest of its period."""
        for repetition in range(step.count):
            began = run.clock.now()
            run.run_steps(step.steps, (*run.path, repetition))
            if step.period_s is not None and repetition + 1 < step.count:
                left = began + step.period_s - run.clock.now()
                text = f"repeat {repetition + 1}/{step.count}: waiting for the next period"
                run.progress.update(text, repetition + 1, step.count, max(left, 0.0))
                run.wait(left)
