"""``reach-cal solve``: a run's noise-wave parameters, written as a solution file."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..checks.temperature_sanity import check_temperatures
from ..choice.model_fit import OrderChoice
from ..core.errors import InvalidDataError
from ..io.hdf5_io import read_run
from ..io.solution_file import write_solution
from ..model.data import CalibrationData
from ..model.noise_waves import PARAMETERS
from ..report.model_used import model_used_line, warning_lines
from ..solve.identifiability import caution_lines
from ..solve.per_frequency import ChannelSolution
from ..solve.solution import Solution, grid_metadata
from ..solve.solvers import AnySolution, method_name, solver
from .args import ORDER_NAMES
from .corrections import corrected_solve, noise_source_line
from .files import check_outputs


def solver_from_args(args: argparse.Namespace) -> Callable[[CalibrationData], AnySolution]:
    """The solve that :func:`~calibration.cli.args.add_solver_options`'s options ask for.

    Orders, order limits or a basis with a per-channel ``--method`` are refused
    (:func:`calibration.solve.solvers.solver`).
    """
    choice = None
    if args.orders is not None:
        choice = OrderChoice.fixed(args.orders)
    elif args.max_orders is not None:
        if min(args.max_orders) < 1:
            raise InvalidDataError("--max-orders must be >= 1 for every parameter")
        choice = OrderChoice(max_orders=args.max_orders)
    return solver(args.method, choice, args.basis)


def calibrators_of(args: argparse.Namespace) -> CalibrationData:
    """The run's calibrators as ``--calibrators`` and ``--cryogenic`` ask (solve, validate).

    Temperatures that look like Celsius are refused, or noted where ``--cryogenic``.
    """
    data, _ = read_run(args.run)
    if args.calibrators:
        data = data.subset(args.calibrators)
    for line in check_temperatures(data, args.cryogenic):
        print(line)
    return data


def cmd_solve(args: argparse.Namespace) -> int:
    """Solve a run for the noise-wave parameters and write the solution."""
    check_outputs({"-o": (args.output, "solution")}, [args.run])
    contributing = getattr(args, "contributions", False)
    if contributing and args.method != "radiometric":
        raise InvalidDataError("--contributions needs the radiometric solver: --method radiometric")
    data = calibrators_of(args)
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
        print(f"model used, orders ({ORDER_NAMES}): {model_used_line(solution)}")
        if solution.models_line():
            print(f"averaged over models (orders, weight): {solution.models_line()}")
        for line in caution_lines(solution):
            print(line)
        print(f"log evidence: {post.log_evidence:.3f}")
        print(noise_line(solution))
    else:
        for line in channel_lines(solution):
            print(line)
    print(noise_source_line(solution, data.freq_hz))
    for line in warning_lines(solution.metadata):
        print(line)
    if contributing and isinstance(solution, Solution):
        from .design import contribution_lines

        for line in contribution_lines(args, data, solution):
            print(line)
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


def noise_line(solution: Solution) -> str:
    """The fitted noise: a scale on the radiometer equation, or the thesis's sigma."""
    var = solution.posterior.noise_variance
    if solution.measurement_model == "homoscedastic":
        return f"noise sigma: {np.sqrt(var):.6g} K (homoscedastic, on the calibrator temperatures)"
    return f"noise scale s^2: {var:.4f} (s = {np.sqrt(var):.4f}; 1 = radiometer equation exact)"
