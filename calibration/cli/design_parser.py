"""The parsers of ``reach-cal plan`` and ``solve --contributions`` (no engine imported)."""

from __future__ import annotations

import argparse
from typing import Any

from .args import add_command, band_arg, number_arg, positive_float

PLAN_DOC = """Propose the next calibration schedule: seconds per calibrator for a target error.

From an earlier run's posterior: the seconds per Dicke position each calibrator needs so
that the antenna's predicted calibration error (RMS over the band) reaches --target-mk,
chosen as the adaptive step chooses (most error removed per second), beside the
round-robin (one time for all) to the same target (docs/adaptive.md)."""


def add_antenna_options(parser: argparse.ArgumentParser) -> None:
    """Which source is the antenna, its temperature and the band of interest."""
    parser.add_argument(
        "--antenna", default="ant",
        help="the run's source whose calibration error counts (default ant)",
    )
    parser.add_argument(
        "--antenna-k", type=positive_float, default=None,
        help="the antenna's temperature at 75 MHz, K (default: a power law fitted to its "
        "spectrum as the solution calibrates it)",
    )
    parser.add_argument(
        "--antenna-index", type=float, default=0.0,
        help="with --antenna-k: its spectral index (default 0, a flat load; about -2.5 for "
        "the sky)",
    )
    parser.add_argument(
        "--interest", type=band_arg, default=None, metavar="LO,HI",
        help="band of interest in MHz over which the error is averaged (default: all)",
    )


def add_contributions_option(solve: argparse.ArgumentParser) -> None:
    """``solve --contributions``."""
    solve.add_argument(
        "--contributions", action="store_true",
        help="also print each calibrator's share of the antenna's information and the "
        "antenna's predicted error without it (needs the antenna's reflection in the run; "
        "default: not printed)",
    )
    add_antenna_options(solve)


def add_plan_command(sub: Any) -> None:
    """``reach-cal plan RUN --target-mk X``."""
    plan = add_command(sub, "plan", ".design:cmd_plan", PLAN_DOC)
    plan.add_argument("run", help="an earlier run file (HDF5) of the same receiver")
    plan.add_argument(
        "--target-mk", type=positive_float, required=True,
        help="the antenna's target calibration error, RMS over the band, mK",
    )
    plan.add_argument(
        "--first-pass-s", type=positive_float, default=60.0,
        help="seconds per position every calibrator gets at least (default 60)",
    )
    plan.add_argument(
        "--overhead-s", type=number_arg(float, 0.0), default=10.0,
        help="switching and settling per measurement, s (default 10)",
    )
    plan.add_argument(
        "--budget-h", type=positive_float, default=48.0,
        help="the most instrument time the plan may use, h (default 48)",
    )
    add_antenna_options(plan)
