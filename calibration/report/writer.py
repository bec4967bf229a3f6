"""A calibration's report: its figures and a one-page summary of the numbers.

:func:`write_report` reads a solution (a solution file, or a receiver's run file holding
one under ``/calibration/solution``) and optionally the run it calibrates, and writes
into a directory:

* one PNG per figure of :mod:`calibration.report.figures` (and with ``pdf=True`` all of them in
  ``report.pdf``): the noise-wave parameters with their bands, the evidence over orders,
  and with a run the calibrated sources, reflections, Dicke powers, flagged channels and
  thermocouples, and for an adaptive calibration its predicted error against time;
* ``summary.md`` and ``summary.html``: the model used (the average's heaviest model,
  its weight and size, :mod:`calibration.report.model_used`; the evidence-best single model and
  the leading averaged models with their weights beside it), every warning of the
  solution (``metadata["warnings"]``) and of its leave-one-out, the noise scale, each
  source's residual against its noise, the distance of each non-calibrator (the antenna)
  to the radiometer noise floor (:mod:`calibration.solve.noise_floor`), predicted and, for a
  simulated run, actual (else said to hold only if the model is right), the share of its
  calibration variance that is the choice of model
  (:attr:`~calibration.solve.solution.CalibratedSpectrum.model_choice_share`); the checks
  (prior-dominated parameters, orders at the search's ceiling, the run's own checks,
  alarms and events) and the software versions.

The calibrators' residuals are in-sample (the solution was fitted to them): a ratio of
residual to predicted noise near 1 says the noise model is right, not that the
calibration generalises. With ``leave_one_out`` (``reach-cal report --run``'s default)
each calibrator is also held out of the solve and calibrated by the others
(:mod:`calibration.report.loo`): a table of actual against predicted beside the
in-sample residuals, and the figure ``leave_one_out.png``. A run of an import
(``power_spectra = placeholder``) has no measured Dicke powers: ``dicke.png`` says so and
draws ``Q`` alone.

A per-channel solution (``least-squares``, ``bayesian``: :mod:`calibration.solve.solvers`) has
no orders to compare: its report leaves out the evidence figure and says so in the
summary, which gives its band-averaged parameters with their per-channel errors and,
for the Bayesian solver, the summed log evidence; its floor is the per-channel one
(:func:`calibration.solve.noise_floor.channel_noise_floor`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import metadata as importlib_metadata
from pathlib import Path

import h5py
import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from ..io.hdf5_io import (
    PLACEHOLDER_POWERS,
    RECEIVER_RUN_FORMAT,
    PathLike,
    read_run,
    read_truth,
    run_power_spectra,
    software_version,
)
from ..io.run_records import (
    ADAPTIVE_DECISION,
    RunRecords,
    adaptive_decisions,
    file_software,
    read_run_records,
)
from ..io.solution_file import read_solution, read_solution_group
from ..model.data import CalibrationData, SourceData
from ..model.noise_waves import PARAMETERS, design_terms, source_temperature
from ..model.simulate import ReceiverTruth
from ..solve.per_frequency import ChannelSolution
from ..solve.solution import CalibratedSpectrum
from ..solve.solvers import AnySolution, method_name, solution_noise_floor
from . import figures
from .loo import ReportLeaveOneOut, report_leave_one_out
from .model_used import model_used_line, warning_lines
from .parts import NO_TRUTH, loo_figure, loo_section
from .render import Section, render_html, render_markdown

FloatArray = NDArray[np.float64]

__all__ = ["Report", "ReportInputs", "load_inputs", "summary_sections", "write_report"]

#: The receiver run file's solution group.
RUN_SOLUTION = "calibration/solution"
#: Libraries whose versions the summary lists.
LIBRARIES = ("numpy", "scipy", "h5py", "matplotlib")


@dataclass(frozen=True)
class ReportInputs:
    """A solution and, optionally, the run it calibrates with everything the run records."""

    solution: AnySolution
    solution_path: str
    solution_software: str
    run_path: str | None = None
    data: CalibrationData | None = None
    others: Mapping[str, SourceData] = field(default_factory=dict)
    truth: ReceiverTruth | None = None
    records: RunRecords = field(default_factory=RunRecords)
    #: The run's spectra are an import's stand-ins (``power_spectra = placeholder``).
    placeholder_powers: bool = False


def _read_solution(path: PathLike) -> tuple[AnySolution, str, bool]:
    """The solution, the writing software, and whether ``path`` is a receiver run file."""
    with h5py.File(path, "r") as f:
        software = file_software(f)
        is_run = f.attrs.get("format") in (RECEIVER_RUN_FORMAT, RECEIVER_RUN_FORMAT.encode())
        if is_run and RUN_SOLUTION in f:
            return read_solution_group(f[RUN_SOLUTION], path), software, True
    return read_solution(path), software, False


def load_inputs(solution_path: PathLike, run_path: PathLike | None = None) -> ReportInputs:
    """Read a solution and its run; a receiver run file is both unless ``run_path`` is given."""
    solution, software, is_run = _read_solution(solution_path)
    run = run_path if run_path is not None else (solution_path if is_run else None)
    if run is None:
        return ReportInputs(solution, str(solution_path), software)
    data, others = read_run(run)
    return ReportInputs(
        solution,
        str(solution_path),
        software,
        str(run),
        data,
        others,
        read_truth(run),
        read_run_records(run),
        run_power_spectra(run) == PLACEHOLDER_POWERS,
    )


@dataclass(frozen=True)
class Calibrated:
    """Every source of the run calibrated, with the known temperatures of those that have one."""

    spectra: Mapping[str, CalibratedSpectrum]
    references: Mapping[str, FloatArray]


def calibrate_run(inputs: ReportInputs) -> Calibrated:
    """Calibrate every source of the run (calibrators first) with the solution."""
    data = inputs.data
    if data is None:
        return Calibrated({}, {})
    sources = {**data.sources, **inputs.others}
    spectra = {
        name: inputs.solution.calibrate(
            data.freq_hz, data.gamma_rec, src,
            data.channel_width_hz, data.gamma_rec_std,
        )
        for name, src in sources.items()
    }
    references = {
        name: np.asarray(src.temperature_k, dtype=float)
        for name, src in sources.items()
        if src.temperature_k is not None
    }
    return Calibrated(spectra, references)


def _rms(values: FloatArray) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def _mk(kelvin: float) -> str:
    return f"{kelvin * 1e3:.4g}"


#: The summary's note where a per-channel solution's report has no evidence figure.
NO_EVIDENCE_FIGURE = (
    "not drawn: a per-channel solution has no polynomial orders whose evidence to compare"
)


def _channel_rows(inputs: ReportInputs, solution: ChannelSolution) -> list[tuple[str, ...]]:
    numbers = solution.summary()
    lo, hi = solution.band_hz
    rows: list[tuple[str, ...]] = [
        ("solution file", inputs.solution_path),
        ("run file", inputs.run_path or "none given (--run)"),
        ("method", f"{method_name(solution)} (per channel)"),
        ("band (MHz)", f"{lo / 1e6:.3f}-{hi / 1e6:.3f}"),
        ("channels solved", str(numbers["n_channels"])),
        ("calibrators", f"{len(solution.calibrators)}: {', '.join(solution.calibrators)}"),
    ]
    for name in PARAMETERS:
        mean, std = numbers["band_mean_k"][name], numbers["channel_std_k"][name]
        rows.append((f"T_{name} band mean +- per-channel std (K)", f"{mean:.6g} +- {std:.3g}"))
    if numbers["log_evidence"] is not None:
        rows.append(("log evidence, sum over channels (nats)", f"{numbers['log_evidence']:.6f}"))
    rows.append(("evidence figure", NO_EVIDENCE_FIGURE))
    return rows


def _solution_rows(inputs: ReportInputs) -> list[tuple[str, ...]]:
    if isinstance(inputs.solution, ChannelSolution):
        return _channel_rows(inputs, inputs.solution)
    solution, post, basis = inputs.solution, inputs.solution.posterior, inputs.solution.basis
    var = post.noise_variance
    if solution.measurement_model == "homoscedastic":
        noise = ("noise sigma (K, homoscedastic)", f"{np.sqrt(var):.6g}")
    else:
        noise = ("noise scale s^2 (1 = radiometer equation exact)", f"{var:.6g}")
    return [
        ("solution file", inputs.solution_path),
        ("run file", inputs.run_path or "none given (--run)"),
        ("method", solution.method),
        ("basis", basis.kind),
        ("band (MHz)", f"{basis.f_lo_hz / 1e6:.3f}-{basis.f_hi_hz / 1e6:.3f}"),
        ("calibrators", f"{len(solution.calibrators)}: {', '.join(solution.calibrators)}"),
        ("model used, orders (unc, cos, sin, NS, L)", model_used_line(solution)),
        ("evidence-best single model", ", ".join(map(str, solution.best_orders))),
        ("averaged models (orders weight)", solution.models_line(limit=6) or "none (single model)"),
        ("posterior layout orders", ", ".join(map(str, solution.orders))),
        ("log evidence (nats)", f"{post.log_evidence:.6f}"),
        noise,
        ("chi2 per row", f"{post.chi2 / post.n_rows:.6g}"),
        ("posterior dof", f"{post.dof:.6g}"),
        ("models evaluated", str(len(solution.evidence_table))),
    ]


def _check_rows(inputs: ReportInputs) -> list[tuple[str, ...]]:
    meta, records = inputs.solution.metadata, inputs.records
    dominated = meta.get("prior_dominated") or {}
    ceiling = meta.get("orders_at_ceiling") or []
    rows: list[tuple[str, ...]] = [
        (
            "prior-dominated parameters",
            ", ".join(f"T_{p} ({r:.0%} of prior width)" for p, r in dominated.items()) or "none",
        ),
        (
            "orders at the search ceiling",
            f"{', '.join(ceiling)} (limits {meta.get('order_limits')})" if ceiling else "none",
        ),
        ("models skipped by the search", str(len(meta.get("skipped_models") or []))),
    ]
    if inputs.run_path is None:
        return rows
    status = records.status + (f" ({records.reason})" if records.reason else "")
    rows.append(("run status", status or "not recorded"))
    for check in records.checks:
        if check.name != ADAPTIVE_DECISION:  # drawn in adaptive.png, summed up below
            rows.append((f"run check: {check.name}", "passed" if check.passed else "FAILED"))
    decisions = adaptive_decisions(records)
    if decisions:
        last = decisions[-1]
        rows.append(("adaptive calibration", (
            f"{len(decisions)} decisions, {float(last['predicted_mk']):.3g} mK predicted after "
            f"{float(last['elapsed_s']) / 3600:.2f} h (stop: {last.get('stop_reason')})"
        )))
    alarms = [f"{key}: {worst} ({n} readings)" for key, (worst, n) in records.alarms.items()]
    rows.append(("alarms during the run", "; ".join(alarms) or "none"))
    events = [f"{kind}: {message}" for _, kind, message in records.events]
    rows.append(("events", "; ".join(events) or "none"))
    return rows


def _source_rows(calibrated: Calibrated) -> list[tuple[str, ...]]:
    rows: list[tuple[str, ...]] = []
    for name, spectrum in calibrated.spectra.items():
        reference = calibrated.references.get(name)
        if reference is None:
            continue
        residual = _rms(spectrum.mean - reference)
        rows.append(
            (
                name,
                _mk(residual),
                _mk(_rms(spectrum.std_measurement)),
                _mk(_rms(spectrum.std_calibration)),
                f"{residual / _rms(spectrum.std):.4f}",
            )
        )
    return rows


def _floor_rows(inputs: ReportInputs, calibrated: Calibrated) -> list[tuple[str, ...]]:
    data, solution = inputs.data, inputs.solution
    if data is None:
        return []
    used = [n for n in solution.calibrators if n in data.sources]
    cal_data = data.subset(used) if used and len(used) == len(solution.calibrators) else data
    rows: list[tuple[str, ...]] = []
    for name, source in inputs.others.items():
        floor = solution_noise_floor(solution, cal_data, source, own_reflection=False).rms
        predicted = _rms(calibrated.spectra[name].std_calibration)
        actual, actual_distance = "not simulated", NO_TRUTH
        if inputs.truth is not None:
            true_t = source_temperature(
                inputs.truth.theta(data.freq_hz), design_terms(source.gamma, data.gamma_rec),
                source.q,
            )
            error = _rms(calibrated.spectra[name].mean - true_t)
            actual, actual_distance = _mk(error), f"{error / floor:.4f}"
        share = calibrated.spectra[name].model_choice_share
        rows.append(
            (name, _mk(floor), _mk(predicted), f"{share:.3f}", f"{predicted / floor:.4f}",
             actual, actual_distance)
        )
    return rows


def _software_rows(inputs: ReportInputs) -> list[tuple[str, ...]]:
    rows: list[tuple[str, ...]] = [("this report", software_version())]
    rows += [(lib, importlib_metadata.version(lib)) for lib in LIBRARIES]
    rows.append(("solution file written by", inputs.solution_software or "not recorded"))
    if inputs.run_path is not None:
        rows.append(("run file written by", inputs.records.software or "not recorded"))
    return rows


def _warning_rows(
    inputs: ReportInputs, loo: ReportLeaveOneOut | None
) -> list[tuple[str, ...]]:
    sentences = [line.removeprefix("warning: ") for line in warning_lines(inputs.solution.metadata)]
    if loo is not None:
        sentences += [s for s in loo.report.warnings() if s not in sentences]
    return [(s,) for s in sentences] or [("none",)]


def summary_sections(
    inputs: ReportInputs, calibrated: Calibrated, loo: ReportLeaveOneOut | None = None
) -> list[Section]:
    """The summary's sections, each a table (:mod:`calibration.report.render`)."""
    sections = [
        Section("Solution", ("quantity", "value"), _solution_rows(inputs)),
        Section("Warnings", ("warning",), _warning_rows(inputs, loo)),
        Section("Checks", ("check", "result"), _check_rows(inputs)),
    ]
    if inputs.data is None:
        sections.append(
            Section("Sources", ("note",), [("no run given: residuals and the floor need --run",)])
        )
    else:
        sections.append(
            Section(
                "Sources against their known temperatures (RMS over channels, in-sample)",
                ("source", "residual (mK)", "radiometer noise (mK)", "calibration sigma (mK)",
                 "residual / predicted"),
                _source_rows(calibrated),
            )
        )
        sections.append(
            Section(
                "Distance to the radiometer noise floor (RMS over channels)",
                ("source", "floor (mK)", "predicted calibration sigma (mK)",
                 "choice of model (share of that variance)",
                 "distance (predicted / floor)", "actual error vs truth (mK)",
                 "actual distance (actual / floor)"),
                _floor_rows(inputs, calibrated),
            )
        )
        sections.append(loo_section(loo, calibrated))
    sections.append(Section("Software", ("component", "version"), _software_rows(inputs)))
    return sections


