"""What a step's executor works with: the run's instruments, store, clock and stop token.

A :class:`RunContext` is made by the :class:`~.session.RunSession` for one run. The
measurements themselves live only in the store (the hand-over to the engine reads them
from there); the context holds what a run carries from step to step besides: the VNA's
sweep settings, the temperature log, the latest solution (and how it was made) and the
checks' verdicts.

Stopping is cooperative: :meth:`StopToken.request` (a signal handler, the daemon's
``abort``) sets an event that the runner checks between steps and that every wait and
integration checks while it runs (:meth:`RunContext.wait`,
:meth:`RunContext.spectrum_progress`); the run then goes to the safe state and closes
its file with the reason.
"""

from __future__ import annotations

import json
import logging
import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from calibration.solve.solvers import AnySolution
from reach_receiver.clock import Clock, StopEvent
from reach_receiver.config.site import SiteConfig
from reach_receiver.devices.vna_settings import SweepSettings
from reach_receiver.errors import ReceiverError
from reach_receiver.schedule.kinds import KindRegistry
from reach_receiver.schedule.steps import Step
from reach_receiver.store.run_store import RunStore

from .instruments import Instruments
from .measure import TemperatureLogger

if TYPE_CHECKING:
    from reach_receiver.monitor import RunWatch

    from .steps.calibrate import CalibrationOutcome

log = logging.getLogger(__name__)


class RunInterrupted(Exception):
    """The run was asked to stop (a signal, the operator, the daemon); carries the reason."""


class CheckFailed(ReceiverError):
    """A check that must pass did not (the test load after every allowed recalibration)."""


@dataclass(frozen=True)
class CheckRecord:
    """A check's name, verdict and a one-line description, for the run's summary."""

    name: str
    passed: bool
    detail: str


class StopToken:
    """A thread-safe request to stop, with its reason; the first reason wins."""

    def __init__(self) -> None:
        self._event = StopEvent()  # set from signal handlers
        self._reason = ""
        self._lock = threading.RLock()  # a handler may interrupt a request in progress

    @property
    def event(self) -> threading.Event:
        """The event set by :meth:`request` (for clock waits)."""
        return self._event

    @property
    def requested(self) -> bool:
        """Whether a stop was requested."""
        return self._event.is_set()

    @property
    def reason(self) -> str:
        """Why the stop was requested (empty when it was not)."""
        return self._reason

    def request(self, reason: str) -> None:
        """Ask the run to stop; safe from a signal handler and from any thread."""
        with self._lock:
            if not self._event.is_set():
                self._reason = reason
                self._event.set()

    def check(self) -> None:
        """Raise :class:`RunInterrupted` if a stop was requested."""
        if self._event.is_set():
            raise RunInterrupted(self._reason)


class Progress(Protocol):
    """Where a run reports what it is doing (the command line, the daemon's followers)."""

    def started(self, directory: Path) -> None:
        """The run's directory exists; its steps are about to run."""
        ...

    def step(self, index: int, total: int, step: Step, text: str, left_s: float | None) -> None:
        """Top-level step ``index`` of ``total`` starts; ``left_s`` is the run's time left."""
        ...

    def update(self, text: str, done: int, total: int, left_s: float | None) -> None:
        """Progress inside the current step: ``done`` of ``total`` units, ``left_s`` for it."""
        ...


class NoProgress:
    """A :class:`Progress` that reports nothing."""

    def started(self, directory: Path) -> None:
        """Report nothing."""

    def step(self, index: int, total: int, step: Step, text: str, left_s: float | None) -> None:
        """Report nothing."""

    def update(self, text: str, done: int, total: int, left_s: float | None) -> None:
        """Report nothing."""


