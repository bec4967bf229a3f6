"""``reach-cal report``: a solution's figures and one-page summary, in a directory.

::

    reach-cal report SOLUTION.h5 [--run RUN.h5] -o DIR [--pdf] [--no-leave-one-out]

``SOLUTION.h5`` is a solution file or a receiver's run file (its latest solution, and the
run itself unless ``--run`` names another). :mod:`calibration.report.writer` says what is written.
"""

from __future__ import annotations

import argparse

from ..report.writer import write_report
from .files import check_outputs

__all__ = ["cmd_report"]


def cmd_report(args: argparse.Namespace) -> int:
    """Write a solution's figures (PNG, optionally one PDF) and its summary (Markdown, HTML).

    With --run (or a receiver's run file as SOLUTION.h5) the report adds each source's
    residual against its noise, the distance to the noise floor, the reflections, Dicke
    powers, flagged channels, thermocouples, the run's checks and alarms.
    """
    check_outputs({"-o": (args.output, "directory")}, [args.solution, args.run])
    report = write_report(
        args.solution, args.output, args.run, pdf=args.pdf,
        leave_one_out=not args.no_leave_one_out,
    )
    for path in (*report.figures, report.pdf, report.markdown, report.html):
        if path is not None:
            print(f"wrote {path}")
    return 0
