"""An archive recalibrated with a new solution on Dask: one task per run, resumable.

Each run ``.../<name>/run.h5`` (or ``<name>.h5``) becomes ``OUT/<name>/run.h5``: its
calibrated antenna cycles calibrated again with the solution
(:func:`calibration.season.recalibrate.write_recalibrated_run`), a run file that
``reach-cal season OUT/*`` reads. The work is two rounds of tasks on the cluster
(:func:`calibration.season.archive.archive_client`): every run is checked first (it has
calibrated cycles whose hand-over measurements cover the solution's band and grid), so
that a bad input stops the command before anything is written; then each run is
recalibrated and written atomically by its task (a hidden temporary file beside the
target, flushed and renamed over it: :func:`recalibrate_file`), so a killed command
leaves no partial ``run.h5``, only a hidden temporary file that is never read.

Resuming: an output that exists holds the digest of the solution that made it and the
run it came from (root attributes ``solution_digest``, ``recalibrated_from``); one made
with this solution from this run is complete (written atomically) and not redone. One
made from another solution or run is refused: ``OUT`` is another archive.
"""

from __future__ import annotations

import io
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

import h5py

from ..core.atomic_file import replacing
from ..core.errors import InvalidDataError
from ..io.calibrated_spectra import solution_digest
from ..io.solution_file import write_solution_group
from ..solve.solvers import AnySolution
from .archive import Cluster, Progress, guarded, out_of_memory, raise_failure
from .recalibrate import check_run, write_recalibrated_run

__all__ = ["digest_of", "output_paths", "recalibrate_file", "recalibrate_on_dask", "split_done"]


def digest_of(solution: AnySolution) -> str:
    """The digest a season knows the solution by (of its stored datasets)."""
    with h5py.File(io.BytesIO(), "w") as f:
        write_solution_group(f.create_group("solution"), solution)
        return solution_digest(f["solution"])


def _name(run: str) -> str:
    path = Path(run)
    return path.parent.name if path.name == "run.h5" else path.stem


def output_paths(runs: Sequence[str], out_dir: str) -> list[str]:
    """``OUT/<name>/run.h5`` of each run; refused where two runs share a name."""
    if os.path.exists(out_dir) and not os.path.isdir(out_dir):
        raise InvalidDataError(
            f"-o {out_dir} is a file: recalibrate writes a directory of run directories; "
            "choose a directory"
        )
    seen: dict[str, str] = {}
    out = []
    for run in runs:
        name = _name(run)
        if name in seen:
            raise InvalidDataError(
                f"{run} and {seen[name]} would both be written to {out_dir}/{name}: "
                "recalibrate them into different directories"
            )
        seen[name] = run
        out.append(os.path.join(out_dir, name, "run.h5"))
    return out


def split_done(
    runs: Sequence[str], outputs: Sequence[str], digest: str
) -> tuple[list[tuple[str, str]], int]:
    """The (run, output) pairs still to do, and how many outputs are done already."""
    todo, done = [], 0
    for run, out in zip(runs, outputs, strict=True):
        if not os.path.exists(out):
            todo.append((run, out))
            continue
        try:
            with h5py.File(out, "r") as f:
                made = str(f.attrs.get("solution_digest", "")), str(
                    f.attrs.get("recalibrated_from", ""))
        except OSError:
            made = ("", "")
        if made != (digest, os.path.abspath(run)):
            raise InvalidDataError(
                f"{out} exists and was not recalibrated from {run} with this solution: "
                "-o holds another archive; choose another directory"
            )
        done += 1
    return todo, done


def recalibrate_file(
    run: str, out: str, solution: AnySolution, solution_file: str, solution_time: float,
    intervals: bool,
) -> int:
    """Recalibrate one run into ``out`` atomically; its number of spectra.

    The file is written beside ``out`` under a hidden temporary name, flushed to disk and
    renamed over it (:func:`calibration.core.atomic_file.replacing`: a file too large to
    build in memory, a night of cycles at 16k channels being GBs).
    """
    with replacing(Path(out)) as tmp, h5py.File(tmp, "w") as f:
        n = write_recalibrated_run(run, f, solution, solution_file, solution_time, intervals)
    return n


def recalibrate_on_dask(
    cluster: Cluster, todo: Sequence[tuple[str, str]], solution: AnySolution,
    solution_file: str, solution_time: float, intervals: bool = False,
    stream: TextIO | None = None,
) -> int:
    """Check every run, then recalibrate each (module doc); the spectra written."""
    from distributed import KilledWorker, as_completed

    if not todo:
        return 0
    client = cluster.client
    [shared] = client.scatter([solution], broadcast=True)
    runs = [run for run, _ in todo]
    counts = client.gather(client.map(guarded, [check_run] * len(runs), runs,
                                      [shared] * len(runs), pure=False))
    for count in counts:
        raise_failure(count)
    print(cluster.description, file=stream or sys.stdout)
    print(f"recalibrate: {len(todo)} runs, {sum(counts)} spectra", file=stream or sys.stdout,
          flush=True)
    futures: dict[Any, int] = {
        client.submit(guarded, recalibrate_file, run, out, shared, solution_file,
                      solution_time, intervals, pure=False): count
        for (run, out), count in zip(todo, counts, strict=True)
    }
    progress = Progress("recalibrate", len(futures), "spectra", stream)
    written = 0
    failure = None
    for future in as_completed(list(futures)):
        try:
            result = future.result()
        except KilledWorker as err:
            raise out_of_memory(err, cluster.memory_per_worker) from None
        if isinstance(result, int):
            written += result
        elif failure is None:
            failure = result
        progress.step(futures.pop(future))
    raise_failure(failure)
    return written
