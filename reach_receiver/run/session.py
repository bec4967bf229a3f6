"""One run of a schedule: compile -> instruments -> store -> runner -> close.

A :class:`RunSession` is what ``reach-run`` and the daemon both stand on. Made from a
schedule file and a site (:meth:`RunSession.prepare`), it has already compiled and
checked the schedule, so a mistake (``file:line: key: message``) is raised before any
device is contacted. :meth:`RunSession.run` then opens the run directory (a durable
store and ``run.log``), builds the instruments from the site and executes the steps
with each kind's executor, reporting progress. :meth:`RunSession.stop`, callable from a
signal handler or another thread, asks for a cooperative stop: the runner checks it
between steps and every wait or integration checks it while it runs.

However a run ends (completed, a device fault, a failed check, a stop, an unexpected
error) the front-end is put in its safe state, the temperature log is stored, the run
file is merged with its status and reason, and the instruments are closed. A run that
did not complete raises :class:`RunFailed` naming the step and its line. On a full disk
the store refuses the measurement by name (:class:`~reach_receiver.store.DiskFull`)
while it still has room for the records that close the run; a merged run file that
does not fit leaves the part files as they are, and the reason says where they are.

A completed run's result (its checks such as the test load's, the solution's orders,
noise scale and distance to the noise floor: :mod:`.summary`) goes to ``run.log`` at
INFO and into :attr:`RunSummary.lines`. A completed run that made a calibration then
gets its report, figures and summary, in ``<run dir>/report/`` (:mod:`.report`;
``report=False`` skips it), so that ``reach-run`` and the daemon's jobs both leave one.
A report that cannot be drawn is logged and leaves ``RunSummary.report`` empty; it never
fails the run, whose file is closed.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from calibration.core.sidereal import apparent_lst_h
from reach_receiver.clock import Clock
from reach_receiver.config.site import SiteConfig
from reach_receiver.disk import DiskFull
from reach_receiver.errors import ReceiverError
from reach_receiver.monitor import Monitor
from reach_receiver.schedule.compile import compile_schedule
from reach_receiver.schedule.kinds import KindRegistry
from reach_receiver.schedule.steps import Schedule, Step
from reach_receiver.schedule.timing import TimelineEntry, timeline
from reach_receiver.store.parts import FILE_MODE, PARTS_DIR, StoreError, safe_name
from reach_receiver.store.run_store import RunStore, software_versions

from .context import (
    CheckRecord,
    NoProgress,
    Progress,
    RunContext,
    RunInterrupted,
    StopToken,
    record_step,
)
from .instruments import Instruments
from .kind import RunnableKind
from .monitoring import store_readings, watch
from .report import write_run_report
from .resume import carry
from .steps import STANDARD_KINDS
from .steps.calibrate import CalibrationOutcome
from .summary import Truth, summary_lines

log = logging.getLogger(__name__)

#: The log file each run directory gets.
RUN_LOG = "run.log"
LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


class RunFailed(ReceiverError):
    """A run stopped before its end; the front-end was put in its safe state."""

    def __init__(self, message: str, run_file: Path | None, status: str) -> None:
        self.run_file = run_file
        self.status = status
        super().__init__(message)


@dataclass(frozen=True)
class RunSummary:
    """What a completed run did: its file, checks, calibration and (clock) duration."""

    directory: Path
    run_file: Path | None
    checks: tuple[CheckRecord, ...]
    calibration: CalibrationOutcome | None
    elapsed_s: float
    #: The report's directory (``None``: no calibration, not asked for, or it failed).
    report: Path | None = None
    #: The result as ``reach-run`` prints it (:func:`.summary.summary_lines`), also in
    #: ``run.log``.
    lines: tuple[str, ...] = ()


def plan(
    schedule: Schedule, site: SiteConfig, start_utc: datetime | None = None
) -> list[TimelineEntry]:
    """The dry-run timeline of ``schedule`` at ``site`` (its longitude, its spectrometer)."""
    return timeline(
        schedule,
        start_utc=start_utc or datetime.now(timezone.utc),
        longitude_deg=site.longitude_deg,
        spectrum_period_s=site.devices.spectrometer.period_s,
    )


def _unique_directory(parent: Path, name: str, now_utc: datetime) -> Path:
    """A new directory ``<UTC time>-<name>`` in ``parent``, and never outside it.

    The schedule's name is anyone's text (a daemon takes schedules from its whole group):
    it becomes a file name (:func:`~reach_receiver.store.parts.safe_name`: no ``/``, no
    leading dot), and the result is checked to lie directly in ``parent``.
    """
    stamp = now_utc.strftime("%Y%m%dT%H%M%SZ")
    name = safe_name(name)
    directory = parent / f"{stamp}-{name}"
    suffix = 1
    while directory.exists():  # two runs started within one second
        suffix += 1
        directory = parent / f"{stamp}-{name}-{suffix}"
    if directory.resolve().parent != parent.resolve():
        raise StoreError(f"the run directory {directory} would not lie in {parent}")
    return directory


@dataclass
class RunSession:
    """A compiled schedule, the site it runs at, and how to run it.

    Parameters
    ----------
    schedule
        The compiled schedule (:meth:`prepare` compiles one from a file).
    site
        The site: instruments, front-end tables, spectrometer period, band.
    clock
        The run's clock (the wall clock on site; a compressed one in dry runs).
    out
        The directory under which the run's own directory is made.
    progress
        Where progress goes.
    metadata
        Anything else the run file should carry (JSON-serialisable).
    """

    schedule: Schedule
    site: SiteConfig
    clock: Clock
    out: Path
    progress: Progress = field(default_factory=NoProgress)
    metadata: Mapping[str, Any] = field(default_factory=dict)
    token: StopToken = field(default_factory=StopToken)
    directory: Path | None = None
    #: An interrupted run this one continues: its measurements are copied in first.
    carry_from: Path | None = None
    #: Set once the run is putting the front-end safe and closing its file: nothing may
    #: interrupt that (a second Ctrl-C is then ignored by the command line).
    closing: bool = False
    #: The daemon's monitor: reads at the run's safe points, its readings in the run file.
    monitor: Monitor | None = None
    #: Draw the calibration's report after a completed run that made one.
    report: bool = True
    #: The simulator's truth, for the result's lines of a simulated run (:mod:`.summary`).
    truth: Truth | None = None

    @classmethod
    def prepare(
        cls,
        path: Path,
        site: SiteConfig,
        clock: Clock,
        out: Path,
        *,
        kinds: KindRegistry = STANDARD_KINDS,
        **options: Any,
    ) -> RunSession:
        """Compile ``path`` for ``site`` (raising :class:`ScheduleError` on any mistake)."""
        schedule = compile_schedule(path, kinds=kinds, site=site)
        # The first sidereal time costs a second (astropy loads its tables): pay it here,
        # before any instrument (or simulator) runs, not in the middle of a measurement.
        apparent_lst_h([clock.now()], site.longitude_deg)
        return cls(schedule, site, clock, out, **options)

    @property
    def kinds(self) -> KindRegistry:
        """The kinds the schedule was compiled with."""
        if self.schedule.kinds is None:
            raise ValueError("the schedule was compiled without its kinds")
        return self.schedule.kinds

    def timeline(self, start_utc: datetime | None = None) -> list[TimelineEntry]:
        """The schedule's dry-run timeline at this site."""
        return plan(self.schedule, self.site, start_utc)

    def stop(self, reason: str) -> None:
        """Ask the run to stop cooperatively (safe from signal handlers and other threads)."""
        self.token.request(reason)

    # ----------------------------------------------------------------- running
    def run(self) -> RunSummary:
        """Run every step; on any fault or stop go safe, close the run file, raise RunFailed."""
        not_runnable = [k.name for k in self.kinds if not isinstance(k, RunnableKind)]
        if not_runnable:
            raise ValueError(f"step kinds without an executor: {', '.join(not_runnable)}")
        entries = [e for e in self.timeline() if e.depth == 0]
        total_s = max((e.start_s + e.duration_s for e in entries), default=0.0)
        now = datetime.fromtimestamp(self.clock.now(), tz=timezone.utc)
        self.directory = _unique_directory(self.out, self.schedule.name, now)
        store = RunStore(
            self.directory,
            name=self.schedule.name,
            schedule_files=self.schedule.files,
            site_yaml=self.site.to_yaml(),
            metadata={
                **self.metadata,
                "started_utc": now.strftime("%Y%m%dT%H%M%SZ"),
                "reach_receiver": software_versions()["reach-receiver"],
            },
            channel_width_hz=self.site.devices.spectrometer.channel_width_hz,
            band_hz=self.site.band_hz,
        )
        self._open(store)
        self.progress.started(self.directory)
        with _run_log(self.directory / RUN_LOG):
            log.info("run %s in %s", self.schedule.name, self.directory)
            lst = apparent_lst_h([self.clock.now()], self.site.longitude_deg)[0]
            log.info("local sidereal time at the start: %.4f h", lst)
            context = RunContext(
                site=self.site,
                instruments=Instruments.from_site(self.site, self.clock),
                store=store,
                clock=self.clock,
                kinds=self.kinds,
                stop=self.token,
                progress=self.progress,
            )
            context.run_steps = lambda steps, scope: self._run_steps(context, steps, scope)
            if self.monitor is not None:
                watch(self.monitor, context)
            summary = self._run(context, entries, total_s)
            lines = tuple(summary_lines(summary, self.truth))
            for line in lines:  # the result first: the report takes a while
                log.info("%s", line)
            return self._with_report(replace(summary, lines=lines))

    def _open(self, store: RunStore) -> None:
        """Open the run file and carry the measurements over; RunFailed if it cannot be.

        No device has been touched yet: a run that cannot begin (a full disk, an earlier
        run that cannot be read) is closed as failed with the reason, if it was opened.
        """
        try:
            store.open()
            if self.carry_from is not None:
                carried = carry(store, self.carry_from)
                log.info("carried %d measurements over from %s", carried, self.carry_from)
        except (ReceiverError, OSError) as err:
            reason = f"the run did not start: {err}"
            run_file = None
            if store.is_open:
                try:
                    run_file = store.finish("failed", reason)
                except (ReceiverError, OSError) as close_err:
                    log.error("could not close the run file: %s", close_err)
            raise RunFailed(reason, run_file, "failed") from err

    def _with_report(self, summary: RunSummary) -> RunSummary:
        """The summary with its report drawn, when the run made a calibration."""
        if not self.report or summary.calibration is None or summary.run_file is None:
            return summary
        if self.token.requested:  # asked to stop as the run ended: do not hold it up
            log.info("no report: %s", self.token.reason)
            return summary
        self.progress.update("drawing the calibration's report", 0, 1, None)
        return replace(summary, report=write_run_report(summary.run_file))

    def _run(
        self, run: RunContext, entries: Sequence[TimelineEntry], total_s: float
    ) -> RunSummary:
        start = self.clock.now()
        current: Step | None = None
        try:
            steps = self.schedule.steps
            for index, step in enumerate(steps):
                current = step
                self.token.check()
                left = total_s - entries[index].start_s if index < len(entries) else None
                text = entries[index].description if index < len(entries) else ""
                self.progress.step(index + 1, len(steps), step, text, left)
                self._execute(run, step, (index,))
            self.closing = True
            run.stop_temperatures()
            _store_health(run)
            run_file: Path | None = run.store.finish("completed")
        except BaseException as err:
            self.closing = True
            status, reason = _ending(err, current, self.token.reason)
            run_file, kept = _fail_safe(run, status, reason, err)
            if isinstance(err, Exception | KeyboardInterrupt):
                raise RunFailed(f"{reason}; {kept}" if kept else reason, run_file, status) from err
            raise  # SystemExit and the like: the run is closed, let it go on
        finally:
            run.stop_temperatures()
            if run.watch is not None:
                run.watch.close()
            run.instruments.close()
        return RunSummary(
            self.directory or run.store.directory,
            run_file,
            tuple(run.checks),
            run.calibration,
            self.clock.now() - start,
        )

    def _run_steps(self, run: RunContext, steps: Sequence[Step], scope: tuple[int, ...]) -> None:
        for index, step in enumerate(steps):
            self.token.check()
            self._execute(run, step, (*scope, index))

    def _execute(self, run: RunContext, step: Step, path: tuple[int, ...]) -> None:
        """Run one step, recording in the run file that it started and that it ended."""
        log.info("%s: %s", step.where, self.kinds.written(step))
        kind = self.kinds.of(step)
        if not isinstance(kind, RunnableKind):  # checked before the run started
            raise TypeError(f"step kind {kind.name} has no executor")
        run.safe_point()
        record_step(run, path, step, "started")
        run.path = path
        kind.execute(step, run)
        run.path = path
        record_step(run, path, step, "done")


