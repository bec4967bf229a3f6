"""``reach-cal season``: many runs' calibrated spectra in LST bins (:mod:`calibration.season`).

The season is computed on Dask (:mod:`calibration.season.archive`); :func:`cluster`
opens the cluster ``season`` and ``recalibrate`` share.
"""

from __future__ import annotations

import argparse
import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

import h5py
import numpy as np

from ..core.errors import InvalidDataError
from ..season.archive import Cluster, archive_client, season_on_dask
from ..season.binning import lst_edges
from ..season.season_file import SEASON_FORMAT, write_season
from .files import same_file


def run_files(given: list[str]) -> list[str]:
    """The run files named: a run directory stands for its ``run.h5``; none twice."""
    out: list[str] = []
    for name in given:
        path = os.path.join(name, "run.h5") if os.path.isdir(name) else name
        if any(same_file(path, seen) for seen in out if os.path.exists(path)):
            raise InvalidDataError(f"{path} is given twice: its spectra would count twice")
        out.append(path)
    return out


def check_output(path: str, inputs: list[str], kind: str, fmt: str | None) -> None:
    """Refuse an output that is an input, or an existing file that is not of ``fmt``.

    ``fmt`` is the root ``format`` attribute the replaced file must have (``None``: a
    GSH5 file, told by its ``metadata`` and ``data`` groups).
    """
    for read in inputs:
        if os.path.exists(read) and same_file(path, read):
            raise InvalidDataError(f"-o {path} is an input ({read}); choose another output")
    if not os.path.exists(path) or (os.path.isfile(path) and os.path.getsize(path) == 0):
        return
    try:
        with h5py.File(path, "r") as f:
            found = f.attrs.get("format", "")
            found = found.decode() if isinstance(found, bytes) else str(found)
            ours = found == fmt if fmt is not None else {"metadata", "data"} <= set(f)
    except OSError:
        ours = False
    if not ours:
        raise InvalidDataError(
            f"-o {path} exists and is not a {kind} file: it would be replaced; remove it "
            "first or choose another output"
        )


#: Runs per local worker when --workers is not given (a worker process takes seconds to start).
RUNS_PER_WORKER = 4


def missing_runs(runs: list[str]) -> None:
    """Refuse a run file that is not there, before any cluster starts."""
    for path in runs:
        if not os.path.isfile(path):
            raise InvalidDataError(f"{path}: no such run file")


@contextlib.contextmanager
def cluster(args: argparse.Namespace, n_runs: int) -> Iterator[Cluster]:
    """The Dask cluster of ``--scheduler``, or a local one of ``--workers``."""
    workers = args.workers or min(os.cpu_count() or 1, -(-n_runs // RUNS_PER_WORKER))
    with archive_client(args.scheduler, workers, args.memory_per_worker) as opened:
        yield opened


def cmd_season(args: argparse.Namespace) -> int:
    """Read, bin and combine the runs on Dask; write the season file."""
    runs = run_files(list(args.runs))
    check_output(args.output, runs, "season", SEASON_FORMAT)
    edges = lst_edges(args.lst_bin_h)
    missing_runs(runs)
    with cluster(args, len(runs)) as opened:
        season = season_on_dask(opened, runs, edges)
    write_season(Path(args.output), season, software=_software())
    used = ~season.flags
    print(
        f"season: {len(season.runs)} runs, {len(season.spectra)} spectra, "
        f"{len(season.solutions)} solutions, {int(np.any(used, axis=1).sum())} of "
        f"{season.edges_h.size - 1} LST bins of {args.lst_bin_h:g} h with data"
    )
    if used.any():
        print(
            f"median error of a bin's channel: radiometer "
            f"{1e3 * float(np.median(season.std_radiometer[used])):.3f} mK, calibration "
            f"{1e3 * float(np.median(season.std_calibration[used])):.3f} mK"
        )
    print(f"wrote {args.output}")
    return 0


def _software() -> str:
    from importlib import metadata

    try:
        return f"reach-receiver {metadata.version('reach-receiver')}"
    except metadata.PackageNotFoundError:
        return "reach-receiver (not installed)"
