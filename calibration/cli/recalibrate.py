"""``reach-cal recalibrate``: an archive's calibrated cycles with a new solution, on Dask.

The work is :mod:`calibration.season.archive_apply`; the cluster is ``season``'s
(:func:`calibration.cli.season.cluster`).
"""

from __future__ import annotations

import argparse
import os

from ..io.solution_file import read_solution
from ..season.archive_apply import digest_of, output_paths, recalibrate_on_dask, split_done
from .season import cluster, missing_runs, run_files


def cmd_recalibrate(args: argparse.Namespace) -> int:
    """Check the runs, skip the outputs done, recalibrate the rest."""
    runs = run_files(list(args.runs))
    outputs = output_paths(runs, args.output)
    missing_runs(runs)
    solution = read_solution(args.solution)
    todo, done = split_done(runs, outputs, digest_of(solution))
    if done:
        print(f"skipped {done} done (recalibrated with this solution in {args.output})")
    if not todo:
        print(f"nothing to do: all {done} runs are in {args.output}")
        return 0
    with cluster(args, len(todo)) as opened:
        written = recalibrate_on_dask(
            opened, todo, solution, os.path.abspath(args.solution),
            os.path.getmtime(args.solution), args.intervals,
        )
    print(f"recalibrated {len(todo)} runs, {written} spectra, into {args.output}")
    print(f"next: reach-cal season {os.path.join(args.output, '*')} -o season.h5")
    return 0
