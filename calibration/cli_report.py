"""``reach-cal report``: a solution's figures and one-page summary, in a directory.

::

    reach-cal report SOLUTION.h5 [--run RUN.h5] -o DIR [--pdf]

``SOLUTION.h5`` is a solution file or a receiver's run file (its latest solution, and the
run itself unless ``--run`` names another). :mod:`calibration.report` says what is written.
matplotlib is imported only when the command runs.
"""

from __future__ import annotations

import argparse
from typing import Any

from .cli_args import add_command
from .cli_files import check_outputs

__all__ = ["add_report_command", "cmd_report"]


def cmd_report(args: argparse.Namespace) -> int:
    """Write a solution's figures (PNG, optionally one PDF) and its summary (Markdown, HTML).

    With --run (or a receiver's run file as SOLUTION.h5) the report adds each source's
    residual against its noise, the distance to the noise floor, the reflections, Dicke
    powers, flagged channels, thermocouples, the run's checks and alarms.
    """
    check_outputs({"-o": (args.output, "directory")}, [args.solution, args.run])
    from .report import write_report

    report = write_report(args.solution, args.output, args.run, pdf=args.pdf)
    for path in (*report.figures, report.pdf, report.markdown, report.html):
        if path is not None:
            print(f"wrote {path}")
    return 0


def add_report_command(sub: Any) -> None:
    """Register ``report`` on the ``reach-cal`` subparsers ``sub``."""
    report = add_command(sub, "report", cmd_report)
    report.add_argument("solution", help="solution file, or a receiver run file (HDF5)")
    report.add_argument("--run", help="run file the solution calibrates (HDF5)")
    report.add_argument("-o", "--output", required=True, help="directory to write (created)")
    report.add_argument("--pdf", action="store_true", help="also write all figures to report.pdf")
