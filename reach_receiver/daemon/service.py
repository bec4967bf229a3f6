"""The daemon: one owner of the hardware, a queue of runs, a main loop systemd can watch.

Life cycle (:class:`Daemon`):

* :meth:`~Daemon.start` takes the hardware lock, closes the runs a crash left open and
  marks their jobs interrupted (queueing their continuation when the site's ``resume``
  policy is on), puts the front-end in its safe state, fires the timers missed while it
  was down (per the policy), opens the control socket and tells systemd it is ready.
* the monitor (:mod:`reach_receiver.monitor`) samples the receiver's health every
  cadence from its own thread, with its own links while idle and at the safe points of
  a run; the daemon takes the hardware from it before a run or a safe-state command.
* :meth:`~Daemon.serve` is the main loop: every ``tick_s`` it feeds the watchdog (while
  healthy), starts the next queued job when idle, fires due timers, and publishes its
  status; each run goes in a worker thread through the run layer's
  :class:`~reach_receiver.run.session.RunSession`.
* :meth:`~Daemon.halt` (SIGTERM, SIGHUP) stops the current run cooperatively: the
  front-end goes safe and the run file is closed with the reason; :meth:`~Daemon.serve`
  then returns and :meth:`~Daemon.close` releases everything.

A run that fails leaves the daemon ``faulted`` (the front-end safe, the queue waiting)
until an operator's ``resume``; when it failed because a device stopped answering, the
daemon tries the front-end again with a growing back-off and resumes by itself once it
answers. The control requests are documented in :mod:`.protocol`.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from reach_receiver.clock import Clock
from reach_receiver.config.site import SiteConfig
from reach_receiver.errors import ConnectionLost, DeviceTimeout, ReceiverError
from reach_receiver.monitor import Monitor
from reach_receiver.run.instruments import Instruments
from reach_receiver.run.resume import resumed_schedule
from reach_receiver.run.session import RunFailed, RunSession, RunSummary
from reach_receiver.run.steps import STANDARD_KINDS, Observe
from reach_receiver.schedule.compile import ScheduleError, compile_text
from reach_receiver.schedule.kinds import KindRegistry
from reach_receiver.schedule.lst import apparent_lst_h
from reach_receiver.schedule.steps import Schedule, Step
from reach_receiver.store import RUN_FILE, read_run_file

from .control import SOCKET_FILE, ControlServer, Peer
from .events import EventHub, HubLog, HubProgress
from .jobs import Job, JobQueue
from .lock import HardwareLock
from .notify import Notifier, Watchdog
from .protocol import ControlError, reply
from .recovery import recover_run, recover_runs
from .states import TRANSITIONS, StateMachine
from .status_page import StatusPage
from .timers import Timers, Trigger

log = logging.getLogger(__name__)

#: Back-off of the attempts to reach a front-end that stopped answering (s of real time).
BACKOFF_S = (1.0, 2.0, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0)


@dataclass
class Directories:
    """Where the daemon keeps things: the socket and lock, the queue, the runs."""

    runtime: Path
    state: Path
    runs: Path = field(init=False)

    def __post_init__(self) -> None:
        self.runs = self.state / "runs"

    def create(self) -> None:
        """Make them (``0750``; the runtime directory's group is the service's)."""
        for directory in (self.runtime, self.state, self.runs):
            directory.mkdir(parents=True, exist_ok=True)
        os.chmod(self.runs, 0o750)


def schedule_reader(files: dict[str, str]) -> Any:
    """Reads included files from the texts a client sent, refusing any other."""

    def read(path: Path) -> str:
        try:
            return files[str(path)]
        except KeyError:
            raise FileNotFoundError(2, "not sent with the schedule", str(path)) from None

    return read


class Daemon:
    """The receiver daemon (module docstring).

    Parameters
    ----------
    site
        The site file: instruments, front-end, timers and policies.
    clock
        The daemon's clock (the wall clock; a compressed one for dry runs).
    directories
        Runtime and state directories.
    kinds
        The step kinds schedules may use.
    notifier
        systemd's notification socket (from the environment by default).
    tick_s
        Real seconds between turns of the main loop.
    """

    def __init__(
        self,
        site: SiteConfig,
        clock: Clock,
        directories: Directories,
        *,
        kinds: KindRegistry = STANDARD_KINDS,
        notifier: Notifier | None = None,
        tick_s: float = 0.5,
    ) -> None:
        self.site = site
        self.clock = clock
        self.dirs = directories
        self.kinds = kinds
        self.tick_s = tick_s
        self.machine = StateMachine()
        self.hub = EventHub()
        self.notifier = notifier or Notifier()
        self.watchdog = Watchdog(self.notifier)
        self.queue = JobQueue(directories.state / "queue.json")
        self.timers = Timers(site.daemon, site.longitude_deg, directories.state / "timers.json")
        self.lock = HardwareLock(directories.state, f"reachd ({site.source})")
        self.server = ControlServer(directories.runtime / SOCKET_FILE, self.dispatch)
        self.alarms: dict[str, str] = {}
        states = list(TRANSITIONS)
        self.monitor = Monitor(
            site, clock, directories.state, directories.runs,
            daemon_state=lambda: states.index(self.machine.state),
        )
        self.page: StatusPage | None = None
        if site.daemon.status_port is not None:  # read-only, 127.0.0.1 only (.status_page)
            self.page = StatusPage(site.daemon.status_port, self._status_reply, directories.runs,
                                   lambda: self.monitor.database, clock.now)
        self.paused = False
        self.current: Job | None = None
        self.session: RunSession | None = None
        self.progress: HubProgress | None = None
        self._worker: threading.Thread | None = None
        self._finished: tuple[Job, RunFailed | None, RunSummary | None] | None = None
        self._loop = threading.RLock()  # held by the main loop during each turn
        self._halt = threading.Event()
        self._halt_reason = ""
        self._retry_at: float | None = None
        self._retries = 0
        self._status = ""

    # ----------------------------------------------------------------- life cycle
    def start(self) -> None:
        """Lock, recover, go safe, catch up with the timers, serve the socket, be ready."""
        self.dirs.create()
        self.lock.acquire()
        # The first sidereal time costs a second (astropy's tables): not in a first run.
        apparent_lst_h([self.clock.now()], self.site.longitude_deg)
        self._recover()
        try:
            self._go_safe()
        except (ReceiverError, OSError) as err:
            self._link_failed(f"front-end unreachable at start: {err}")
        for trigger in self.timers.start(self.clock.now()):
            self._queue_timer(trigger)
        self._check_timers()
        self.monitor.start()
        self.server.start()
        if self.page is not None:
            self.page.start()
        if self.machine.state == "starting":
            self.machine.go("idle", "started: front-end safe, socket open")
        self.notifier.ready(self.status_line())

    def serve(self) -> None:
        """The main loop, until :meth:`halt`; then the current run is stopped safely."""
        while not self._halt.wait(self.tick_s):
            self.tick()
        self.machine.go("stopping", self._halt_reason)
        self.notifier.stopping(f"stopping: {self._halt_reason}")
        if self.session is not None:
            self.session.stop(self._halt_reason)
        if self._worker is not None:
            self._worker.join()
        self._collect()

    def halt(self, reason: str) -> None:
        """Stop: the current run cooperatively (safe from a signal handler)."""
        self._halt_reason = self._halt_reason or reason
        session = self.session
        if session is not None:
            session.stop(reason)
        self._halt.set()

    def close(self) -> None:
        """Close the socket and the page, release the hardware, say goodbye to systemd."""
        self.server.close()
        if self.page is not None:
            self.page.close()
        self.monitor.close()
        self.lock.release()
        if self.machine.can("stopped"):
            self.machine.go("stopped", self._halt_reason or "closed")
        self.notifier.close()

    # ----------------------------------------------------------------- the main loop
    def tick(self) -> None:
        """One turn of the main loop."""
        with self._loop:
            self.watchdog.feed(self.healthy())
            self._collect()
            now = self.clock.now()
            for trigger in self.timers.due(now):
                self._queue_timer(trigger)
            if self._retry_at is not None and time.monotonic() >= self._retry_at:
                self._retry_front_end()
            if self.machine.state == "idle" and not self.paused:
                job = self.queue.next_queued()
                if job is not None:
                    self._start(job)
            line = self.status_line()
            if line != self._status:
                self._status = line
                self.notifier.status(line)

    def healthy(self) -> bool:
        """Whether the daemon works: its socket serves and a run's worker is alive."""
        serving = self.server.serving
        running = self.machine.state in ("running", "observing")
        return serving and (not running or (self._worker is not None and self._worker.is_alive()))

    def status_line(self) -> str:
        """One line for systemd and the log: state, job and step, alarms (health: the first)."""
        text: str = self.machine.state
        if self.current is not None:
            text += f": job {self.current.id} {self.current.name}"
            if self.progress is not None and self.progress.step_text:
                text += f", {self.progress.step_text}"
        if self.paused:
            text += " (queue paused)"
        if self.alarms:
            text += f"; alarm: {'; '.join(self.alarms.values())}"
        health = self.monitor.alarms()
        if health:
            more = f" (+{len(health) - 1} more)" if len(health) > 1 else ""
            text += f"; health alarm: {health[0]}{more}"
        return text

    # ----------------------------------------------------------------- jobs
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
            self.hub.publish(job.id, "end", state="failed", reason=job.reason, run=None)
            return
        def started(directory: Path) -> None:
            self.queue.update(job, run=str(directory))

        self.progress = HubProgress(
            self.hub, job.id, on_step=self._step_started, on_started=started
        )
        self.monitor.hand_over()
        session = RunSession(
            schedule, self.site, self.clock, self.dirs.runs, progress=self.progress,
            metadata={"job": job.id, "origin": job.origin, "resumes": job.resumes},
            carry_from=Path(job.resumes[-1]) if job.resumes else None, monitor=self.monitor,
        )
        self.current, self.session = job, session
        self.queue.update(job, state="running", started=time.time())
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
        self.current, self.session, self.progress, self._worker = None, None, None, None
        self.monitor.run_ended()
        state = "completed" if failure is None else failure.status
        if state == "interrupted" and job.state == "cancelled":
            state = "cancelled"
        reason = "" if failure is None else str(failure)
        report = str(summary.report) if summary is not None and summary.report else None
        if report is not None:
            log.info("job %d: report in %s", job.id, report)
        self.queue.update(job, state=state, ended=time.time(), run=run, reason=reason,
                          report=report)
        self.hub.publish(job.id, "end", state=state, reason=reason, run=run, report=report)
        if self.machine.state == "stopping":
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

    # ----------------------------------------------------------------- the front-end
    def _go_safe(self) -> None:
        """Put the front-end in its safe state through the Teensy alone, and let it go."""
        with self.monitor.hardware():
            state = Instruments.from_site(self.site, self.clock).make_safe()
        log.info("front-end safe: %s", " ".join(f"{k}={v}" for k, v in state.as_pins().items()))

    def _link_failed(self, reason: str, job: Job | None = None) -> None:
        self.alarms["link"] = reason
        delay = BACKOFF_S[min(self._retries, len(BACKOFF_S) - 1)]
        self._retry_at = time.monotonic() + delay
        self._retries += 1
        if self.machine.state == "starting":
            self.machine.go("faulted", reason)
        log.error("%s; trying the front-end again in %g s", reason, delay)
        if job is not None and self.site.daemon.resume and job.run:
            self._queue_resumption(job, Path(job.run) / RUN_FILE)

    def _retry_front_end(self) -> None:
        try:
            self._go_safe()
        except (ReceiverError, OSError) as err:
            self._link_failed(f"front-end still unreachable: {err}")
            return
        log.warning("front-end answers again after %d attempts", self._retries)
        self.alarms.pop("link", None)
        self._retry_at, self._retries = None, 0
        if self.machine.state == "faulted" and "run" not in self.alarms:
            self.machine.go("idle", "the front-end answers again")

    # ----------------------------------------------------------------- recovery
    def _recover(self) -> None:
        """Close runs left open; jobs that were running are interrupted (and resumed)."""
        recovered = {r.directory: r for r in recover_runs(self.dirs.runs)}
        for job in self.queue.jobs("running"):
            directory = Path(job.run) if job.run else None
            found = recovered.get(directory) if directory else None
            if directory is not None and found is None:
                found = recover_run(directory)
            reason = found.reason if found else "the daemon stopped before the run began"
            self.queue.update(job, state="interrupted", ended=time.time(), reason=reason)
            log.warning("job %d was running when the daemon stopped: %s", job.id, reason)
            if self.site.daemon.resume and directory is not None:
                self._queue_resumption(job, directory / RUN_FILE)

    def _queue_resumption(self, job: Job, run_file: Path) -> None:
        if not run_file.exists():
            return
        resumption = self.queue.add(
            job.name, job.schedule, job.files, f"resumption of job {job.id}", time.time(),
            resumes=[*job.resumes, str(run_file)], first=True,
        )
        log.warning("job %d resumes job %d from %s", resumption.id, job.id, run_file)

    # ----------------------------------------------------------------- the control socket
    def dispatch(
        self, request: dict[str, Any], peer: Peer
    ) -> dict[str, Any] | Iterator[dict[str, Any]]:
        """Answer one control request (:mod:`.protocol`)."""
        op = request.get("op")
        if op == "status":
            return self._status_reply()
        if op == "submit":
            files = request.get("files")
            schedule = request.get("schedule")
            if not isinstance(files, dict) or not isinstance(schedule, str):
                raise ControlError("submit needs 'schedule' and 'files'")
            texts = {str(k): str(v) for k, v in files.items()}
            job = self.submit(schedule, texts, f"uid {peer.uid}")
            log.info("job %d (%s) submitted by uid %d", job.id, job.name, peer.uid)
            return reply(job=job.public())
        if op == "queue":
            return reply(jobs=[j.public() for j in self.queue.jobs()])
        if op == "cancel":
            return reply(job=self._cancel(_job_id(request), peer).public())
        if op == "abort":
            return reply(job=self._abort(peer))
        if op == "resume":
            return reply(resumed=self._resume(peer))
        if op == "follow":
            return self._follow(request)
        if op == "solutions":
            return reply(solutions=self._solutions(int(request.get("limit", 20))))
        raise ControlError(f"unknown op {op!r}")

    def _status_reply(self) -> dict[str, Any]:
        changes = self.machine.history
        return reply(
            state=self.machine.state,
            since=changes[-1].at if changes else None,
            job=self.current.public() if self.current else None,
            step=self.progress.step_text if self.progress else None,
            left_s=self.progress.left_s if self.progress else None,
            queue=[j.id for j in self.queue.jobs("queued")],
            paused=self.paused,
            alarms=list(self.alarms.values()),
            timers=self.timers.next_occurrences(self.clock.now()),
            status=self.status_line(),
            health=self.monitor.status(),
        )

    def _cancel(self, job_id: int, peer: Peer) -> Job:
        job = self.queue.get(job_id)
        if job is None:
            raise ControlError(f"no job {job_id}")
        if job.state == "queued":
            return self.queue.update(job, state="cancelled", ended=time.time(),
                                     reason=f"cancelled by uid {peer.uid} before it ran")
        if job.state == "running" and self.session is not None and self.current is job:
            self.queue.update(job, state="cancelled")
            self.session.stop(f"cancelled by uid {peer.uid}")
            return job
        raise ControlError(f"job {job_id} is {job.state}: nothing to cancel")

    def _abort(self, peer: Peer) -> dict[str, Any] | None:
        self.paused = True
        if self.session is not None and self.current is not None:
            self.session.stop(f"aborted by uid {peer.uid}")
            return self.current.public()
        with self._loop:
            self._go_safe()
        return None

    def _resume(self, peer: Peer) -> bool:
        with self._loop:
            self.paused = False
            self.alarms.pop("run", None)
            if self.machine.state == "faulted" and "link" not in self.alarms:
                self.machine.go("idle", f"resumed by uid {peer.uid}")
            return True

    def _follow(self, request: dict[str, Any]) -> Iterator[dict[str, Any]]:
        job_id = request.get("job")
        if job_id is None:
            job = self.current or self.queue.next_queued()
            if job is None:
                raise ControlError("no job running or queued")
            job_id = job.id
        job = self.queue.get(int(job_id))
        if job is None:
            raise ControlError(f"no job {job_id}")
        if job.state not in ("queued", "running") and not self.hub.ended(job.id):
            return iter([reply(end=True, event={"kind": "end", "state": job.state,
                                                "reason": job.reason, "run": job.run,
                                                "report": job.report})])
        events = self.hub.follow(job.id, self._halt)
        return (reply(event=e, end=e["kind"] == "end") for e in events)

    def _solutions(self, limit: int) -> list[dict[str, Any]]:
        found: list[dict[str, Any]] = []
        runs = sorted((p for p in self.dirs.runs.glob(f"*/{RUN_FILE}")), reverse=True)
        for run_file in runs:
            if len(found) >= limit:
                break
            try:
                contents = read_run_file(run_file)
            except (ReceiverError, OSError, ValueError):
                continue
            solutions = contents.of_kind("solution")
            if solutions:
                found.append({"run": str(run_file), "name": contents.name,
                              "status": contents.status, "solutions": len(solutions),
                              "time": solutions[-1].timestamp})
        return found


def _job_id(request: dict[str, Any]) -> int:
    try:
        return int(request["job"])
    except (KeyError, TypeError, ValueError):
        raise ControlError("give the job's id: {\"job\": <id>}") from None
