"""``reach-run recover RUN``: merge a killed run's parts into its ``run.h5``.

A run writes its measurements as parts and merges them when it ends
(:mod:`reach_receiver.store`); a run whose writer was killed (power cut, ``kill -9``)
leaves the parts, which :func:`~reach_receiver.store.merge.merge_run` merges with the
status ``interrupted``. The command is that merge, with a one-line answer.
"""

from __future__ import annotations

import sys
from pathlib import Path


def recover(directory: Path, json_out: bool) -> int:
    """Merge ``directory``'s parts: 0 merged, 1 the merge failed, 2 not a run directory."""
    from reach_receiver.errors import ReceiverError
    from reach_receiver.store.merge import RUN_FILE, list_parts, merge_run

    if not directory.is_dir():
        print(f"reach-run recover: {directory} is not a directory", file=sys.stderr)
        return 2
    parts = list_parts(directory)
    if not parts and not (directory / RUN_FILE).is_file():
        print(f"reach-run recover: {directory} holds no run parts and no {RUN_FILE}",
              file=sys.stderr)
        return 2
    try:
        target = merge_run(directory, status="interrupted" if parts else None,
                           reason="recovered with reach-run recover" if parts else "")
    except (ReceiverError, OSError, ValueError) as err:
        print(f"reach-run recover: {directory}: {err}", file=sys.stderr)
        return 1
    if json_out:
        from .commands import dumps

        print(dumps({"run_file": str(target), "parts_merged": len(parts)}))
    else:
        print(f"{target}: {len(parts)} parts merged" if parts else f"{target}: nothing to merge")
    return 0
