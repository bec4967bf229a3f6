"""Recovery at start: close the runs a crash or a power cut left open, and say how each ended.

A run directory whose part files were never merged (its writer died) is merged into its
``run.h5`` with the status its writer recorded, if it got that far, or as
``interrupted``, with the time of its last stored measurement and the time of the
recovery as the cause. Nothing else in it changes: the measurements are those the
writer made durable. Merging is idempotent, so a recovery itself interrupted is simply
done again at the next start.

How a run ended is read from the run itself, never guessed from the daemon's own record
of its job: a daemon killed in the second between a run's final merge and the job's
record finds a merged ``completed`` run, and its job is completed (:func:`run_outcome`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from reach_receiver.errors import ReceiverError
from reach_receiver.store import RUN_FILE, merge_run, read_run_file
from reach_receiver.store.parts import list_parts

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Recovered:
    """How a run ended: where, its status (``completed``, ``failed``, ``interrupted``), why."""

    directory: Path
    status: str
    reason: str
    #: Why the run could not be merged ("" when it was): its parts wait for the next start.
    error: str = ""


def _utc(at: float) -> str:
    return datetime.fromtimestamp(at, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def recover_run(directory: Path, now: float | None = None) -> Recovered | None:
    """Merge one run directory left open; ``None`` when it was closed already.

    A merge that fails (a damaged part, a full disk) leaves the parts as they are, to be
    merged at the next start, and is reported as an ``interrupted`` run whose reason
    says why: recovery never stops the daemon from starting.
    """
    try:
        return _merge_left_open(directory, now)
    except Exception as err:  # anything a damaged directory can raise: keep starting
        error = f"{type(err).__name__}: {err}"
        log.error("recovery of %s failed: %s", directory, error)
        reason = f"recovery could not merge the run ({error}); its parts are kept"
        return Recovered(directory, "interrupted", reason, error)


def _merge_left_open(directory: Path, now: float | None) -> Recovered | None:
    parts = list_parts(directory)
    if not parts:
        return None
    if any(p.kind == "status" for p in parts):  # the writer finished; its merge did not
        merge_run(directory)
        log.warning("recovered %s: finished its merge", directory)
        return _recorded(directory, "the merge was interrupted; finished by recovery")
    last = max(p.path.stat().st_mtime for p in parts)
    reason = (
        f"the daemon stopped during the run (last measurement stored {_utc(last)}); "
        f"closed by recovery at {_utc(now or time.time())}"
    )
    target = merge_run(directory, "interrupted", reason)
    log.warning("recovered %s: %s", target, reason)
    return Recovered(directory, "interrupted", reason)


def run_outcome(directory: Path) -> Recovered | None:
    """How the run in ``directory`` ended, merging it first if it was left open.

    ``None`` when the directory holds no run (the daemon stopped before its first part).
    """
    found = recover_run(directory)
    if found is not None:
        return found
    if not (directory / RUN_FILE).is_file():
        return None
    return _recorded(directory, "")


def _recorded(directory: Path, note: str) -> Recovered:
    """The status and reason the merged run file records (``interrupted`` if unreadable)."""
    try:
        contents = read_run_file(directory / RUN_FILE)
    except (ReceiverError, OSError, ValueError) as err:  # FileFormatError is a ValueError
        return Recovered(directory, "interrupted", f"its run file cannot be read: {err}")
    status = contents.status if contents.status != "unfinished" else "interrupted"
    reason = "; ".join(r for r in (contents.reason, note) if r)
    return Recovered(directory, status, reason)


def recover_runs(runs_dir: Path) -> list[Recovered]:
    """Recover every run directory under ``runs_dir`` that was left open."""
    if not runs_dir.is_dir():
        return []
    found = []
    for directory in sorted(p for p in runs_dir.iterdir() if p.is_dir()):
        if list_parts(directory) or not (directory / RUN_FILE).exists():
            result = recover_run(directory)
            if result is not None:
                found.append(result)
    return found
