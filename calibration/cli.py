"""``reach-cal``: simulate, solve, apply and summarise noise-wave calibrations.

::

    reach-cal simulate -o RUN.h5 [--seed N] [--integration-s S] [--channel-width-hz B]
                       [--band LO HI] [--calibrators a,b,...] [--vna-sigma X]
    reach-cal solve RUN.h5 -o SOLUTION.h5 [--method radiometric|thesis|least-squares|bayesian]
                    [--orders n_unc,n_cos,n_sin,n_NS,n_L | --max-orders ...] [--calibrators ...]
                    [--band LO,HI] [--mask-band LO,HI] [--rfi] [--smooth-s11 P]
                    [--check-consistency | --exclude-inconsistent [N]]  (cli_corrections)
    reach-cal apply SOLUTION.h5 RUN.h5 [--source ant] [-o OUT.h5] [--csv OUT.csv]
                    [--vna-accuracy DRAWS [--vna-correlation-mhz C] [--seed N]]
    reach-cal summary SOLUTION.h5 [--run RUN.h5 --source ant]
    reach-cal import edges DIR -o RUN.h5 --temperatures amb=K,...  (calibration.cli_import)
    reach-cal import vna DIR -o OUT_DIR --devices a,b,...
    reach-cal validate RUN.h5 --leave-one-out [...]  (calibration.cli_validate)
    reach-cal report SOLUTION.h5 [--run RUN.h5] -o DIR [--pdf]  (calibration.cli_report)

Files are those of :mod:`calibration.hdf5_io`. No command writes over one of its inputs or
a file holding measurements (:mod:`calibration.cli_files`); every numeric option is
range-checked as it is parsed (:func:`calibration.cli_args.number_arg`); ``apply`` refuses
a run on another channel grid than its solution's. Errors an operator can act on (unreadable or
malformed files, unusable data, an unsolvable model) print ``reach-cal: error: <message>``
on stderr without a traceback and exit with status 2, as do usage errors; success is 0.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .cli_args import (
    ORDER_NAMES,
    Command,
    add_command,
    add_solver_options,
    count_arg,
    names_arg,
    number_arg,
    output_arg,
    positive_float,
    positive_int,
    solver_from_args,
)
from .cli_corrections import add_correction_options, corrected_solve, noise_source_line
from .cli_files import check_outputs
from .cli_import import add_import_command
from .cli_report import add_report_command
from .cli_validate import add_validate_command
from .data import CalibrationData, SourceData
from .errors import CalibrationError, InvalidDataError
from .hdf5_io import read_run, read_truth, write_run
from .identifiability import caution_lines, model_choice_line
from .noise_waves import PARAMETERS, design_terms, source_temperature
from .per_frequency import ChannelSolution
from .polynomial_model import coefficient_slices
from .simulate import ITPM_CHANNEL_WIDTH_HZ, REACH_CALIBRATORS, SimulationConfig, simulate_run
from .solution import CalibratedSpectrum, Solution, check_grid, grid_metadata
from .solution_file import read_solution, write_calibrated, write_solution
from .solvers import AnySolution, band_hz, method_name, refit, solution_noise_floor
from .vna_systematics import DEFAULT_CORRELATION_HZ, reflection_systematics

PROG = "reach-cal"
#: The most channels ``simulate`` makes: the iTPM's 32768 over its whole band, twice.
MAX_SIM_CHANNELS = 65536
#: The most Monte-Carlo refits ``apply --vna-accuracy`` makes (64 is typical).
MAX_VNA_DRAWS = 10_000


def _rms(values: NDArray[np.float64]) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def _mk(kelvin: float) -> str:
    return f"{kelvin * 1e3:.3f} mK"


def _pick_source(
    data: CalibrationData, extra: dict[str, SourceData], name: str, run: str
) -> SourceData:
    """The named source of a run: a non-calibrator (e.g. ``ant``) or a calibrator."""
    source = extra.get(name) or data.sources.get(name)
    if source is None:
        have = ", ".join([*extra, *data.sources])
        raise InvalidDataError(f"{run} has no source {name!r} (it has: {have})")
    return source


def _check_band(solution: AnySolution, data: CalibrationData, run: str) -> None:
    """Refuse to extrapolate the solution's polynomials (or channels) outside its band."""
    lo, hi = band_hz(solution)
    tol = 1e-9 * hi
    if data.freq_hz[0] < lo - tol or data.freq_hz[-1] > hi + tol:
        raise InvalidDataError(
            f"{run} covers {data.freq_hz[0] / 1e6:.3f}-{data.freq_hz[-1] / 1e6:.3f} MHz, "
            f"outside the solution's band {lo / 1e6:.3f}-{hi / 1e6:.3f} MHz"
        )