def _ending(err: BaseException, current: Step | None, requested: str) -> tuple[str, str]:
    """The status and the reason a run ended with ``err`` at step ``current``.

    ``requested`` is the reason of a stop request, which names the cause first (a second
    signal that cut the cooperative stop short comes after it).
    """
    where = f" at {current.where}" if current is not None else ""
    if isinstance(err, RunInterrupted | KeyboardInterrupt):
        cause = str(err) or "Ctrl-C"
        if requested and cause != requested:
            cause = f"{requested}, then {cause}"
        return "interrupted", f"interrupted{where}: {cause}"
    if isinstance(err, ReceiverError | OSError):
        return "failed", f"{type(err).__name__}{where}: {err}"
    return "failed", f"internal error {type(err).__name__}{where}: {err}"


def _fail_safe(
    run: RunContext, status: str, reason: str, err: BaseException
) -> tuple[Path | None, str]:
    """Safe state first, then the record: each part tried even if another fails.

    Returns the merged run file (``None`` when it could not be merged) and, then, where
    the measurements are kept instead: on a full disk the part files stay as they are,
    each readable, and the run is merged once there is room (a later merge, or
    ``reachd``'s recovery at its start).
    """
    if status == "failed" and not isinstance(err, ReceiverError | OSError):
        log.error("run %s: %s", status, reason, exc_info=err)
    else:
        log.error("run %s: %s", status, reason)
    try:
        state = run.instruments.make_safe()
        safe_note = "front-end in its safe state" + ("" if state.is_safe else " (reads otherwise!)")
        pins = state.as_pins()
    except (ReceiverError, OSError) as safe_err:
        safe_note, pins = f"could not reach the safe state: {safe_err}", {}
        log.critical(safe_note)
    try:
        run.stop_temperatures()
    except (ReceiverError, OSError) as temp_err:
        log.error("could not store the last temperatures: %s", temp_err)
    _store_health(run)
    store_err: BaseException = err  # a finished store's end is recorded: its merge failed
    if not run.store.finished:
        try:
            message = f"{reason}; {safe_note}"
            if pins:
                message += " (" + " ".join(f"{k}={v}" for k, v in pins.items()) + ")"
            run.store.add_event(status, message, timestamp=run.clock.now())
            return run.store.finish(status, f"{reason}; {safe_note}"), ""
        except (ReceiverError, OSError) as failed:
            store_err = failed
    log.critical("could not close the run file: %s", store_err)
    parts = run.store.directory / PARTS_DIR
    kept = f"its measurements are kept as part files in {parts}" if parts.is_dir() else ""
    if kept and isinstance(store_err, DiskFull):
        kept += ", to be merged into its run file once there is room"
    return None, kept


