"""``python -m benchmarks.faults [--quick] [--only CLASS] [-v]``: the fault table.

Runs every class of faults of :mod:`benchmarks.faults` (in full unless ``--quick``),
prints each trial that was not clean (all of them with ``-v``), then the table "tried /
clean / crash / lost / silent" per class. Exit 1 when any trial was not clean.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from .core import Trial, Verdict, fault_classes, table, tally


def main(argv: list[str] | None = None) -> int:
    """Run the classes; print the trials that were not clean and the table."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.faults", description=__doc__)
    p.add_argument("--quick", action="store_true", help="the suite's quick subset only")
    p.add_argument("--only", action="append", default=[], help="one class (repeatable)")
    p.add_argument("-v", "--verbose", action="store_true", help="print every trial")
    args = p.parse_args(argv)
    rows: list[tuple[str, dict[Verdict, int]]] = []
    for module in fault_classes():
        name = str(module.CLASS)
        if args.only and name not in args.only:
            continue
        start = time.perf_counter()
        with tempfile.TemporaryDirectory(prefix=f"faults-{name}-") as work:
            trials: list[Trial] = list(module.trials(Path(work), args.quick))
        for t in trials:
            if args.verbose or t.verdict != "clean":
                print(f"{name}: {t.verdict:<6} {t.name}: {t.detail}", flush=True)
        print(f"{name}: {len(trials)} tried in {time.perf_counter() - start:.1f} s", flush=True)
        rows.append((name, tally(trials)))
    print(table(rows))
    bad = sum(c[v] for _, c in rows for v in ("crash", "lost", "silent"))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