def _calibrate(
    solution: AnySolution, run: str, name: str
) -> tuple[CalibrationData, SourceData, CalibratedSpectrum]:
    """Read ``run`` and calibrate its source ``name`` with ``solution``."""
    data, extra = read_run(run)
    source = _pick_source(data, extra, name, run)
    _check_band(solution, data, run)
    check_grid(solution.metadata, data.freq_hz, data.channel_width_hz, run)
    spectrum = solution.calibrate(
        data.freq_hz, data.gamma_rec, source,
        data.channel_width_hz, data.gamma_rec_std,
    )
    return data, source, spectrum


def cmd_simulate(args: argparse.Namespace) -> int:
    """Write a simulated run with the validation source ``ant`` and the truth."""
    unknown = [n for n in args.calibrators if n not in REACH_CALIBRATORS]
    if unknown:
        known = ", ".join(REACH_CALIBRATORS)
        raise InvalidDataError(f"unknown calibrators {unknown}; REACH has: {known}")
    check_outputs({"-o": (args.output, "run")}, [], remakes="simulation")
    lo, hi = args.band
    if not 0 < lo < hi:
        raise InvalidDataError(f"--band needs 0 < LO < HI (MHz), got {lo:g} {hi:g}")
    channels = (hi - lo) * 1e6 / args.channel_width_hz
    if not 1 <= channels <= MAX_SIM_CHANNELS:
        raise InvalidDataError(
            f"--channel-width-hz {args.channel_width_hz:g} makes {channels:.3g} channel "
            f"intervals over {lo:g}-{hi:g} MHz: give between 1 and {MAX_SIM_CHANNELS}"
        )
    config = SimulationConfig(
        f_lo_hz=lo * 1e6,
        f_hi_hz=hi * 1e6,
        channel_width_hz=args.channel_width_hz,
        integration_s=args.integration_s,
        calibrators=args.calibrators,
        vna_sigma=args.vna_sigma,
    )
    run = simulate_run(config, rng=args.seed)
    write_run(
        args.output,
        run.data,
        {run.validation.name: run.validation},
        attrs={"simulation_seed": args.seed},
        truth=run.truth,
    )
    print(
        f"wrote {args.output}: {len(run.data.names)} calibrators + {run.validation.name!r}, "
        f"{run.data.n_channels} channels, {lo:g}-{hi:g} MHz, seed {args.seed}"
    )
    return 0


