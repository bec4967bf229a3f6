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

The class is assembled from parts with one job each (:mod:`.base` lists them): this
module holds the life cycle and the main loop; :mod:`.running` the jobs, :mod:`.requests`
the control socket, :mod:`.faults` the front-end's faults and the recovery of jobs.
"""

from __future__ import annotations

import logging
import threading
import time

from calibration.core.sidereal import load_tables
from reach_receiver.clock import Clock, StopEvent
from reach_receiver.config.site import SiteConfig
from reach_receiver.monitor import Monitor
from reach_receiver.run.steps import STANDARD_KINDS
from reach_receiver.run.summary import Truth
from reach_receiver.schedule.kinds import KindRegistry

from .base import Directories
from .control import SOCKET_FILE, ControlServer
from .events import EventHub
from .faults import BACKOFF_S
from .jobs import JobQueue
from .lock import HardwareLock
from .notify import Notifier, Watchdog
from .requests import ControlRequests
from .running import schedule_reader
from .states import TRANSITIONS, StateMachine
from .status_page import StatusPage
from .timers import Timers

log = logging.getLogger(__name__)

__all__ = ["BACKOFF_S", "Daemon", "Directories", "schedule_reader"]


class Daemon(ControlRequests):
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
    lock
        The hardware lock, if the caller took it (``reachd`` does, before anything else).
    truth
        The simulator's truth (``reachd --sim``): a run's result then says how far its
        calibration is from it, as ``reach-run --sim`` does.
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
        lock: HardwareLock | None = None,
        truth: Truth | None = None,
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
        self.lock = lock or HardwareLock(directories.state, f"reachd ({site.source})")
        self.server = ControlServer(directories.runtime / SOCKET_FILE, self.dispatch)
        self.alarms = {}
        states = list(TRANSITIONS)
        self.monitor = Monitor(
            site, clock, directories.state, directories.runs,
            daemon_state=lambda: states.index(self.machine.state),
        )
        self.page = None
        if site.daemon.status_port is not None:  # read-only, 127.0.0.1 only (.status_page)
            self.page = StatusPage(site.daemon.status_port, self._status_reply, directories.runs,
                                   lambda: self.monitor.database, clock.now,
                                   lambda: [{**j.public(), "result": j.result}
                                            for j in self.queue.jobs()],
                                   self.monitor.settings.alarms)
        self.paused = False
        self.current = None
        self.session = None
        self.truth = truth
        self.progress = None
        self._worker = None
        self._finished = None
        self._loop = threading.RLock()
        self._halt = StopEvent()  # set from the signal handler
        self._halt_reason = ""
        self._retry_at = None
        self._retries = 0
        self._status = ""

    # ----------------------------------------------------------------- life cycle
    def start(self, made_safe: str | None = None) -> None:
        """Lock, go safe, recover, catch up with the timers, serve the socket, be ready.

        ``made_safe`` says the caller took the lock and commanded the safe state itself
        (``reachd`` does both before it imports the daemon): ``""`` when the front-end
        answered, what went wrong otherwise.
        """
        self.dirs.create()
        if made_safe is None:
            self.lock.acquire()
            made_safe = self._try_safe()
        if made_safe:
            self._link_failed(f"front-end unreachable at start: {made_safe}")
        self._recover()
        self._state_file_alarms()
        # The first sidereal time costs a second (astropy's tables): not in a first run.
        load_tables()
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

    def serve(self) -> bool:
        """The main loop, until :meth:`halt`; then the current run is stopped safely.

        A failure of the loop itself (a bug; nothing a client sends reaches it) stops
        the daemon the same way, the front-end commanded safe once more after the run's
        own stop; returns whether the loop ended by :meth:`halt` (``False``: it failed).
        """
        failure = None
        try:
            while not self._halt.wait(self.tick_s):
                self.tick()
        except Exception as err:
            failure = f"the main loop failed: {type(err).__name__}: {err}"
            log.critical("%s", failure, exc_info=True)
            self._halt_reason = self._halt_reason or failure
        self.machine.go("stopping", self._halt_reason)
        self.notifier.stopping(f"stopping: {self._halt_reason}")
        if self.session is not None:
            self.session.stop(self._halt_reason)
        if self._worker is not None:
            self._worker.join()
        self._collect()
        if failure is not None and (problem := self._try_safe()):
            log.critical("front-end: cannot command the safe state: %s", problem)
        return failure is None

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
            self.queue.retry()  # a queue file a full disk refused, written once there is room
            self._state_file_alarms()
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

    def _state_file_alarms(self) -> None:
        """Alarms for the state files: one while a file is not written (a full disk).

        And one for a file that could not be read at start (moved aside; ``resume``
        clears it).
        """
        for name, holder in (("queue file", self.queue), ("timers file", self.timers)):
            if holder.write_error:
                self.alarms[name] = holder.write_error
            else:
                self.alarms.pop(name, None)
            if holder.read_error:
                self.alarms[f"{name} at start"] = holder.read_error
                holder.read_error = None

    def healthy(self) -> bool:
        """Whether the daemon works: its socket serves and a run's worker is alive."""
        serving = self.server.serving
        running = self.machine.state in ("running", "observing")
        return serving and (not running or (self._worker is not None and self._worker.is_alive()))