def figure_builders(
    inputs: ReportInputs, calibrated: Calibrated, loo: ReportLeaveOneOut | None = None
) -> dict[str, Callable[[], Figure]]:
    """The report's figures by file stem, each built when called (one at a time in memory)."""
    truth = inputs.truth.parameters if inputs.truth is not None else None
    solution = inputs.solution
    builders: dict[str, Callable[[], Figure]] = {
        "parameters": lambda: figures.noise_wave_parameters(
            solution, truth=truth, data=inputs.data
        ),
    }
    if not isinstance(solution, ChannelSolution):  # no orders: NO_EVIDENCE_FIGURE
        builders["evidence"] = lambda: figures.evidence_landscape(solution)
    data = inputs.data
    if data is None:
        return builders
    flags = {name: value for name, value in inputs.records.flags.items()} or None
    builders.update(
        {
            "sources": lambda: figures.calibrated_sources(
                calibrated.spectra, calibrated.references
            ),
            "reflections": lambda: figures.reflections(data, inputs.others),
            "dicke": lambda: figures.dicke_powers(
                data, inputs.others, placeholder=inputs.placeholder_powers
            ),
            "flags": lambda: figures.flagged_channels(data.freq_hz, flags),
            "temperatures": lambda: figures.temperatures(inputs.records.temperature_log),
        }
    )
    if loo is not None:
        builders["leave_one_out"] = lambda: loo_figure(loo, calibrated)
    decisions = adaptive_decisions(inputs.records)
    if decisions:
        builders["adaptive"] = lambda: figures.adaptive_course(decisions)
    return builders