def cmd_solve(args: argparse.Namespace) -> int:
    """Solve a run for the noise-wave parameters and write the solution."""
    check_outputs({"-o": (args.output, "solution")}, [args.run])
    data, _ = read_run(args.run)
    if args.calibrators:
        data = data.subset(args.calibrators)
    solve = solver_from_args(args)
    start = time.perf_counter()
    data, solution, prepared = corrected_solve(data, args, solve)
    elapsed = time.perf_counter() - start
    solution = replace(
        solution,
        metadata={
            **solution.metadata, **prepared, **grid_metadata(data.freq_hz, data.channel_width_hz),
            "run_file": str(args.run), "solve_time_s": elapsed,
        },
    )
    write_solution(args.output, solution)
    print(
        f"solved {args.run} ({args.method}, {len(data.names)} calibrators, "
        f"{data.n_channels} channels) in {elapsed:.2f} s"
    )
    if isinstance(solution, Solution):
        post = solution.posterior
        how = "fixed" if args.orders else f"best of {len(solution.evidence_table)} by evidence"
        print(f"orders ({ORDER_NAMES}): {', '.join(map(str, solution.best_orders))} ({how})")
        if solution.models_line():
            print(f"averaged over models (orders, weight): {solution.models_line()}")
        for line in caution_lines(solution):
            print(line)
        print(f"log evidence: {post.log_evidence:.3f}")
        print(_noise_line(solution))
    else:
        for line in channel_lines(solution):
            print(line)
    print(noise_source_line(solution, data.freq_hz))
    print(f"wrote {args.output}")
    return 0


def channel_lines(solution: ChannelSolution) -> list[str]:
    """A per-channel solution in numbers: each parameter's band average +- its channel std."""
    summary = solution.summary()
    lines = [
        f"per-channel solution ({method_name(solution)} solver, thesis "
        f"{'4.7' if solution.method == 'least_squares' else '4.8'}): "
        f"{summary['n_channels']} channels solved independently",
        "parameters (K): band mean +- per-channel std (RMS over channels; "
        "uncorrelated between channels)",
    ]
    for name in PARAMETERS:
        mean, std = summary["band_mean_k"][name], summary["channel_std_k"][name]
        lines.append(f"  {name:>3}: {mean:.6g} +- {std:.3g}")
    if summary["log_evidence"] is not None:
        lines.append(
            f"log evidence (sum over channels, eq. 4.22, uniform prior of unit volume): "
            f"{summary['log_evidence']:.3f}"
        )
    if not solution.finite_covariance:
        lines.append("errors undefined: exactly 5 calibrators leave no residual (least squares)")
    return lines


def _noise_line(solution: Solution) -> str:
    var = solution.posterior.noise_variance
    if solution.measurement_model == "homoscedastic":
        return f"noise sigma: {np.sqrt(var):.6g} K (homoscedastic, on the calibrator temperatures)"
    return f"noise scale s^2: {var:.4f} (s = {np.sqrt(var):.4f}; 1 = radiometer equation exact)"


def cmd_apply(args: argparse.Namespace) -> int:
    """Calibrate a source of a run with a solution."""
    check_outputs(
        {"-o": (args.output, "calibrated"), "--csv": (args.csv, "text")},
        [args.solution, args.run],
    )
    solution = read_solution(args.solution)
    data, source, spectrum = _calibrate(solution, args.run, args.source)
    systematics = None
    if args.vna_accuracy:
        systematics = reflection_systematics(
            data, {args.source: source}, refit(solution), args.seed, args.vna_accuracy,
            correlation_hz=args.vna_correlation_mhz * 1e6,
        )
        spectrum = spectrum.with_systematics(systematics.deviations[args.source])
    if args.output:
        files = {"solution_file": str(args.solution), "run_file": str(args.run)}
        write_calibrated(args.output, spectrum, args.source, attrs=files)
    if args.csv:
        _write_csv(Path(args.csv), spectrum)
    print(
        f"calibrated {args.source!r}: {spectrum.freq_hz.size} channels, "
        f"mean temperature {np.mean(spectrum.mean):.3f} K"
    )
    print(
        f"RMS std: total {_mk(_rms(spectrum.std))}, calibration "
        f"{_mk(_rms(spectrum.std_calibration))}, measurement {_mk(_rms(spectrum.std_measurement))}"
        + (f", VNA systematic {_mk(_rms(spectrum.std_systematic))}" if systematics else "")
    )
    if systematics:
        print(f"VNA systematic: {systematics.describe()}")
    choice = model_choice_line(spectrum.model_choice_share, args.source)
    if choice:
        print(choice)
    for path in (args.output, args.csv):
        if path:
            print(f"wrote {path}")
    return 0


