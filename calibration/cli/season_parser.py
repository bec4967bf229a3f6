"""``reach-cal season``, ``recalibrate`` and ``export``'s parsers (argparse only).

The commands are in :mod:`calibration.cli.season`, :mod:`calibration.cli.recalibrate` and
:mod:`calibration.cli.export`; ``season`` and ``recalibrate`` run on Dask
(:mod:`calibration.season.archive`) and share the cluster's options.
"""

from __future__ import annotations

import argparse
import math
import re
from typing import Any

from .args import add_command, output_arg, positive_float, positive_int

__all__ = ["add_season_commands", "size_arg"]

#: The LST bin width when none is given (h; :data:`calibration.season.binning.DEFAULT_LST_BIN_H`).
DEFAULT_LST_BIN_H = 1.0
#: The formats ``export`` writes.
EXPORT_FORMATS = ("gsdata",)

SEASON = """Combine the calibrated antenna spectra of many runs into LST bins (a season file).

Each spectrum is weighted by its radiometer variance (a flagged channel gets no weight);
each bin's average keeps its error in two parts: radiometer noise (independent, averages
down) and the calibration's error (shared by the spectra one solution calibrated,
averaging down only across solutions). Which solution calibrated which spectra is
recorded. RUNS are the run.h5 files reach-run writes (or their run directories).

The work is a Dask graph: each run read and binned in chunks of spectra sized to a
worker's memory, the chunks' sums added in a tree fixed by the order of RUNS (the same
season, bit for bit, on any number of workers). It runs on a local cluster (--workers)
or an existing one (--scheduler); the cluster, its memory per worker and a progress line
per tenth of the chunks are printed."""

RECALIBRATE = """Recalibrate an archive's antenna cycles with a new solution, run by run.

Each run's calibrated cycles are calibrated again as the observe step did (the cycle's
powers and the S11s its hand-over names, over the solution's band, the engine's RFI
flags and the night's) and written to OUT/<run name>/run.h5, which reach-cal season
reads: reach-cal season OUT/* -o season.h5 is the recalibrated season. Every run is
checked before anything is written; each output is written atomically, and one already
made from its run with this solution is skipped ("skipped N done"), so an interrupted
command continues where it stopped. A task per run on a local Dask cluster (--workers)
or an existing one (--scheduler)."""

#: The least memory a worker may be given (bytes): an idle worker process holds ~150 MiB.
MIN_WORKER_MEMORY = 2**29
_SIZE = re.compile(r"^\s*([0-9]*\.?[0-9]+)\s*([kmgt]?)(i?b?)\s*$", re.IGNORECASE)


def size_arg(text: str) -> int:
    """A memory size such as ``4GiB``, ``500MB`` or ``2G`` (bytes; argparse type)."""
    match = _SIZE.match(text)
    if not match:
        raise argparse.ArgumentTypeError(f"expected a size such as 4GiB or 500MB, got {text!r}")
    number, prefix, suffix = match.groups()
    base = 1024 if suffix.lower().startswith("i") or not suffix else 1000
    value = float(number) * base ** " kmgt".index(prefix.lower() or " ")
    if not (math.isfinite(value) and value >= MIN_WORKER_MEMORY):
        raise argparse.ArgumentTypeError(
            f"expected at least 512MiB for a worker (its interpreter and libraries take "
            f"about 150MiB), got {text!r}"
        )
    return int(value)


def _add_cluster_options(parser: argparse.ArgumentParser) -> None:
    """``--workers``, ``--scheduler`` and ``--memory-per-worker``."""
    parser.add_argument(
        "--workers", type=positive_int, default=None,
        help="workers of the local cluster (default: one per 4 runs, up to this machine's "
        "cores: starting a worker process costs seconds; 1 runs in this process)",
    )
    parser.add_argument(
        "--scheduler", metavar="ADDRESS", default=None,
        help="address of an existing Dask distributed scheduler (tcp://host:8786) to run "
        "on instead of a local cluster; its workers must see the run files at the same paths",
    )
    parser.add_argument(
        "--memory-per-worker", type=size_arg, default=None, metavar="SIZE",
        help="memory limit of each local worker (default: 80%% of this machine's memory "
        "shared out); with --scheduler, at most this much of each worker's is used",
    )

EXPORT = """Export a season file to the 21-cm community's formats.

--format gsdata writes pygsdata's GSData (GSH5): frequencies, times and LSTs of the bins,
the site, the averages (K), flags, weights (nsamples: 1/K^2, the inverse radiometer
variance) and the errors as auxiliary measurements (calibration_error_k,
radiometer_error_k, per bin and channel)."""


def add_season_commands(sub: Any) -> None:
    """Add ``season`` and ``export`` to ``reach-cal``'s subcommands."""
    season: argparse.ArgumentParser = add_command(sub, "season", ".season:cmd_season", SEASON)
    season.add_argument("runs", nargs="+", metavar="RUNS", help="run files (HDF5) or run dirs")
    season.add_argument(
        "-o", "--output", type=output_arg, required=True, help="season file to write (HDF5)"
    )
    season.add_argument(
        "--lst-bin-h", type=positive_float, default=DEFAULT_LST_BIN_H,
        help="LST bin width in hours, dividing 24 (default %(default)g)",
    )
    _add_cluster_options(season)
    again: argparse.ArgumentParser = add_command(
        sub, "recalibrate", ".recalibrate:cmd_recalibrate", RECALIBRATE
    )
    again.add_argument("solution", help="solution file (HDF5, from reach-cal solve)")
    again.add_argument("runs", nargs="+", metavar="RUNS", help="run files (HDF5) or run dirs")
    again.add_argument(
        "-o", "--output", required=True, metavar="DIR",
        help="directory of the recalibrated runs (created; an existing one is resumed)",
    )
    again.add_argument(
        "--intervals", action="store_true",
        help="also store each spectrum's credible intervals, as observe does (default: off; "
        "a season does not read them, and they cost most of the time)",
    )
    _add_cluster_options(again)
    export: argparse.ArgumentParser = add_command(sub, "export", ".export:cmd_export", EXPORT)
    export.add_argument("season", help="season file (HDF5, from reach-cal season)")
    export.add_argument(
        "--format", choices=EXPORT_FORMATS, required=True, help="what to write: gsdata (GSH5)"
    )
    export.add_argument(
        "-o", "--output", type=output_arg, required=True, help="file to write (.gsh5)"
    )
