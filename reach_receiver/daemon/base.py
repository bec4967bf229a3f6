"""What the parts of the daemon share: its directories, and the state they all read.

:class:`~reach_receiver.daemon.service.Daemon` is built from parts with one job each,
each a class in its own module that the next one extends:

* :class:`DaemonBase` (here): the attributes, which :class:`~.service.Daemon` sets;
* :class:`~.faults.FaultHandling`: the front-end's safe state, a link that failed and
  its retries, the jobs a stop interrupted and their resumption;
* :class:`~.running.JobRunning`: checking and queueing schedules, running a job in a
  worker thread and recording how it ended, the timers' jobs;
* :class:`~.requests.ControlRequests`: the control socket's requests and the status
  they and systemd are told;
* :class:`~.service.Daemon`: the life cycle and the main loop.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field
from pathlib import Path

from reach_receiver.clock import Clock
from reach_receiver.config.site import SiteConfig
from reach_receiver.monitor import Monitor
from reach_receiver.run.session import RunFailed, RunSession, RunSummary
from reach_receiver.run.summary import Truth
from reach_receiver.schedule.kinds import KindRegistry

from .control import ControlServer
from .events import EventHub, HubProgress
from .jobs import Job, JobQueue
from .lock import HardwareLock
from .notify import Notifier, Watchdog
from .states import StateMachine
from .status_page import StatusPage
from .timers import Timers


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


class DaemonBase:
    """The daemon's state, shared by its parts (set by :class:`~.service.Daemon`)."""

    site: SiteConfig
    clock: Clock
    dirs: Directories
    kinds: KindRegistry
    tick_s: float
    machine: StateMachine
    hub: EventHub
    notifier: Notifier
    watchdog: Watchdog
    queue: JobQueue
    timers: Timers
    lock: HardwareLock
    server: ControlServer
    #: The daemon's own alarms by cause ("run", "link", "timer NAME").
    alarms: dict[str, str]
    monitor: Monitor
    page: StatusPage | None
    paused: bool
    current: Job | None
    session: RunSession | None
    #: The simulator's truth (``reachd --sim``), for the result's lines (run.summary).
    truth: Truth | None
    progress: HubProgress | None
    _worker: threading.Thread | None
    #: Set by the worker thread when its run ended; read by the main loop.
    _finished: tuple[Job, RunFailed | None, RunSummary | None] | None
    #: Held by the main loop during each turn.
    _loop: threading.RLock
    _halt: threading.Event
    _halt_reason: str
    #: When to try a front-end that stopped answering again (monotonic s), and how often
    #: it was tried.
    _retry_at: float | None
    _retries: int
    _status: str