def _write_csv(path: Path, spectrum: CalibratedSpectrum) -> None:
    """Write the calibrated spectrum as CSV (atomically: temporary file, then rename)."""
    table = np.column_stack(
        [
            spectrum.freq_hz,
            spectrum.mean,
            spectrum.std,
            spectrum.std_calibration,
            spectrum.std_measurement,
            spectrum.std_systematic,
        ]
    )
    tmp = path.with_name(f".{path.name}.tmp")
    header = "freq_hz,mean_k,std_k,std_calibration_k,std_measurement_k,std_systematic_k"
    np.savetxt(tmp, table, delimiter=",", header=header, comments="", fmt="%.10g")
    os.replace(tmp, path)


def cmd_summary(args: argparse.Namespace) -> int:
    """Print a solution's parameters and evidence, and its distance to the noise floor."""
    solution = read_solution(args.solution)
    if isinstance(solution, ChannelSolution):
        lo, hi = solution.band_hz
        print(f"solution {args.solution}: {method_name(solution)} solver, per channel on "
              f"{lo / 1e6:.3f}-{hi / 1e6:.3f} MHz")
        print(f"calibrators ({len(solution.calibrators)}): {', '.join(solution.calibrators)}")
        for line in channel_lines(solution):
            print(line)
        print(noise_source_line(solution))
        if args.run:
            _floor_summary(solution, args.run, args.source)
        return 0
    post, basis = solution.posterior, solution.basis
    print(
        f"solution {args.solution}: {solution.method} solver, {basis.kind} basis on "
        f"{basis.f_lo_hz / 1e6:.3f}-{basis.f_hi_hz / 1e6:.3f} MHz"
    )
    print(f"calibrators ({len(solution.calibrators)}): {', '.join(solution.calibrators)}")
    print(f"orders ({ORDER_NAMES}): {', '.join(map(str, solution.best_orders))}")
    if solution.models_line():
        print(f"averaged over models (orders, weight): {solution.models_line()}")
        print(f"posterior layout (the models' envelope): {solution.orders}")
    for line in caution_lines(solution):
        print(line)
    at_ceiling = solution.metadata.get("orders_at_ceiling") or []
    if at_ceiling:
        print(
            f"warning: {', '.join(at_ceiling)} reached the order ceiling "
            f"{solution.metadata.get('order_limits')}: the data want more terms than were "
            "searched (unmodelled structure?)"
        )
    print("coefficients (K, posterior mean +- std):")
    std = np.sqrt(np.diag(post.covariance))
    for name, s in zip(PARAMETERS, coefficient_slices(solution.orders), strict=True):
        terms = ", ".join(f"{m:.6g} +- {e:.2g}" for m, e in zip(post.mean[s], std[s], strict=True))
        print(f"  {name:>3}: {terms or '(none)'}")
    print(f"log evidence: {post.log_evidence:.3f} (posterior dof {post.dof:.6g})")
    table = sorted(solution.evidence_table.items(), key=lambda kv: -kv[1])
    best = table[0][1] if table else post.log_evidence
    print(f"evidence table: {len(table)} models, top {min(args.top, len(table))}:")
    for orders, logz in table[: args.top]:
        print(f"  {','.join(map(str, orders)):<14} log Z = {logz:.3f}  (delta {logz - best:.3f})")
    print(_noise_line(solution))
    print(noise_source_line(solution))
    if args.run:
        _floor_summary(solution, args.run, args.source)
    return 0


