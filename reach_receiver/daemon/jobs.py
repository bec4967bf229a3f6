"""Jobs: schedules submitted to the daemon, queued, run, and remembered across restarts.

A job holds the schedule as submitted (its path as the client named it, and the texts of
it and every file it includes), so that it runs as validated even if the files change
or are not readable by the daemon's user. The queue is one JSON file in the state
directory, rewritten atomically (temporary file, fsync, rename) on every change, so a
crash or a power cut finds the queue as it was: queued jobs run after the restart, and a
job that was running is found and marked interrupted by recovery.

A queue file that cannot be written (a full disk) keeps its previous contents: the
daemon goes on with the queue in memory, logs the failure once, names it in
:attr:`JobQueue.write_error`, and writes the queue again at the next change or
:meth:`JobQueue.retry` (the main loop's turn).
"""

from __future__ import annotations

import json
import logging
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

from .state_file import read_state, write_state

log = logging.getLogger(__name__)

JobState = Literal["queued", "running", "completed", "failed", "interrupted", "cancelled"]
ENDED: tuple[JobState, ...] = ("completed", "failed", "interrupted", "cancelled")
#: Ended jobs kept in the queue file for ``queue`` replies.
KEEP_ENDED = 50
#: Real seconds between attempts to write a queue file that could not be written (a
#: failed attempt on a full disk costs one small temporary file, removed at once).
RETRY_S = 2.0


@dataclass
class Job:
    """One schedule to run, and what became of it.

    ``resumes`` lists the run files of earlier, interrupted runs of the same schedule that
    this job continues (oldest first); ``report`` is the directory of the calibration's
    report its run left (:mod:`reach_receiver.run.report`), if any; ``result`` what a
    completed run printed (:mod:`reach_receiver.run.summary`).
    """

    id: int
    name: str
    schedule: str
    files: dict[str, str]
    origin: str
    submitted: float
    state: JobState = "queued"
    started: float | None = None
    ended: float | None = None
    run: str | None = None
    reason: str = ""
    resumes: list[str] = field(default_factory=list)
    report: str | None = None
    #: A completed run's result as ``reach-run`` prints it (run.summary), for a follower
    #: who attaches after the end.
    result: list[str] = field(default_factory=list)

    def public(self) -> dict[str, Any]:
        """The job as the control protocol shows it (without the schedule's texts and result)."""
        out = asdict(self)
        del out["files"], out["result"]
        return out


class JobQueue:
    """The daemon's jobs, persisted in ``path`` (thread-safe)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._lock = threading.RLock()
        self._jobs: list[Job] = []
        self._next = 1
        #: Why the last write of the queue file failed (``None``: it is up to date).
        self.write_error: str | None = None
        self._failed_at = 0.0
        #: Why the queue file could not be read at start (``None``: it was, or was absent).
        self.read_error: str | None = None
        found, self.read_error = read_state(self.path, _parse_queue)
        if found is not None:
            self._jobs, self._next = found

    def add(
        self,
        name: str,
        schedule: str,
        files: dict[str, str],
        origin: str,
        submitted: float,
        *,
        resumes: list[str] | None = None,
        first: bool = False,
    ) -> Job:
        """Queue a new job (at the front with ``first``)."""
        with self._lock:
            job = Job(self._next, name, schedule, files, origin, submitted, resumes=resumes or [])
            self._next += 1
            if first:
                self._jobs.insert(0, job)
            else:
                self._jobs.append(job)
            self.save()
            return job

    def get(self, job_id: int) -> Job | None:
        """A job by id."""
        with self._lock:
            return next((j for j in self._jobs if j.id == job_id), None)

    def jobs(self, *states: JobState) -> list[Job]:
        """The jobs (in one of ``states``), in queue order."""
        with self._lock:
            return [j for j in self._jobs if not states or j.state in states]

    def next_queued(self) -> Job | None:
        """The job to run next."""
        queued = self.jobs("queued")
        return queued[0] if queued else None

    def update(self, job: Job, **changes: Any) -> Job:
        """Change a job and save the queue."""
        with self._lock:
            for key, value in changes.items():
                setattr(job, key, value)
            self.save()
            return job

    def save(self) -> None:
        """Write the queue atomically (ended jobs beyond the last few are forgotten).

        A write that fails keeps the previous file; the queue stays as it is in memory.
        """
        with self._lock:
            ended = [j for j in self._jobs if j.state in ENDED]
            for old in ended[:-KEEP_ENDED]:
                self._jobs.remove(old)
            text = json.dumps({"next_id": self._next, "jobs": [asdict(j) for j in self._jobs]})
            self.write_error = write_state(self.path, text, self.write_error)
            if self.write_error is not None:
                self._failed_at = time.monotonic()

    def retry(self) -> None:
        """Write the queue again if its last write failed (at most every :data:`RETRY_S`)."""
        with self._lock:
            if self.write_error is not None and time.monotonic() - self._failed_at >= RETRY_S:
                self.save()


def _parse_queue(data: Any) -> tuple[list[Job], int]:
    """The jobs and the next id of a queue file's JSON (``KeyError``/``TypeError`` if not)."""
    jobs = [Job(**job) for job in data["jobs"]]
    next_id = int(data["next_id"])
    if any(not isinstance(j.id, int) or j.id >= next_id for j in jobs):
        raise ValueError("a job's id is not below next_id")
    return jobs, next_id
