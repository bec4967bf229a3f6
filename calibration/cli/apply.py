"""``reach-cal apply``: a source of a run calibrated with a solution (HDF5 and CSV)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..checks.vna_systematics import reflection_systematics
from ..core.errors import InvalidDataError
from ..io.hdf5_io import read_run
from ..io.solution_file import read_solution, write_calibrated
from ..model.data import CalibrationData, SourceData
from ..solve.identifiability import model_choice_line
from ..solve.solution import CalibratedSpectrum, check_grid
from ..solve.solvers import AnySolution, band_hz, refit
from .files import check_outputs


def rms(values: NDArray[np.float64]) -> float:
    """Root mean square over all elements."""
    return float(np.sqrt(np.mean(np.square(values))))


def mk(kelvin: float) -> str:
    """Kelvin written in millikelvin."""
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


def calibrate_source(
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


def cmd_apply(args: argparse.Namespace) -> int:
    """Calibrate a source of a run with a solution."""
    check_outputs(
        {"-o": (args.output, "calibrated"), "--csv": (args.csv, "text")},
        [args.solution, args.run],
    )
    solution = read_solution(args.solution)
    data, source, spectrum = calibrate_source(solution, args.run, args.source)
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
        f"RMS std: total {mk(rms(spectrum.std))}, calibration "
        f"{mk(rms(spectrum.std_calibration))}, measurement {mk(rms(spectrum.std_measurement))}"
        + (f", VNA systematic {mk(rms(spectrum.std_systematic))}" if systematics else "")
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