def _floor_summary(solution: AnySolution, run: str, name: str) -> None:
    """Noise floor, predicted and (for simulations) actual calibration error of a source."""
    data, source, spectrum = _calibrate(solution, run, name)
    used = [n for n in solution.calibrators if n in data.sources]
    cal_data = data.subset(used) if len(used) == len(solution.calibrators) and used else data
    floor = solution_noise_floor(solution, cal_data, source, own_reflection=False).rms
    predicted = _rms(spectrum.std_calibration)
    print(f"source {name!r} of {run} ({len(cal_data.names)} calibrators):")
    model = "per channel" if isinstance(solution, ChannelSolution) else "polynomial"
    print(f"  noise floor RMS (Cramer-Rao, radiometer noise, {model} model): {_mk(floor)}")
    print(f"  predicted calibration std RMS: {_mk(predicted)}")
    print(f"  distance to floor (predicted / floor): {predicted / floor:.3f}")
    truth = read_truth(run)
    if truth is not None:
        terms = design_terms(source.gamma, data.gamma_rec)
        true_t = source_temperature(truth.theta(data.freq_hz), terms, source.q)
        actual = _rms(spectrum.mean - true_t)
        print(
            f"  actual calibration error RMS (solution vs true parameters, same Q): "
            f"{_mk(actual)} ({actual / floor:.3f} x floor)"
        )


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


def build_parser() -> argparse.ArgumentParser:
    """The ``reach-cal`` argument parser."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Simulate, solve, apply and summarise REACH noise-wave calibrations.",
        epilog="Exit status: 0 success, 2 error (message on stderr).",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, func: Command) -> argparse.ArgumentParser:
        return add_command(sub, name, func)

    sim = command("simulate", cmd_simulate)
    sim.add_argument(
        "-o", "--output", type=output_arg, required=True, help="run file to write (HDF5)"
    )
    sim.add_argument("--seed", type=count_arg, default=0, help="noise seed (default 0)")
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
        help="channel width, Hz (default the iTPM's 12207 Hz)",
    )
    sim.add_argument(
        "--band",
        type=positive_float,
        nargs=2,
        default=(50.0, 130.0),
        metavar=("LO", "HI"),
        help="band in MHz (default 50 130)",
    )
    sim.add_argument(
        "--calibrators",
        type=names_arg,
        default=REACH_CALIBRATORS,
        help="comma-separated calibrators (default all twelve)",
    )
    sim.add_argument(
        "--vna-sigma",
        type=number_arg(float, 0.0, 1.0),
        default=0.0,
        help="noise on measured reflection coefficients (default 0)",
    )

    solve = command("solve", cmd_solve)
    solve.add_argument("run", help="run file (HDF5)")
    solve.add_argument(
        "-o", "--output", type=output_arg, required=True, help="solution file to write (HDF5)"
    )
    add_solver_options(solve)
    add_correction_options(solve)

    apply = command("apply", cmd_apply)
    apply.add_argument("solution", help="solution file (HDF5)")
    apply.add_argument("run", help="run file holding the source (HDF5)")
    apply.add_argument("--source", default="ant", help="source to calibrate (default ant)")
    apply.add_argument(
        "-o", "--output", type=output_arg, help="calibrated spectrum to write (HDF5)"
    )
    apply.add_argument("--csv", type=output_arg, help="calibrated spectrum to write (CSV)")
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
        "--seed", type=count_arg, default=0, help="seed of the Monte-Carlo draws"
    )

    summary = command("summary", cmd_summary)
    summary.add_argument("solution", help="solution file (HDF5)")
    summary.add_argument("--run", help="run file: report the noise floor of --source")
    summary.add_argument("--source", default="ant", help="source of --run (default ant)")
    summary.add_argument(
        "--top", type=positive_int, default=5, help="evidence-table rows to show (>= 1)"
    )
    add_import_command(sub)
    add_validate_command(sub)
    add_report_command(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``reach-cal``; return the exit status (0 success, 2 error)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) and usage errors (2)
        return exc.code if isinstance(exc.code, int) else 2
    try:
        return int(args.func(args))
    except (CalibrationError, OSError) as err:
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
