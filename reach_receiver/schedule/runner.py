"""The runner: executes a compiled schedule, reports progress, and fails safe.

Steps run in order; ``repeat`` blocks run their steps ``count`` times, starting each
repetition ``period_s`` after the previous one when a period is given. Progress goes to
a :class:`Progress` (the command line prints it): the step, where it was written, and the
estimated time left.

On any device fault, failed check or interruption (Ctrl-C, SIGTERM), the runner puts
the front-end into its safe state, records the event, merges the run file with status
``failed`` or ``interrupted`` and raises :class:`RunFailed` naming the step and its line.
Measurements completed before the fault are already durable in the store.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from reach_receiver.errors import ReceiverError
from reach_receiver.schedule import steps as st
from reach_receiver.schedule.actions import Actions, CheckRecord
from reach_receiver.schedule.solve import calibrate, observe

log = logging.getLogger(__name__)


class RunInterrupted(Exception):
    """The operator (Ctrl-C) or the system (SIGTERM) stopped the run."""


class RunFailed(ReceiverError):
    """A run stopped before its end; the front-end was put in its safe state."""

    def __init__(self, message: str, run_file: Path | None, status: str) -> None:
        self.run_file = run_file
        self.status = status
        super().__init__(message)


class Progress(Protocol):
    """Where the runner reports what it is doing."""

    def step(self, index: int, total: int, step: st.Step, left_s: float | None) -> None:
        """A top-level step (``index`` of ``total``) starts; ``left_s`` is the estimate."""
        ...


@dataclass(frozen=True)
class RunSummary:
    """What a completed run did: checks, the solution's numbers, the run file."""

    run_file: Path | None
    checks: tuple[CheckRecord, ...]
    results: dict[str, object]
    elapsed_s: float


#: The YAML name of each step class.
STEP_NAMES: dict[type[st.Step], str] = {
    st.Initialise: "initialise",
    st.Power: "power",
    st.Connect: "connect",
    st.VnaCalibrate: "vna_calibrate",
    st.TestLoadCheck: "test_load_check",
    st.MeasureS11: "s11",
    st.MeasureSpectrum: "spectrum",
    st.Dicke: "dicke",
    st.Temperatures: "temperatures",
    st.Tec: "tec",
    st.Wait: "wait",
    st.Repeat: "repeat",
    st.Calibrate: "calibrate",
    st.Observe: "observe",
    st.Safe: "safe",
}


def _value(value: object) -> str:
    if isinstance(value, tuple):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if hasattr(value, "__dataclass_fields__"):
        given = {k: v for k, v in vars(value).items() if v is not None}
        return "{" + ", ".join(f"{k}: {_value(v)}" for k, v in given.items()) + "}"
    return str(value)


def describe(step: st.Step) -> str:
    """A one-line description of a step for progress lines, in the schedule's words."""
    name = STEP_NAMES.get(type(step), type(step).__name__.lower())
    fields = {k: v for k, v in vars(step).items() if k not in ("where", "steps")}
    text = ", ".join(f"{k}: {_value(v)}" for k, v in fields.items() if v not in (None, ()))
    return f"{name} {{{text}}}" if text else name


class Runner:
    """Runs a schedule's steps with :class:`Actions`.

    ``remaining_s(index)`` gives the estimated time left from top-level step ``index``.
    """

    def __init__(
        self,
        schedule: st.Schedule,
        actions: Actions,
        progress: Progress | None = None,
        remaining_s: Callable[[int], float | None] | None = None,
    ) -> None:
        self.schedule = schedule
        self.actions = actions
        self.progress = progress
        self.remaining_s = remaining_s or (lambda index: None)
        self._handlers: dict[type[st.Step], Callable[[st.Step], None]] = {
            st.Initialise: self.actions.initialise,  # type: ignore[dict-item]
            st.Power: self.actions.power,  # type: ignore[dict-item]
            st.Connect: self.actions.connect,  # type: ignore[dict-item]
            st.VnaCalibrate: self.actions.vna_calibrate,  # type: ignore[dict-item]
            st.TestLoadCheck: self.actions.test_load_check,  # type: ignore[dict-item]
            st.MeasureS11: self.actions.s11_step,  # type: ignore[dict-item]
            st.MeasureSpectrum: self.actions.spectrum,  # type: ignore[dict-item]
            st.Dicke: self.actions.dicke,  # type: ignore[dict-item]
            st.Temperatures: self.actions.temperatures_step,  # type: ignore[dict-item]
            st.Tec: self.actions.tec,  # type: ignore[dict-item]
            st.Wait: self.actions.wait,  # type: ignore[dict-item]
            st.Repeat: self._repeat,  # type: ignore[dict-item]
            st.Calibrate: lambda step: calibrate(self.actions, step),  # type: ignore[arg-type]
            st.Observe: lambda step: observe(self.actions, step),  # type: ignore[arg-type]
            st.Safe: self.actions.safe,  # type: ignore[dict-item]
        }

    def run(self) -> RunSummary:
        """Run every step; on a fault go safe, close the run file and raise RunFailed."""
        clock = self.actions.clock
        start = clock.now()
        store = self.actions.store
        current: st.Step | None = None
        try:
            total = len(self.schedule.steps)
            for index, step in enumerate(self.schedule.steps):
                current = step
                if self.progress is not None:
                    self.progress.step(index + 1, total, step, self.remaining_s(index))
                self._run(step)
            self.actions.flush_temperatures()
            run_file: Path | None = store.finish("completed")
        except (ReceiverError, RunInterrupted, KeyboardInterrupt, OSError) as err:
            status = "failed" if isinstance(err, ReceiverError | OSError) else "interrupted"
            where = f" at {current.where}" if current is not None else ""
            reason = f"{type(err).__name__}{where}: {err}"
            run_file = self._fail_safe(status, reason)
            raise RunFailed(reason, run_file, status) from err
        finally:
            if self.actions.temperatures is not None:
                self.actions.temperatures.stop()
            self.actions.instruments.close()
        return RunSummary(
            run_file, tuple(self.actions.checks), dict(self.actions.results), clock.now() - start
        )

    def _run(self, step: st.Step) -> None:
        log.info("%s: %s", step.where, describe(step))
        self._handlers[type(step)](step)

    def _repeat(self, step: st.Repeat) -> None:
        clock = self.actions.clock
        for repetition in range(step.count):
            began = clock.now()
            for inner in step.steps:
                self._run(inner)
            if step.period_s is not None and repetition + 1 < step.count:
                clock.sleep(max(0.0, began + step.period_s - clock.now()))

    def _fail_safe(self, status: str, reason: str) -> Path | None:
        """Safe state first, then the record: each part tried even if another fails."""
        actions = self.actions
        log.error("run %s: %s", status, reason)
        try:
            actions.instruments.frontend.safe()
            safe_note = "front-end in its safe state"
        except (ReceiverError, OSError) as err:
            safe_note = f"could not reach the safe state: {err}"
            log.critical(safe_note)
        try:
            actions.flush_temperatures()
            actions.store.add_event(status, f"{reason}; {safe_note}", timestamp=actions.clock.now())
            return actions.store.finish(status, f"{reason}; {safe_note}")
        except (ReceiverError, OSError) as err:
            log.critical("could not close the run file: %s", err)
            return None
