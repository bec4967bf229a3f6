"""``reach-cal validate``: leave-one-out validation of a run's calibrators.

::

    reach-cal validate RUN.h5 --leave-one-out [--method radiometric|thesis]
                       [--orders ... | --max-orders ...] [--basis ...] [--calibrators ...]
                       [-o REPORT.json | REPORT.csv]

Each calibrator is left out of the solve in turn and calibrated with the others' solution
(:mod:`calibration.checks.validation`); the table gives its RMS actual error, the RMS predicted
error (calibration part, and the full predictive), their ratio and the fractions of
channels inside the 68% / 95% intervals, or ``refused: <message>``.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
from pathlib import Path
from typing import Any

from ..checks.validation import HeldOut, LeaveOneOutReport, leave_one_out
from ..core.atomic_file import write_atomically
from ..core.errors import CalibrationError, InvalidDataError
from ..report.model_used import warning_lines
from ..solve.solution import Solution
from .files import check_outputs
from .solve import calibrators_of, noise_line, solver_from_args

__all__ = ["cmd_validate"]


def cmd_validate(args: argparse.Namespace) -> int:
    """Validate a run: each calibrator held out of the solve and calibrated as a test source.

    Columns (K): RMS of the held-out calibrator's calibrated minus known temperature; the
    RMS predicted error, calibration part alone and in full (with the source's radiometer
    noise); actual / full predicted; fractions of channels inside the 68% and 95%
    predictive intervals; the orders chosen. A refused solve prints its reason.
    """
    if not args.leave_one_out:
        raise InvalidDataError("validate needs a method: --leave-one-out")
    suffix = Path(args.output).suffix.lower() if args.output else ""
    if suffix not in ("", ".json", ".csv"):
        raise InvalidDataError(f"-o {args.output}: write .json or .csv")
    check_outputs({"-o": (args.output, "text")}, [args.run])
    data = calibrators_of(args)
    solve = solver_from_args(args)
    report = leave_one_out(data, solve)
    print(
        f"leave-one-out on {args.run} ({args.method}, {len(data.names)} calibrators, "
        f"{data.n_channels} channels); errors in K, RMS over channels; orders: the model "
        "used by each solve (the average's heaviest):"
    )
    for line in report.lines():
        print(f"  {line}")
    full = None
    if args.orders is not None:  # fixed orders: one cheap solve gives their s^2 to judge
        try:
            full = solve(data)
        except CalibrationError as err:
            print(f"every calibrator, orders {','.join(map(str, args.orders))}: refused: {err}")
    if isinstance(full, Solution):
        print(f"every calibrator, orders {','.join(map(str, args.orders))}: {noise_line(full)}")
    for line in warning_lines({"warnings": report.warnings(full)}):
        print(line)
    if args.output:
        text = _json(report, args) if suffix == ".json" else _csv(report)
        write_atomically(Path(args.output), text)
        print(f"wrote {args.output}")
    return 0


def _json(report: LeaveOneOutReport, args: argparse.Namespace) -> str:
    document: dict[str, Any] = {
        "run_file": str(args.run),
        "method": args.method,
        "orders": list(args.orders) if args.orders else None,
        "held_out": [r.as_dict() for r in report.results],
    }
    return json.dumps(document, indent=2) + "\n"


def _csv(report: LeaveOneOutReport) -> str:
    fields = list(HeldOut.__dataclass_fields__)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    for result in report.results:
        row = result.as_dict()
        row["calibrators"] = " ".join(result.calibrators)
        row["orders"] = " ".join(map(str, result.orders))
        writer.writerow(row)
    return buffer.getvalue()
