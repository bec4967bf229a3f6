"""``reach-cal``: simulate, solve, apply and summarise noise-wave calibrations.

::

    reach-cal simulate -o RUN.h5 [--seed N] [--integration-s S] [--channel-width-hz B]
                       [--band LO,HI] [--calibrators a,b,...] [--vna-sigma X]
    reach-cal solve RUN.h5 -o SOLUTION.h5 [--method radiometric|thesis|least-squares|bayesian]
                    [--orders n_unc,n_cos,n_sin,n_NS,n_L | --max-orders ...] [--calibrators ...]
                    [--band LO,HI] [--mask-band LO,HI] [--rfi] [--smooth-s11 P]
                    [--check-consistency | --exclude-inconsistent [N]]  (cli.corrections)
    reach-cal apply SOLUTION.h5 RUN.h5 [--source ant] [-o OUT.h5] [--csv OUT.csv]
                    [--vna-accuracy DRAWS [--vna-correlation-mhz C] [--seed N]]
    reach-cal summary SOLUTION.h5 [--run RUN.h5 [--source NAME]]
    reach-cal import edges DIR -o RUN.h5 --temperatures amb=K,...  (cli.import_commands)
    reach-cal import vna DIR -o OUT_DIR --devices a,b,...
    reach-cal validate RUN.h5 --leave-one-out [...]
    reach-cal report SOLUTION.h5 [--run RUN.h5] -o DIR [--pdf] [--no-leave-one-out]
    reach-cal season RUNS... -o SEASON.h5 [--lst-bin-h H]   (cli.season_parser)
                     [--workers N | --scheduler ADDRESS] [--memory-per-worker SIZE]
    reach-cal recalibrate SOLUTION.h5 RUNS... -o DIR [--workers N | --scheduler ADDRESS]
    reach-cal export --format gsdata SEASON.h5 -o OUT.gsh5
    reach-cal plan RUN.h5 --target-mk X [--antenna ant] [--antenna-k K]  (cli.design_parser)

Files are those of :mod:`calibration.io.hdf5_io`. No command writes over one of its inputs or
a file holding measurements (:mod:`calibration.cli.files`); every numeric option is
range-checked as it is parsed (:func:`calibration.cli.args.number_arg`); ``apply`` refuses
a run on another channel grid than its solution's. Errors an operator can act on (unreadable or
malformed files, unusable data, an unsolvable model) print ``reach-cal: error: <message>``
on stderr without a traceback and exit with status 2, as do usage errors; success is 0.

Parsing imports nothing of the engine (:mod:`calibration.cli.args`): ``--help`` and
``--version`` answer at once, and a command's module (:mod:`.simulate`, :mod:`.solve`,
:mod:`.apply`, :mod:`.summary`, :mod:`.validate`, :mod:`.report`, :mod:`.import_commands`,
:mod:`.season`, :mod:`.recalibrate`, :mod:`.export`, :mod:`.design`)
is imported when it runs.
"""


from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import sys
from collections.abc import Sequence

from ..core.constants import DEFAULT_CORRELATION_HZ, ITPM_CHANNEL_WIDTH_HZ, REACH_CALIBRATORS
from ..core.errors import CalibrationError, IllPosedError
from .args import (
    add_command,
    add_correction_options,
    add_solver_options,
    band_arg,
    count_arg,
    joined_band,
    names_arg,
    number_arg,
    output_arg,
    positive_float,
    positive_int,
)
from .design_parser import add_contributions_option, add_plan_command
from .import_parser import add_import_command
from .season_parser import add_season_commands

PROG = "reach-cal"
#: The most Monte-Carlo refits ``apply --vna-accuracy`` makes (64 is typical).
MAX_VNA_DRAWS = 10_000

