"""The daemon's own state files (``queue.json``, ``timers.json``): written, and read at start.

A write that fails (a full disk) keeps the previous file and says so once
(:func:`write_state`); the caller keeps its state in memory and writes again later.


They are written atomically (:func:`calibration.core.atomic_file.write_atomically`), so a
crash leaves either the old file or the new one; but a disk fault, a hand edit or a copy
from elsewhere can still leave one that does not read. A daemon that refused to start
over it would leave the front-end to a restart loop, so an unreadable file is moved
aside (``<name>.unreadable-<UTC time>``, kept for whoever looks into it), the daemon
starts as if it had none, and says so (:attr:`StateFile.problem`, an alarm).
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, TypeVar

from calibration.core.atomic_file import write_atomically

log = logging.getLogger(__name__)

T = TypeVar("T")
#: A state file larger than this is not read (ours are a few kB; a queue of 50 ended
#: jobs with their schedules' texts a few MB).
MAX_BYTES = 64 * 2**20


def read_state(path: Path, parse: Callable[[Any], T]) -> tuple[T | None, str | None]:
    """``parse`` of the JSON in ``path``; ``(None, None)`` when there is no such file.

    A file that cannot be read, is not JSON or that ``parse`` rejects (any of
    ``KeyError``, ``TypeError``, ``ValueError``) is moved aside: ``(None, problem)``.
    """
    try:
        if path.stat().st_size > MAX_BYTES:
            raise ValueError(f"larger than {MAX_BYTES // 2**20} MB")
        return parse(json.loads(path.read_bytes())), None
    except FileNotFoundError:
        return None, None
    except (OSError, KeyError, TypeError, ValueError, AttributeError) as err:
        stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
        aside = path.with_name(f"{path.name}.unreadable-{stamp}")
        try:
            os.replace(path, aside)
            kept = f"moved to {aside.name}"
        except OSError as move:
            kept = f"left in place ({move.strerror or move})"
        problem = (f"{path}: unreadable ({type(err).__name__}: {err}); {kept}, "
                   "the daemon started without it")
        log.error("%s", problem)
        return None, problem


def write_state(path: Path, text: str, previous_error: str | None) -> str | None:
    """Write ``text`` to ``path`` atomically; ``None``, or why it was not written.

    A failure is logged once (while ``previous_error`` says the same), and the file
    written again after one is logged too.
    """
    try:
        write_atomically(path, text)
    except OSError as err:
        error = f"{path}: not written, its previous state kept ({err.strerror or err})"
        if error != previous_error:
            log.error("%s", error)
        return error
    if previous_error is not None:
        log.warning("%s: written again", path)
    return None