def _store_health(run: RunContext) -> None:
    """The monitor's readings taken during the run, into the run file (if any)."""
    if run.watch is None:
        return
    taken, run.watch.taken = run.watch.taken, []
    try:
        count = store_readings(run.store, taken)
    except (ReceiverError, OSError, ValueError) as err:
        log.error("could not store the health readings: %s", err)
    else:
        log.info("%d health readings of the monitor stored with the run", count)


class _RunLogHandler(logging.FileHandler):
    """``run.log``: a line that cannot be written (a full disk) is dropped, said once.

    The logging module's own answer would be a traceback on standard error for every
    line; the run goes on and its error, if the disk stays full, names the disk.
    """

    dropped = False

    def handleError(self, record: logging.LogRecord) -> None:
        if not self.dropped:
            self.dropped = True
            sys.stderr.write(f"{self.baseFilename}: log lines dropped ({sys.exc_info()[1]})\n")


@contextlib.contextmanager
def _run_log(path: Path) -> Iterator[None]:
    """Everything the receiver side logs at INFO and above, also in the run's ``run.log``."""
    handler = _RunLogHandler(path, encoding="utf-8")
    os.chmod(path, FILE_MODE)
    handler.setLevel(logging.INFO)
    handler.setFormatter(logging.Formatter(LOG_FORMAT))
    loggers = [logging.getLogger("reach_receiver"), logging.getLogger("calibration")]
    previous = [lg.level for lg in loggers]
    for lg in loggers:
        lg.addHandler(handler)
        if lg.getEffectiveLevel() > logging.INFO:
            lg.setLevel(logging.INFO)
    try:
        yield
    finally:
        for lg, level in zip(loggers, previous, strict=True):
            lg.removeHandler(handler)
            lg.setLevel(level)
        with contextlib.suppress(OSError):  # its last lines did not fit: said above
            handler.close()
