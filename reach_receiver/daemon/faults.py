"""What the daemon does when something went wrong: a front-end, a job interrupted.

* The front-end goes to its safe state through the Teensy alone (:meth:`_go_safe`) at
  start, after an abort, and as the test of a link that failed: the daemon then tries
  again with a growing back-off (:data:`BACKOFF_S`) and leaves ``faulted`` by itself
  once the front-end answers.
* At start, the runs a crash left open are closed (:mod:`.recovery`) and the jobs that
  were running are marked interrupted; with the site's ``resume`` policy their
  continuation is queued first, as it is for a job whose link failed.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from reach_receiver.devices.teensy import Teensy
from reach_receiver.errors import ReceiverError
from reach_receiver.store import RUN_FILE

from .base import DaemonBase
from .jobs import Job
from .recovery import recover_runs, run_outcome

log = logging.getLogger(__name__)

#: Back-off of the attempts to reach a front-end that stopped answering (s of real time).
BACKOFF_S = (1.0, 2.0, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0)


class FaultHandling(DaemonBase):
    """The front-end's safe state and its retries; recovery of interrupted jobs."""

    def _go_safe(self) -> None:
        """Put the front-end in its safe state through the Teensy alone, and let it go."""
        teensy = self.site.devices.teensy
        with self.monitor.hardware():
            state = Teensy.command_safe(teensy.port, teensy.timeout_s)
        log.info("front-end safe: %s", state.describe())

    def _try_safe(self) -> str:
        """:meth:`_go_safe`; ``""`` when the front-end answered, what went wrong otherwise."""
        try:
            self._go_safe()
        except (ReceiverError, OSError) as err:
            return str(err) or type(err).__name__
        return ""

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

    def _recover(self) -> None:
        """Close runs left open; each job that was running ends as its run file says.

        A run merged ``completed`` (or ``failed``) before the daemon died gives its job
        that state; only an interrupted run is resumed (with the site's ``resume``
        policy). A job whose run never began is queued again whole under that policy.
        """
        recovered = {r.directory: r for r in recover_runs(self.dirs.runs)}
        for failed in (r for r in recovered.values() if r.error):
            self.alarms[f"recovery {failed.directory.name}"] = failed.reason
        for job in self.queue.jobs("running"):
            directory = Path(job.run) if job.run else None
            found = recovered.get(directory) if directory else None
            if directory is not None and found is None:
                found = run_outcome(directory)
            state = found.status if found else "interrupted"
            reason = found.reason if found else "the daemon stopped before the run began"
            self.queue.update(job, state=state, ended=time.time(), reason=reason)
            log.warning("job %d was running when the daemon stopped: its run is %s%s",
                        job.id, state, f" ({reason})" if reason else "")
            if found is not None and found.error:
                self.alarms[f"recovery {found.directory.name}"] = reason
            elif self.site.daemon.resume and state == "interrupted":
                if found is None and not job.origin.startswith("restart of"):
                    self._queue_again(job)  # once: a job that kills the daemon must not loop
                elif directory is not None:
                    self._queue_resumption(job, directory / RUN_FILE)

    def _queue_again(self, job: Job) -> None:
        again = self.queue.add(
            job.name, job.schedule, job.files, f"restart of job {job.id}", time.time(),
            resumes=list(job.resumes), first=True,
        )
        log.warning("job %d runs job %d again: it stopped before its run began", again.id, job.id)

    def _queue_resumption(self, job: Job, run_file: Path) -> None:
        if not run_file.exists():
            return
        resumption = self.queue.add(
            job.name, job.schedule, job.files, f"resumption of job {job.id}", time.time(),
            resumes=[*job.resumes, str(run_file)], first=True,
        )
        log.warning("job %d resumes job %d from %s", resumption.id, job.id, run_file)
