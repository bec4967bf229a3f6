"""Recovery at start: close the runs a crash or a power cut left open, and say so.

A run directory whose part files were never merged (its writer died) is merged into its
``run.h5`` with the status its writer recorded, if it got that far, or as
``interrupted``, with the time of its last stored measurement and the time of the
recovery as the cause. Nothing else in it changes: the measurements are those the
writer made durable. Merging is idempotent, so a recovery itself interrupted is simply
done again at the next start.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from reach_receiver.store import RUN_FILE, merge_run
from reach_receiver.store.parts import list_parts

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Recovered:
    """A run closed by recovery: where, with which status and why."""

    directory: Path
    status: str
    reason: str


def _utc(at: float) -> str:
    return datetime.fromtimestamp(at, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def recover_run(directory: Path, now: float | None = None) -> Recovered | None:
    """Merge one run directory left open; ``None`` when it was closed already."""
    parts = list_parts(directory)
    if not parts:
        return None
    if any(p.kind == "status" for p in parts):  # the writer finished; its merge did not
        target = merge_run(directory)
        log.warning("recovered %s: finished its merge", directory)
        return Recovered(directory, "as recorded", "the merge was interrupted")
    last = max(p.path.stat().st_mtime for p in parts)
    reason = (
        f"the daemon stopped during the run (last measurement stored {_utc(last)}); "
        f"closed by recovery at {_utc(now or time.time())}"
    )
    target = merge_run(directory, "interrupted", reason)
    log.warning("recovered %s: %s", target, reason)
    return Recovered(directory, "interrupted", reason)


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
