"""What ``reach-cal solve``'s data-preparation and calibrator-consistency options do.

::

    reach-cal solve RUN.h5 -o SOLUTION.h5 [--band LO,HI] [--mask-band LO,HI ...] [--rfi]
                    [--smooth-s11 P] [--check-consistency | --exclude-inconsistent [N]]
                    [--alpha A]

In this order, before the solve: ``--band`` keeps the channels in ``LO-HI`` MHz;
``--mask-band`` drops those in a band of known interference (repeatable;
:func:`calibration.checks.preparation.excision_flags`); ``--rfi`` flags spikes in each
calibrator's three Dicke spectra (:func:`calibration.checks.rfi.calibrator_flags`, 5 sigma) and
drops the channels flagged in any of them from every calibrator, saying how many per source;
``--smooth-s11 P`` replaces every reflection (calibrators' and the receiver's) by the
smoothing spline of factor ``P`` (:func:`calibration.checks.preparation.smooth_reflection`,
frequency in MHz; its kernel width is printed). What was dropped is counted in the
solution's metadata. Then ``--check-consistency`` holds each calibrator out and tests it
against the others (:mod:`calibration.checks.consistency`), and ``--exclude-inconsistent N``
also excludes the calibrator it names and checks again, at most ``N`` times (default 2),
and solves without them. After the solve, :func:`noise_source_line` holds the fitted
``T_NS`` to the noise diode's ENR table (:func:`calibration.model.measurement_uncertainty.
check_noise_source`): PASS or FAIL, also in ``reach-cal summary``; only for a run whose
root attribute ``noise_source_model`` is ``"NC346A"`` (:mod:`calibration.io.hdf5_io`), the
diode the table describes; other runs (EDGES imports) get one line saying why not.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..checks.consistency import check_consistency, exclude_inconsistent
from ..checks.preparation import excision_flags, smooth_reflection, smoothing_width_hz
from ..checks.rfi import calibrator_flags
from ..core.errors import CalibrationError
from ..io.hdf5_io import NC346A, run_noise_source_model
from ..model.data import CalibrationData
from ..model.measurement_uncertainty import check_noise_source
from ..model.noise_waves import INDEX
from ..model.simulate import NC346A_ENR_DB
from ..solve.solvers import AnySolution, band_hz

__all__ = [
    "corrected_solve",
    "noise_source_line",
    "prepare",
]

BoolArray = NDArray[np.bool_]
Solve = Callable[[CalibrationData], AnySolution]


def _keep(data: CalibrationData, keep: BoolArray, what: str) -> CalibrationData:
    return data.select(keep, what)


def prepare(
    data: CalibrationData, args: argparse.Namespace
) -> tuple[CalibrationData, list[str], dict[str, Any]]:
    """Band, masks, RFI and smoothing of ``args`` on ``data``: data, report lines, metadata."""
    lines: list[str] = []
    meta: dict[str, Any] = {}
    if args.band is not None:
        lo, hi = args.band
        n = data.n_channels
        data = data.band(lo * 1e6, hi * 1e6)
        lines.append(f"band {lo:g}-{hi:g} MHz: {data.n_channels} of {n} channels")
        meta["band_mhz"] = [lo, hi]
    if args.mask_band:
        bands = [(lo * 1e6, hi * 1e6) for lo, hi in args.mask_band]
        masked = excision_flags(data.freq_hz, bands)
        data = _keep(data, ~masked, "--mask-band")
        text = ", ".join(f"{lo:g}-{hi:g}" for lo, hi in args.mask_band)
        lines.append(f"masked {text} MHz: {int(np.count_nonzero(masked))} channels dropped")
        meta["masked_bands_mhz"] = [list(b) for b in args.mask_band]
        meta["masked_channels"] = int(np.count_nonzero(masked))
    if args.rfi:
        flagged, counts = calibrator_flags(data)
        n = data.n_channels
        data = _keep(data, ~flagged, "--rfi")
        per_source = ", ".join(f"{k} {v}" for k, v in counts.items())
        lines.append(
            f"RFI: {int(np.count_nonzero(flagged))} of {n} channels flagged and dropped "
            f"(spikes in a load or noise-source spectrum, per calibrator: {per_source})"
        )
        meta["rfi_flagged_channels"] = int(np.count_nonzero(flagged))
        meta["rfi_flagged_by_source"] = counts
    if args.smooth_s11 is not None:
        p = args.smooth_s11
        width = smoothing_width_hz(data.freq_hz, p)

        def smooth(gamma: NDArray[np.complex128]) -> NDArray[np.complex128]:
            return np.asarray(smooth_reflection(data.freq_hz, gamma, p), dtype=complex)

        data = replace(
            data,
            gamma_rec=smooth(data.gamma_rec),
            sources={n: replace(s, gamma=smooth(s.gamma)) for n, s in data.sources.items()},
        )
        lines.append(f"reflections smoothed: factor {p:g}, kernel width {width / 1e3:.3g} kHz")
        meta["smooth_s11"] = p
    return data, lines, meta


def corrected_solve(
    data: CalibrationData, args: argparse.Namespace, solve: Solve
) -> tuple[CalibrationData, AnySolution, dict[str, Any]]:
    """Prepare ``data``, check or exclude calibrators as asked, solve; print what was done.

    Returns the data solved, the solution and metadata to store with it.
    """
    data, lines, meta = prepare(data, args)
    for line in lines:
        print(line)
    if args.check_consistency:
        report = check_consistency(data, solve, args.alpha)
        print("calibrator consistency (each held out of the solve):")
        for line in report.lines():
            print(f"  {line}")
        meta["inconsistent"] = list(report.flagged)
        meta["named_inconsistent"] = None if report.worst is None else report.worst.name
    elif args.exclude_inconsistent is not None:
        result = exclude_inconsistent(data, solve, args.alpha, args.exclude_inconsistent)
        print("calibrator consistency (each held out of the solve), with exclusion:")
        for line in result.lines():
            print(f"  {line}")
        meta["excluded_inconsistent"] = list(result.excluded)
        if result.solution is None:
            raise CalibrationError(f"the calibrators left could not be solved: {result.refused}")
        return data.subset(result.calibrators), result.solution, meta
    return data, solve(data), meta


def noise_source_line(
    solution: AnySolution,
    freq_hz: NDArray[np.float64] | None = None,
    run: str | None = None,
) -> str:
    """The fitted ``T_NS`` against the NC346A's ENR table (thesis fig. 4.20), PASS/FAIL.

    Only when the run (``run``, else the solution's ``run_file``) names its noise source
    ``NC346A``; otherwise one line saying it was not checked and why. ``freq_hz``
    defaults to 201 points over the solution's band; the table covers 30-200 MHz,
    outside which the check is not made.
    """
    run = run or solution.metadata.get("run_file")
    if not run:
        return "noise source: not checked, no run file names its noise source"
    try:
        model = run_noise_source_model(run)
    except (OSError, CalibrationError) as err:
        return f"noise source: not checked, the run {run} is not readable ({err})"
    if model != NC346A:
        said = f"is {model!r}" if model else "is not recorded (e.g. an import)"
        return f"noise source: not checked, the run's noise source {said}, not the {NC346A}"
    f = np.linspace(*band_hz(solution), 201) if freq_hz is None else freq_hz
    lo, hi = min(NC346A_ENR_DB) * 1e6, max(NC346A_ENR_DB) * 1e6
    if f[0] < lo or f[-1] > hi:
        return f"noise source: not checked, the ENR table covers {lo / 1e6:g}-{hi / 1e6:g} MHz"
    fitted = solution.evaluate(f)[INDEX["NS"]]
    sigma = solution.parameter_std(f)[INDEX["NS"]]
    if not np.all(np.isfinite(sigma)):
        return "noise source: not checked, the fitted T_NS has no defined error"
    return str(check_noise_source(fitted, f, sigma))