#: Each command's help (first line) and description.
DESCRIPTIONS = {
    "simulate": "Write a simulated run with the validation source ``ant`` and the truth.",
    "solve": "Solve a run for the noise-wave parameters and write the solution.",
    "apply": """Calibrate a source of a run with a solution.

An archive of runs (each antenna cycle, as observe calibrated it) is recalibrated with a
new solution by reach-cal recalibrate SOLUTION RUNS... -o DIR.""",
    "summary": "Print a solution's parameters and evidence, and its distance to the floor.",
    "validate": """Validate a run: each calibrator held out of the solve, calibrated as a source.

Columns (K): RMS of the held-out calibrator's calibrated minus known temperature; the
RMS predicted error, calibration part alone and in full (with the source's radiometer
noise); actual / full predicted; fractions of channels inside the 68% and 95%
predictive intervals; the orders of the model each solve used (an average's heaviest).
A refused solve prints its reason; errors far from their prediction are warned about.""",
    "report": """Write a solution's figures (PNG, optionally one PDF) and summary (Markdown, HTML).

With --run (or a receiver's run file as SOLUTION.h5) the report adds each source's
residual against its noise, the distance to the noise floor, the reflections, Dicke
powers, flagged channels, thermocouples, the run's checks and alarms.""",
}


def _draws_arg(text: str) -> int:
    """``--vna-accuracy``: 0 (none) or 2-:data:`MAX_VNA_DRAWS` refits (argparse type)."""
    draws = number_arg(int, 0, MAX_VNA_DRAWS)(text)
    if draws == 1:
        raise argparse.ArgumentTypeError("expected 0 (none) or at least 2 draws, got '1'")
    return draws


def _version() -> str:
    """The installed project's version (the same as reach-run's)."""
    from importlib import metadata

    try:
        return metadata.version("reach-receiver")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


