"""The daemon's jobs: schedules checked and queued, each run in a worker thread.

A schedule is compiled against the site when it is submitted (a mistake comes back at
once, nothing queued) and again when its job starts. The run goes through the run
layer's :class:`~reach_receiver.run.session.RunSession` in a worker thread, its
progress and log lines to the job's followers (:mod:`.events`); the main loop then
records how it ended (:meth:`JobRunning._collect`): the job's state, its run directory
and the calibration's report if the run drew one, and the daemon's next state
(``idle``, or ``faulted`` with an alarm). Its start and its end (with the outcome and
the reason) are logged at INFO, a failure at WARNING; the end's event carries the run's
result as ``reach-run`` prints it (:mod:`reach_receiver.run.summary`). The timers'
schedules become jobs the same way.
"""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any

from reach_receiver.errors import ConnectionLost, DeviceTimeout, ReceiverError
from reach_receiver.run.resume import resumed_schedule
from reach_receiver.run.session import RunFailed, RunSession, RunSummary
from reach_receiver.run.steps import Observe
from reach_receiver.run.summary import report_line
from reach_receiver.schedule.compile import ScheduleError, compile_text
from reach_receiver.schedule.steps import Schedule, Step
from reach_receiver.store import RUN_FILE

from .events import HubLog, HubProgress
from .faults import FaultHandling
from .jobs import Job
from .protocol import ControlError
from .timers import Trigger

log = logging.getLogger(__name__)


def schedule_reader(files: dict[str, str]) -> Any:
    """Reads included files from the texts a client sent, refusing any other."""

    def read(path: Path) -> str:
        try:
            return files[str(path)]
        except KeyError:
            raise FileNotFoundError(2, "not sent with the schedule", str(path)) from None

    return read


def _result(summary: RunSummary | None) -> list[str]:
    """A completed run's result as ``reach-run`` prints it, the report's line last."""
    if summary is None:
        return []
    line = report_line(summary)
    return [*summary.lines, *([line] if line else [])]


