"""``reach-cal export --format gsdata``: a season file as pygsdata's GSData (GSH5)."""

from __future__ import annotations

import argparse

import numpy as np

from ..season.gsdata import write_gsdata
from ..season.season_file import read_season
from .season import check_output


def cmd_export(args: argparse.Namespace) -> int:
    """Read the season file and write it in the format asked for."""
    check_output(args.output, [args.season], "GSH5", None)
    season = read_season(args.season)
    write_gsdata(season, args.output)
    kept = int(np.sum(~np.all(season.flags, axis=1)))
    print(f"exported {kept} LST bins x {season.freq_hz.size} channels as GSData")
    print(f"wrote {args.output}")
    return 0