@dataclass(frozen=True)
class Report:
    """What :func:`write_report` wrote."""

    directory: Path
    figures: tuple[Path, ...]
    markdown: Path
    html: Path
    pdf: Path | None


def write_report(
    solution_path: PathLike,
    out_dir: PathLike,
    run_path: PathLike | None = None,
    pdf: bool = False,
    leave_one_out: bool = False,
) -> Report:
    """Write the figures and the summary of a solution (and its run) into ``out_dir``.

    With a run and ``leave_one_out``, each calibrator is also held out of the solve
    (:mod:`calibration.report.loo`: one solve per calibrator; ``reach-cal report`` asks
    for it, the receiver's report after each run does not, to keep its time).
    """
    inputs = load_inputs(solution_path, run_path)
    calibrated = calibrate_run(inputs)
    loo = None
    if leave_one_out and inputs.data is not None:
        loo = report_leave_one_out(inputs.solution, inputs.data)
    directory = Path(out_dir)
    directory.mkdir(parents=True, exist_ok=True)
    pngs: list[Path] = []
    pdf_path = directory / "report.pdf" if pdf else None
    pages = None
    if pdf_path is not None:  # the PDF backend's import costs 0.1-0.2 s: only when asked
        from matplotlib.backends.backend_pdf import PdfPages

        pages = PdfPages(pdf_path)
    with pages if pages is not None else contextlib.nullcontext():
        for stem, build in figure_builders(inputs, calibrated, loo).items():
            fig = build()
            pngs.append(figures.save_png(fig, directory / f"{stem}.png"))
            if pages is not None:
                pages.savefig(fig)
    sections = summary_sections(inputs, calibrated, loo)
    names = [p.name for p in pngs]
    title = f"Calibration report: {Path(inputs.solution_path).name}"
    markdown = directory / "summary.md"
    markdown.write_text(render_markdown(title, sections, names), encoding="utf-8")
    html = directory / "summary.html"
    html.write_text(render_html(title, sections, names), encoding="utf-8")
    return Report(directory, tuple(pngs), markdown, html, pdf_path)