class JobRunning(FaultHandling):
    """Submitting, starting, running and collecting jobs; the timers' jobs."""

    def submit(self, schedule: str, files: dict[str, str], origin: str, **options: Any) -> Job:
        """Check a schedule against the site and queue it; a mistake raises, nothing queued."""
        compiled = self._compile(schedule, files)
        return self.queue.add(compiled.name, schedule, files, origin, time.time(), **options)

    def _compile(self, schedule: str, files: dict[str, str]) -> Schedule:
        if schedule not in files:
            raise ControlError(f"the schedule {schedule} was not sent with its files")
        try:
            return compile_text(
                files[schedule], schedule, kinds=self.kinds, site=self.site,
                read=schedule_reader(files),
            )
        except ScheduleError as err:
            raise ControlError(
                f"{schedule} is not valid; nothing was queued", [str(p) for p in err.problems]
            ) from err

    def _start(self, job: Job) -> None:
        try:
            schedule = self._compile(job.schedule, job.files)
            for run_file in job.resumes:
                schedule = resumed_schedule(schedule, Path(run_file))
        except (ControlError, ReceiverError, OSError) as err:
            problems = "; ".join(getattr(err, "problems", []))
            self.queue.update(job, state="failed", ended=time.time(), reason=f"{err} {problems}")
            log.warning("job %d %s failed before it started: %s", job.id, job.name, job.reason)
            self.hub.publish(job.id, "end", state="failed", reason=job.reason, run=None)
            return
        def started(directory: Path) -> None:
            self.queue.update(job, run=str(directory))

        self.progress = HubProgress(
            self.hub, job.id, self.clock, on_step=self._step_started, on_started=started
        )
        self.monitor.hand_over()
        session = RunSession(
            schedule, self.site, self.clock, self.dirs.runs, progress=self.progress,
            metadata={"job": job.id, "origin": job.origin, "resumes": job.resumes},
            carry_from=Path(job.resumes[-1]) if job.resumes else None, monitor=self.monitor,
            truth=self.truth,
        )
        self.current, self.session = job, session
        self.queue.update(job, state="running", started=time.time())
        log.info("job %d %s started: %s, %d steps (%s)", job.id, job.name, job.schedule,
                 len(schedule.steps), job.origin)
        self.machine.go("running", f"job {job.id} {job.name} ({job.origin})")
        self._worker = threading.Thread(
            target=self._work, args=(job, session), name=f"job-{job.id}", daemon=True
        )
        self._worker.start()

    def _work(self, job: Job, session: RunSession) -> None:
        """The worker thread: one run, its log lines to the job's followers."""
        handler = HubLog(self.hub, job.id)
        logging.getLogger("reach_receiver").addHandler(handler)
        failure: RunFailed | None = None
        summary: RunSummary | None = None
        try:
            summary = session.run()  # with the calibration's report, if it made one
        except RunFailed as err:
            failure = err
        except Exception as err:  # the run layer closed the run; record what happened
            log.exception("job %d", job.id)
            failure = RunFailed(f"{type(err).__name__}: {err}", None, "failed")
        finally:
            logging.getLogger("reach_receiver").removeHandler(handler)
            self._finished = (job, failure, summary)

    def _collect(self) -> None:
        """Record a finished job and move the state on."""
        if self._finished is None:
            return
        job, failure, summary = self._finished
        self._finished = None
        run = str(self.session.directory) if self.session and self.session.directory else None
        token = self.session.token if self.session else None
        self.current, self.session, self.progress, self._worker = None, None, None, None
        self.monitor.run_ended()
        state = "completed" if failure is None else failure.status
        if state == "interrupted" and job.state == "cancelled":
            state = "cancelled"
        reason = "" if failure is None else str(failure)
        report = str(summary.report) if summary is not None and summary.report else None
        result = _result(summary)
        self.queue.update(job, state=state, ended=time.time(), run=run, reason=reason,
                          report=report, result=result)
        log.log(logging.INFO if state != "failed" else logging.WARNING, "job %d %s %s%s%s",
                job.id, job.name, state, f": {reason}" if reason else "",
                f"; report in {report}" if report else "")
        if state == "completed" and token is not None and token.requested:
            log.info("job %d had run all its steps when asked to stop (%s)", job.id,
                     token.reason)
        self.hub.publish(job.id, "end", state=state, reason=reason, run=run, report=report,
                         result=result)
        if self.machine.state == "stopping":
            # The daemon itself is stopping (SIGTERM, SIGHUP: a restart, a reboot): the
            # schedule goes on after it, from where the run stopped, if the site says so.
            if state == "interrupted" and self.site.daemon.resume and run is not None:
                self._queue_resumption(job, Path(run) / RUN_FILE)
            return
        if failure is None or state in ("interrupted", "cancelled"):
            self.machine.go("idle", f"job {job.id} {state}")
        elif isinstance(failure.__cause__, ConnectionLost | DeviceTimeout):
            self.machine.go("faulted", f"job {job.id} failed: {reason}")
            self._link_failed(f"job {job.id}: {failure.__cause__}", job)
        else:
            self.alarms["run"] = f"job {job.id} failed: {reason}"
            self.machine.go("faulted", f"job {job.id} failed: {reason}")

    def _step_started(self, step: Step) -> None:
        observing = isinstance(step, Observe)
        if observing and self.machine.state == "running":
            self.machine.go("observing", f"{step.where}: observe")
        elif not observing and self.machine.state == "observing":
            self.machine.go("running", f"{step.where}: {self.kinds.of(step).name}")

    def _queue_timer(self, trigger: Trigger) -> None:
        timer = trigger.timer
        try:
            text = timer.schedule.read_text(encoding="utf-8")
            compiled = compile_text(text, str(timer.schedule), kinds=self.kinds, site=self.site)
        except (OSError, ScheduleError) as err:
            self.alarms[f"timer {timer.name}"] = f"timer {timer.name}: {err}"
            log.error("timer %s: %s", timer.name, err)
            return
        when = "late" if trigger.late else "on time"
        job = self.queue.add(
            compiled.name, str(timer.schedule), dict(compiled.files),
            f"timer {timer.name} ({when})", time.time(),
        )
        log.info("timer %s: job %d queued", timer.name, job.id)

    def _check_timers(self) -> None:
        """Every timer's schedule compiles against the site (an alarm otherwise)."""
        for timer in self.site.daemon.timers:
            try:
                compile_text(
                    timer.schedule.read_text(encoding="utf-8"), str(timer.schedule),
                    kinds=self.kinds, site=self.site,
                )
            except (OSError, ScheduleError) as err:
                self.alarms[f"timer {timer.name}"] = f"timer {timer.name}: {err}"