@dataclass
class RunContext:
    """The run's instruments, store, clock and the state it carries between steps.

    ``run_steps(steps, scope)`` executes nested steps (a ``repeat``'s body) with the
    runner's rules; ``path`` is the position of the step being executed (``(3,)`` for the
    fourth top-level step, ``(3, 1, 0)`` for the first step of its second repetition),
    which the run file records as each step starts and ends.
    """

    site: SiteConfig
    instruments: Instruments
    store: RunStore
    clock: Clock
    kinds: KindRegistry
    stop: StopToken = field(default_factory=StopToken)
    progress: Progress = field(default_factory=NoProgress)
    run_steps: Callable[[Sequence[Step], tuple[int, ...]], None] = field(
        default=lambda steps, scope: None
    )
    path: tuple[int, ...] = ()
    sweep: SweepSettings = field(default_factory=SweepSettings)
    solution: AnySolution | None = None
    temperatures: TemperatureLogger | None = None
    checks: list[CheckRecord] = field(default_factory=list)
    calibration: CalibrationOutcome | None = None
    #: The daemon's monitor, when there is one (:mod:`.monitoring`).
    watch: RunWatch | None = None
    _stored_readings: int = 0

    # ----------------------------------------------------------------- time
    @property
    def period_s(self) -> float:
        """The spectrometer's accumulation period (the site file's)."""
        return self.site.devices.spectrometer.period_s

    def n_spectra(self, seconds: float) -> int:
        """Spectra that make ``seconds`` of integration at the site's period."""
        return max(1, round(seconds / self.period_s))

    def wait(self, seconds: float) -> None:
        """Wait ``seconds`` of clock time; a stop request ends the wait at once.

        A wait is idle time: with a monitor, it is a safe point every cadence.
        """
        end = self.clock.now() + max(seconds, 0.0)
        while True:
            self.safe_point()
            left = end - self.clock.now()
            if left <= 0:
                return
            step = left if self.watch is None else min(left, self.watch.cadence_s)
            if self.clock.wait(self.stop.event, step):
                self.stop.check()

    def safe_point(self) -> None:
        """Nothing is being measured: the monitor may read the board and the TEC now."""
        if self.watch is not None:
            self.watch.safe_point()

    def spectrum_progress(self, what: str, seconds_each: float) -> Callable[[int, int], None]:
        """A per-spectrum callback: reports ``what`` with the time left, honours a stop."""

        def report(done: int, total: int) -> None:
            self.stop.check()
            self.progress.update(what, done, total, (total - done) * seconds_each)

        return report

    # ----------------------------------------------------------------- records
    def record_check(
        self, name: str, passed: bool, detail: str, details: dict[str, Any] | None = None
    ) -> None:
        """A check's verdict: in the summary and in the run file."""
        self.checks.append(CheckRecord(name.replace("_", " "), passed, detail))
        self.store.add_check(name, passed, timestamp=self.clock.now(), details=details or {})

    def log_temperatures(self, period_s: float) -> None:
        """(Re)start the background thermocouple log every ``period_s`` of clock time."""
        if self.temperatures is not None:
            self.flush_temperatures()
            self.temperatures.stop()
        self.temperatures = TemperatureLogger(self.instruments.tc08, self.clock, period_s)
        self._stored_readings = 0
        self.temperatures.start()

    def flush_temperatures(self) -> None:
        """Store the thermocouple readings logged since the last flush."""
        if self.temperatures is None:
            return
        readings = self.temperatures.readings()[self._stored_readings :]
        if not readings:
            return
        channels = sorted(readings[0].raw_c)
        values = np.array([[r.temperatures_c.get(c, math.nan) for c in channels] for r in readings])
        names = [self.instruments.tc08.ports.get(c, f"port{c}") for c in channels]
        self.store.add_temperatures([r.timestamp for r in readings], values, names)
        self._stored_readings += len(readings)

    def stop_temperatures(self) -> None:
        """Stop the temperature log (its readings are flushed first)."""
        if self.temperatures is not None:
            try:
                self.flush_temperatures()
            finally:
                self.temperatures.stop()
                self.temperatures = None


#: The kind of the events that record each step's start and end.
STEP_EVENT = "step"


def record_step(run: RunContext, path: tuple[int, ...], step: Step, state: str) -> None:
    """A ``step`` event: which step (its path and line) started or ended, durably.

    The run file's record of how far a run got, which a resumed run reads
    (:mod:`reach_receiver.run.resume`).
    """
    text = json.dumps({"path": list(path), "state": state, "where": str(step.where)})
    run.store.add_event(STEP_EVENT, text, timestamp=run.clock.now())
