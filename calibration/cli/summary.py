"""``reach-cal summary``: a solution's parameters and evidence, and its distance to the floor."""

from __future__ import annotations

import argparse

import numpy as np

from ..io.hdf5_io import read_run, read_truth
from ..io.solution_file import read_solution
from ..model.data import CalibrationData, SourceData
from ..model.noise_waves import PARAMETERS, design_terms, source_temperature
from ..model.polynomial_model import coefficient_slices
from ..report.model_used import distance_line, model_used_line, warning_lines
from ..solve.identifiability import caution_lines
from ..solve.per_frequency import ChannelSolution
from ..solve.solution import check_grid
from ..solve.solvers import AnySolution, method_name, solution_noise_floor
from .apply import _check_band, calibrate_source, mk, rms
from .args import ORDER_NAMES
from .corrections import noise_source_line
from .solve import channel_lines, noise_line


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
        for line in warning_lines(solution.metadata):
            print(line)
        if args.run:
            _floor_summary(solution, args.run, args.source)
        return 0
    post, basis = solution.posterior, solution.basis
    delays = getattr(basis, "delays_s", ())
    kind = basis.kind + (
        f" + delay terms at {', '.join(f'{d * 1e9:.1f}' for d in delays)} ns" if delays else ""
    )
    print(
        f"solution {args.solution}: {solution.method} solver, {kind} basis on "
        f"{basis.f_lo_hz / 1e6:.3f}-{basis.f_hi_hz / 1e6:.3f} MHz"
    )
    print(f"calibrators ({len(solution.calibrators)}): {', '.join(solution.calibrators)}")
    print(f"model used, orders ({ORDER_NAMES}): {model_used_line(solution)}")
    if solution.models_line():
        print(f"averaged over models (orders, weight): {solution.models_line()}")
        print(f"posterior layout (the models' envelope): {solution.orders}")
    for line in caution_lines(solution):
        print(line)
    for line in warning_lines(solution.metadata):
        print(line)
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
    print(noise_line(solution))
    print(noise_source_line(solution))
    if args.run:
        _floor_summary(solution, args.run, args.source)
    return 0


def default_source(others: dict[str, SourceData]) -> str | None:
    """The source ``summary --run`` reports without ``--source`` (None when there is none).

    The run's first non-calibrator (``ant`` in a simulated or receiver run).
    """
    return next(iter(others), None)


def _floor_summary(solution: AnySolution, run: str, name: str | None) -> None:
    """Noise floor, predicted and (for simulations) actual calibration error of a source.

    ``name`` None: the run's non-calibrator source (:func:`default_source`), or, on a run
    of calibrators alone (an import), each calibrator's in-sample residual.
    """
    data, others = read_run(run)
    if name is None:
        name = default_source(others)
        if name is None:
            _calibrator_summary(solution, data, run)
            return
        print(f"source {name!r}: the run's non-calibrator source (--source picks another)")
    data, source, spectrum = calibrate_source(solution, run, name)
    used = [n for n in solution.calibrators if n in data.sources]
    cal_data = data.subset(used) if len(used) == len(solution.calibrators) and used else data
    floor = solution_noise_floor(solution, cal_data, source, own_reflection=False).rms
    predicted = rms(spectrum.std_calibration)
    print(f"source {name!r} of {run} ({len(cal_data.names)} calibrators):")
    model = "per channel" if isinstance(solution, ChannelSolution) else "polynomial"
    print(f"  noise floor RMS (Cramer-Rao, radiometer noise, {model} model): {mk(floor)}")
    print(f"  predicted calibration std RMS: {mk(predicted)}")
    truth = read_truth(run)
    actual = None
    if truth is not None:
        terms = design_terms(source.gamma, data.gamma_rec)
        true_t = source_temperature(truth.theta(data.freq_hz), terms, source.q)
        actual = rms(spectrum.mean - true_t)
        print(
            f"  actual calibration error RMS (solution vs true parameters, same Q): "
            f"{mk(actual)} ({actual / floor:.3f} x floor)"
        )
    print(f"  {distance_line(predicted, floor, actual)}")
    if name in data.sources and name in solution.calibrators:
        print(f"  note: {name!r} is a calibrator of the solution: its residual is in-sample")


def _calibrator_summary(solution: AnySolution, data: CalibrationData, run: str) -> None:
    """A run without a non-calibrator: each calibrator's floor and in-sample residual."""
    _check_band(solution, data, run)
    check_grid(solution.metadata, data.freq_hz, data.channel_width_hz, run)
    used = [n for n in solution.calibrators if n in data.sources] or list(data.names)
    cal_data = data.subset(used)
    print(
        f"{run} has no non-calibrator source (e.g. an import): its {len(used)} calibrators, "
        "in-sample (the solution was fitted to them; `reach-cal validate RUN "
        "--leave-one-out` holds each out)"
    )
    print(f"  {'calibrator':<12} {'floor':>12} {'predicted':>12} {'residual':>12} {'res/pred':>9}")
    for name in used:
        source = cal_data.sources[name]
        spectrum = solution.calibrate(
            data.freq_hz, data.gamma_rec, source, data.channel_width_hz, data.gamma_rec_std,
        )
        floor = solution_noise_floor(solution, cal_data, source, own_reflection=False).rms
        residual = rms(spectrum.mean - np.asarray(source.temperature_k, dtype=float))
        print(
            f"  {name:<12} {mk(floor):>12} {mk(rms(spectrum.std_calibration)):>12} "
            f"{mk(residual):>12} {residual / rms(spectrum.std):>9.3f}"
        )
    print(
        "  floor and predicted: calibration error RMS; residual: calibrated minus known "
        "temperature RMS; res/pred: residual over the full predicted sd (1 = noise model right)"
    )