class _Version(argparse.Action):
    """``--version`` on standard output, the version read only when it is asked for.

    importlib.metadata's email parser would otherwise cost every command's start.
    """

    def __call__(self, parser: argparse.ArgumentParser, *_: object) -> None:
        print(f"{parser.prog} {_version()}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The ``reach-cal`` argument parser."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Simulate, solve, apply and summarise REACH noise-wave calibrations.",
        epilog="Exit status: 0 success, 2 error (message on stderr).",
    )
    parser.add_argument("--version", action=_Version, nargs=0,
                        help="show program's version number and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str) -> argparse.ArgumentParser:
        return add_command(sub, name, f".{name}:cmd_{name}", DESCRIPTIONS[name])

    sim = command("simulate")
    sim.add_argument(
        "-o", "--output", type=output_arg, required=True, help="run file to write (HDF5)"
    )
    sim.add_argument(
        "--seed", type=count_arg, default=0, help="noise seed, an integer >= 0 (default 0)"
    )
    sim.add_argument(
        "--integration-s",
        type=positive_float,
        default=600.0,
        help="integration per Dicke position, s (default 600)",
    )
    sim.add_argument(
        "--channel-width-hz",
        type=positive_float,
        default=ITPM_CHANNEL_WIDTH_HZ,
        help="channel width, Hz (default the iTPM's 12207.03 Hz: 32768 channels over 400 MHz)",
    )
    sim.add_argument(
        "--band",
        type=band_arg,
        default=(50.0, 130.0),
        metavar="LO,HI",
        help="band in MHz, as solve takes it (default 50,130; the older LO HI still works)",
    )
    sim.add_argument(
        "--calibrators",
        type=names_arg,
        default=REACH_CALIBRATORS,
        help=f"comma-separated calibrators (default REACH's twelve: {','.join(REACH_CALIBRATORS)})",
    )
    sim.add_argument(
        "--vna-sigma",
        type=number_arg(float, 0.0, 1.0),
        default=0.0,
        help="sd of the noise on each measured reflection coefficient, linear units 0-1 "
        "(default 0: exact reflections)",
    )

    solve = command("solve")
    solve.add_argument("run", help="run file (HDF5)")
    solve.add_argument(
        "-o", "--output", type=output_arg, required=True, help="solution file to write (HDF5)"
    )
    add_solver_options(solve)
    add_correction_options(solve)
    add_contributions_option(solve)

    apply = command("apply")
    apply.add_argument("solution", help="solution file (HDF5)")
    apply.add_argument("run", help="run file holding the source (HDF5)")
    apply.add_argument(
        "--source", default="ant",
        help="source of the run to calibrate, a non-calibrator or a calibrator (default ant)",
    )
    apply.add_argument(
        "-o", "--output", type=output_arg,
        help="calibrated spectrum to write (HDF5; default: none)",
    )
    apply.add_argument(
        "--csv", type=output_arg, help="calibrated spectrum to write (CSV; default: none)"
    )
    apply.add_argument(
        "--vna-accuracy", type=_draws_arg, default=0, metavar="DRAWS",
        help="add the VNA's data-sheet accuracy (thesis table 2.3) as a systematic error, "
        "from DRAWS Monte-Carlo refits (64 is typical; 0, the default, leaves it out)",
    )
    apply.add_argument(
        "--vna-correlation-mhz", type=positive_float, default=DEFAULT_CORRELATION_HZ / 1e6,
        help="correlation length of that error over frequency (default %(default)g MHz)",
    )
    apply.add_argument(
        "--seed", type=count_arg, default=0, help="seed of the Monte-Carlo draws (default 0)"
    )

    summary = command("summary")
    summary.add_argument("solution", help="solution file (HDF5)")
    summary.add_argument(
        "--run",
        help="run file (HDF5): also report the noise floor and error of --source (default: none)",
    )
    summary.add_argument(
        "--source",
        help="source of --run (default: the run's non-calibrator source, e.g. ant; a run "
        "without one, such as an import, gets each calibrator's in-sample residual)",
    )
    summary.add_argument(
        "--top", type=positive_int, default=5, help="evidence-table rows to show (>= 1, default 5)"
    )
    add_import_command(sub)
    add_season_commands(sub)
    add_plan_command(sub)

    validate = command("validate")
    validate.add_argument("run", help="run file (HDF5)")
    validate.add_argument(
        "--leave-one-out",
        action="store_true",
        help="solve without each calibrator in turn and calibrate it (required)",
    )
    add_solver_options(validate)
    validate.add_argument(
        "-o", "--output", type=output_arg, help="report to write, .json or .csv (default: none)"
    )

    report = command("report")
    report.add_argument("solution", help="solution file, or a receiver run file (HDF5)")
    report.add_argument(
        "--run",
        help="run file the solution calibrates (HDF5; default: none, or SOLUTION.h5 itself if "
        "it is a receiver's run file); adds the sources, leave-one-out (one solve per "
        "calibrator) and the run's figures",
    )
    report.add_argument("-o", "--output", required=True, help="directory to write (created)")
    report.add_argument(
        "--pdf", action="store_true", help="also write all figures to report.pdf (default: off)"
    )
    report.add_argument(
        "--no-leave-one-out", action="store_true",
        help="with --run, leave out the leave-one-out residuals (default: computed, one solve "
        "per calibrator with the solution's method and orders)",
    )
    return parser


def what_to_do(err: BaseException) -> str:
    """The command-line way out of a refusal whose message names none (empty if it does).

    The engine's messages say what is wrong and, for its Python callers, what to change;
    a message that already names an option (``--...``) is left alone. An undetermined
    parameter (``identifiability.UndeterminedError``, read by its ``parameter``
    attribute: this module imports no engine) and an unconstrained model get the options
    that change the calibrators or the model.
    """
    message = str(err)
    if "--" in message or not isinstance(err, IllPosedError):
        return ""
    parameter = getattr(err, "parameter", None)
    if parameter == "NS":
        return (
            "what to do: solve with calibrators at different temperatures seen through low "
            "reflection (--calibrators: keep the hot and an ambient load), or fewer terms "
            "(--max-orders, --orders)"
        )
    if parameter is not None:
        return (
            f"what to do: add reflective calibrators (open, short) to determine T_{parameter} "
            "(--calibrators), or fix fewer terms (--orders)"
        )
    if "at least 5 calibrators" in message:
        return "what to do: --method radiometric (polynomials) solves fewer calibrators"
    return (
        "what to do: lower the orders (--max-orders or --orders n_unc,n_cos,n_sin,n_NS,n_L), "
        "or use more calibrators (--calibrators; default all)"
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``reach-cal``; return the exit status (0 success, 2 error)."""
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["simulate"]:
        argv = joined_band(argv)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) and usage errors (2)
        return exc.code if isinstance(exc.code, int) else 2
    module, name = args.target.split(":")
    try:
        command = getattr(importlib.import_module(module, __package__), name)
        return int(command(args))
    except BrokenPipeError:  # the reader (`| head`) stopped reading: nothing to report
        with contextlib.suppress(OSError, ValueError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # as a shell reports SIGPIPE
    except (CalibrationError, OSError) as err:
        print(f"{PROG}: error: {err}", file=sys.stderr)
        hint = what_to_do(err)
        if hint:
            print(f"{PROG}: {hint}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
