"""The control socket's requests (:mod:`.protocol`) and the status they are told.

:meth:`ControlRequests.dispatch` answers each request from the socket's threads:
``status``, ``submit``, ``queue``, ``cancel``, ``abort``, ``resume``, ``follow`` (a
stream of the job's events) and ``solutions``. :meth:`ControlRequests.status_line` is
the one line systemd, the log and the status page show.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from typing import Any

from reach_receiver.errors import ReceiverError
from reach_receiver.store import RUN_FILE, read_run_file

from .control import Peer
from .jobs import Job
from .protocol import ControlError, reply
from .running import JobRunning

log = logging.getLogger(__name__)


class ControlRequests(JobRunning):
    """Answers to the control socket, and the daemon's status."""

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
            now=self.clock.now(),  # the daemon's clock (a simulator's runs compressed)
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
            log.info("job %d cancelled by uid %d before it ran", job.id, peer.uid)
            return self.queue.update(job, state="cancelled", ended=time.time(),
                                     reason=f"cancelled by uid {peer.uid} before it ran")
        if job.state == "running" and self.session is not None and self.current is job:
            log.info("job %d cancelled by uid %d: stopping it", job.id, peer.uid)
            self.queue.update(job, state="cancelled")
            self.session.stop(f"cancelled by uid {peer.uid}")
            return job
        raise ControlError(f"job {job_id} is {job.state}: nothing to cancel")

    def _abort(self, peer: Peer) -> dict[str, Any] | None:
        """Stop the running job now and pause the queue; idle, pause and go safe.

        A run past its last step (closing its run file, drawing its report) has nothing
        left to stop: the abort is refused with that said, and changes nothing.
        """
        session, job = self.session, self.current
        if session is not None and job is not None:
            if session.closing:
                raise ControlError(
                    f"job {job.id} has run all its steps and is closing (its run file, its "
                    "report): nothing to abort; the queue was not paused"
                )
            self.paused = True
            session.stop(f"aborted by uid {peer.uid}")
            log.info("job %d aborted by uid %d; the queue is paused", job.id, peer.uid)
            return job.public()
        self.paused = True
        with self._loop:
            self._go_safe()
        log.info("abort by uid %d: the queue is paused, the front-end safe", peer.uid)
        return None

    def _resume(self, peer: Peer) -> bool:
        log.info("queue resumed by uid %d", peer.uid)
        with self._loop:
            self.paused = False
            # The operator has seen them: a failed run, and what the start found (a state
            # file moved aside, a run recovery could not merge).
            for cause in [c for c in self.alarms
                          if c == "run" or c.endswith(" at start") or c.startswith("recovery ")]:
                del self.alarms[cause]
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
            return iter([reply(end=True, event={"kind": "end", "job": job.id,
                                                "state": job.state, "reason": job.reason,
                                                "run": job.run, "report": job.report,
                                                "result": job.result})])
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
