"""``reach-cal season`` and ``reach-cal export``'s parsers (argparse only, like every parser).

The commands are in :mod:`calibration.cli.season` and :mod:`calibration.cli.export`.
"""

from __future__ import annotations

import argparse
from typing import Any

from .args import add_command, output_arg, positive_float

__all__ = ["add_season_commands"]

#: The LST bin width when none is given (h; :data:`calibration.season.binning.DEFAULT_LST_BIN_H`).
DEFAULT_LST_BIN_H = 1.0
#: The formats ``export`` writes.
EXPORT_FORMATS = ("gsdata",)

SEASON = """Combine the calibrated antenna spectra of many runs into LST bins (a season file).

Each spectrum is weighted by its radiometer variance (a flagged channel gets no weight);
each bin's average keeps its error in two parts: radiometer noise (independent, averages
down) and the calibration's error (shared by the spectra one solution calibrated,
averaging down only across solutions). Which solution calibrated which spectra is
recorded. RUNS are the run.h5 files reach-run writes (or their run directories)."""

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
    export: argparse.ArgumentParser = add_command(sub, "export", ".export:cmd_export", EXPORT)
    export.add_argument("season", help="season file (HDF5, from reach-cal season)")
    export.add_argument(
        "--format", choices=EXPORT_FORMATS, required=True, help="what to write: gsdata (GSH5)"
    )
    export.add_argument(
        "-o", "--output", type=output_arg, required=True, help="file to write (.gsh5)"
    )
