"""A run's antenna cycles calibrated again with another solution, as the observe step did.

The observe step (``reach_receiver/run/steps/observe.py``) calibrates each Dicke cycle of
the antenna through the run's hand-over: the cycle's three powers on the band's channels
(``k * channel_width_hz`` inside the solution's band), the latest error-corrected S11s of
the source and the receiver (``lna``) splined onto those channels, each sweep's trace
noise beside it; then the solution's calibration (thesis eqs. 3.13-3.27 for ``T_source``
from ``Q``, eq. 3.41 for its predictive), the engine's flagger on the spectrum
(:func:`calibration.checks.rfi.flag_sky`) and, after the step's cycles, the night's
(:func:`calibration.checks.rfi_night.flag_night`). Each stored ``calibrated`` measurement
records in its ``handover`` attribute the cycle and the S11s it used (by measurement
number), so the same inputs are read here from the run file alone and calibrated with a
new solution: :func:`recalibrated_run_bytes`.

The output is a receiver's run file (``format = "reach-receiver-run"``) holding what a
season reads (:mod:`calibration.io.calibrated_spectra`): ``/run`` (the site), the new
solution as measurement 0 (before every spectrum), copies of the Dicke cycles and S11s
used (original numbers, so the hand-overs still name them, and the output can itself be
recalibrated), each ``calibrated`` measurement again under its number and time, and a
``rfi_night_<source>`` check per night of the original. Root attributes
``recalibrated_from`` (the run), ``solution_file`` and ``solution_digest`` say what made it.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from ..checks.rfi import flag_sky
from ..checks.rfi_night import flag_night
from ..core.errors import FileFormatError, InvalidDataError
from ..io.calibrated_spectra import solution_digest
from ..io.hdf5_io import RECEIVER_RUN_FORMAT, attr_text, software_version
from ..io.receiver_grid import band_channels, interpolate_s11
from ..io.solution_file import write_solution_group
from ..model.data import Integration, SourceData, check_source
from ..model.reflection_noise import trace_noise
from ..solve.solution import check_grid
from ..solve.solvers import AnySolution, band_hz

FloatArray = NDArray[np.float64]

__all__ = [
    "CycleInputs",
    "cycle_inputs",
    "recalibrated_run_bytes",
    "run_cycles",
    "write_recalibrated_run",
]

#: The receiver's own reflection among a run's S11s.
RECEIVER = "lna"
#: The Dicke positions and the engine's names for their powers.
POSITIONS = ("source", "load", "ns")
#: The threshold (sigma) of a cycle whose night recorded none: the observe step's default.
DEFAULT_THRESHOLD = 5.0


@dataclass(frozen=True)
class CycleInputs:
    """What one Dicke cycle's calibration takes: the channels, the receiver, the source."""

    freq_hz: FloatArray
    channel_width_hz: float
    gamma_rec: NDArray[np.complex128]
    gamma_rec_std: FloatArray | None
    source: SourceData


def _reflection(g: h5py.Group, freq: FloatArray, where: str) -> tuple[
    NDArray[np.complex128], FloatArray | None
]:
    """An S11 measurement on the channels and its trace noise per channel (or ``None``)."""
    gamma = interpolate_s11(g["frequencies"][()], g["s11"][()], freq)
    if gamma is None:
        raise InvalidDataError(
            f"{where}: S11 {g.name} does not cover {freq[0] / 1e6:.3f}-{freq[-1] / 1e6:.3f} MHz "
            "(the solution's band); calibrate with a solution of the run's band"
        )
    sigma = trace_noise(g["s11"][()])
    return gamma, None if sigma is None else np.full(freq.size, sigma)


def cycle_inputs(
    by_number: Mapping[int, h5py.Group], handover: Mapping[str, Any],
    band: tuple[float, float], where: str,
) -> CycleInputs:
    """The inputs of a ``calibrated`` measurement's cycle (its hand-over) over ``band``."""
    width = float(handover["channel_width_hz"])
    cycles = [(s, int(n)) for s, numbers in handover.get("cycles", {}).items() for n in numbers]
    s11 = {k: int(v) for k, v in handover.get("s11", {}).items()}
    if len(cycles) != 1:
        raise InvalidDataError(f"{where}: its hand-over names no single Dicke cycle {cycles}")
    (name, number), = cycles
    missing = [n for n in (number, s11.get(name), s11.get(RECEIVER)) if n not in by_number]
    if missing:
        raise InvalidDataError(
            f"{where}: the hand-over's measurements {missing} are not in the run "
            f"(its {name!r} cycle and the S11s of {name!r} and {RECEIVER!r})"
        )
    channels = band_channels(width, band)
    freq = width * np.arange(channels.start, channels.stop, dtype=float)
    dicke = by_number[number]
    n_ch = dicke["source/spectrum"].shape[1]
    if channels.stop > n_ch or channels.start < 0:
        raise InvalidDataError(
            f"{where}: the cycle's {n_ch} channels do not cover the solution's band "
            f"{band[0] / 1e6:.3f}-{band[1] / 1e6:.3f} MHz"
        )
    powers = [np.asarray(dicke[f"{p}/spectrum"][0, channels], dtype=float) for p in POSITIONS]
    seconds = [float(dicke[p].attrs["integration_s"]) for p in POSITIONS]
    gamma_rec, rec_std = _reflection(by_number[s11[RECEIVER]], freq, where)
    gamma, gamma_std = _reflection(by_number[s11[name]], freq, where)
    source = SourceData(
        name, gamma, powers[0], powers[1], powers[2], Integration(*seconds), None, None, 0.0,
        gamma_std,
    )
    return CycleInputs(freq, width, gamma_rec, rec_std, check_source(source, freq.size))


@dataclass(frozen=True)
class RunCycles:
    """A run's ``calibrated`` measurements in order, and its nights' flag checks."""

    calibrated: tuple[h5py.Group, ...]
    nights: tuple[h5py.Group, ...]
    by_number: Mapping[int, h5py.Group]


def run_cycles(f: h5py.File, where: str) -> RunCycles:
    """The calibrated measurements of an open receiver's run file (refused without any)."""
    fmt = attr_text(f.attrs.get("format", ""))
    if fmt != RECEIVER_RUN_FORMAT or "measurements" not in f:
        raise FileFormatError(
            f"{where}: not a receiver's run file (format {fmt!r}); recalibrate reads the "
            "run.h5 files reach-run writes"
        )
    groups = sorted(f["measurements"].values(), key=lambda g: int(g.attrs["sequence"]))
    calibrated = tuple(g for g in groups if attr_text(g.attrs["kind"]) == "calibrated")
    nights = tuple(
        g for g in groups
        if attr_text(g.attrs["kind"]) == "check"
        and attr_text(g.attrs["name"]).startswith("rfi_night_")
    )
    if not calibrated:
        raise InvalidDataError(
            f"{where}: no calibrated spectra (observe calibrates its cycles once the run has "
            "a solution); leave this run out"
        )
    return RunCycles(calibrated, nights, {int(g.attrs["sequence"]): g for g in groups})


def check_run(path: str, solution: AnySolution) -> int:
    """Refuse a run the solution cannot recalibrate; its number of calibrated cycles."""
    with _open(path) as f:
        cycles = run_cycles(f, path)
        band = band_hz(solution)
        for g in cycles.calibrated:
            where = f"{path}:{g.name}"
            if "handover" not in g.attrs:
                raise InvalidDataError(f"{where}: no hand-over (a run file older than the season)")
            inputs = cycle_inputs(cycles.by_number, json.loads(attr_text(g.attrs["handover"])),
                                  band, where)
            check_grid(solution.metadata, inputs.freq_hz, inputs.channel_width_hz, path)
        return len(cycles.calibrated)


def _open(path: str) -> h5py.File:
    if not os.path.isfile(path):
        raise InvalidDataError(f"{path}: no such run file")
    try:
        return h5py.File(path, "r")
    except OSError as err:
        raise FileFormatError(f"{path}: not an HDF5 run file ({err})") from err


def _thresholds(nights: tuple[h5py.Group, ...]) -> dict[str, float]:
    """Each spectrum name's flagging threshold, as its night's check recorded it."""
    out: dict[str, float] = {}
    for g in nights:
        details = json.loads(attr_text(g.attrs.get("details", "{}")))
        for name in details.get("spectra", []):
            out[name] = float(details.get("threshold_sigma", DEFAULT_THRESHOLD))
    return out


def _put(g: h5py.Group, name: str, value: Any, units: str) -> None:
    g.create_dataset(name, data=value).attrs["units"] = units


def _measurement(parent: h5py.Group, kind: str, name: str, number: int, time: float) -> Any:
    g = parent.create_group(f"{number:06d}_{kind}_{name}")
    g.attrs.update(kind=kind, name=name, sequence=number, timestamp=time)
    return g


def recalibrated_run_bytes(
    path: str, solution: AnySolution, solution_file: str, solution_time: float,
    intervals: bool = False,
) -> bytes:
    """:func:`write_recalibrated_run`'s file as bytes (built in memory: small runs, tests)."""
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as out:
        write_recalibrated_run(path, out, solution, solution_file, solution_time, intervals)
    return buffer.getvalue()


def write_recalibrated_run(
    path: str, out: h5py.File, solution: AnySolution, solution_file: str,
    solution_time: float, intervals: bool = False,
) -> int:
    """Write into ``out`` the run of ``path``'s cycles calibrated with ``solution`` (module doc).

    ``solution_time`` (Unix s) is the new solution's time stamp, which orders solutions in
    a season. ``intervals`` adds the credible intervals' ends (``lower_68`` ...), as the
    observe step stores them; a season does not read them, and for a model-averaged
    solution their mixture quantiles take most of the time (about 1.5 s a cycle of 6554
    channels against 0.2 s for the rest). One cycle is in memory at a time. Returns the
    number of spectra written.
    """
    band = band_hz(solution)
    with _open(path) as f:
        cycles = run_cycles(f, path)
        thresholds = _thresholds(cycles.nights)
        out.attrs.update(
            format=RECEIVER_RUN_FORMAT, format_version="1.0", software=software_version(),
            name=attr_text(f.attrs.get("name", os.path.basename(os.path.dirname(path)))),
            status="recalibrated", recalibrated_from=os.path.abspath(path),
            solution_file=solution_file,
        )
        if "run" in f:
            f.copy(f["run"], out, name="run")
        measurements = out.create_group("measurements")
        sol = _measurement(measurements, "solution", solution.method, 0, solution_time)
        write_solution_group(sol.create_group("solution"), solution)
        out.attrs["solution_digest"] = solution_digest(sol["solution"])
        copied: set[int] = set()
        by_name: dict[str, tuple[str, FloatArray, NDArray[np.bool_], FloatArray]] = {}
        for g in cycles.calibrated:
            where = f"{path}:{g.name}"
            handover = json.loads(attr_text(g.attrs["handover"]))
            inputs = cycle_inputs(cycles.by_number, handover, band, where)
            check_grid(solution.metadata, inputs.freq_hz, inputs.channel_width_hz, path)
            spectrum = solution.calibrate(
                inputs.freq_hz, inputs.gamma_rec, inputs.source, inputs.channel_width_hz,
                inputs.gamma_rec_std,
            )
            name = attr_text(g.attrs["name"])
            flags = flag_sky(spectrum.mean, thresholds.get(name, DEFAULT_THRESHOLD),
                             inputs.freq_hz)
            number = int(g.attrs["sequence"])
            for used in [n for ns in handover["cycles"].values() for n in ns] + list(
                handover["s11"].values()
            ):
                if int(used) not in copied:
                    f.copy(cycles.by_number[int(used)], measurements)
                    copied.add(int(used))
            new = _measurement(measurements, "calibrated", name, number,
                               float(g.attrs["timestamp"]))
            _put(new, "frequencies", inputs.freq_hz, "Hz")
            _put(new, "mean", spectrum.mean, "K")
            _put(new, "std", spectrum.std, "K")
            _put(new, "flags", flags, "1")
            for key, values in (spectrum.intervals() if intervals else {}).items():
                _put(new, key, np.asarray(values, dtype=float), "K")
            radiometer = spectrum.std_radiometer
            assert radiometer is not None  # both solvers separate it
            _put(new, "std_calibration", spectrum.std_calibration, "K")
            _put(new, "std_radiometer", radiometer, "K")
            new.attrs["handover"] = json.dumps({**handover, "band_hz": list(band)})
            by_name[name] = (new.name, np.asarray(spectrum.mean), flags, inputs.freq_hz)
        for night in cycles.nights:
            _night(measurements, night, by_name)
        return len(cycles.calibrated)


def _night(
    measurements: h5py.Group, night: h5py.Group,
    by_name: Mapping[str, tuple[str, FloatArray, NDArray[np.bool_], FloatArray]],
) -> None:
    """The night's flags of the recalibrated spectra the original check named."""
    details = json.loads(attr_text(night.attrs.get("details", "{}")))
    names = [n for n in details.get("spectra", []) if n in by_name]
    if not names:
        return
    threshold = float(details.get("threshold_sigma", DEFAULT_THRESHOLD))
    freq = by_name[names[0]][3]
    names = [n for n in names if by_name[n][3].shape == freq.shape]
    flags = flag_night(
        np.stack([by_name[n][1] for n in names]), np.stack([by_name[n][2] for n in names]),
        freq, threshold,
    )
    g = _measurement(measurements, "check", attr_text(night.attrs["name"]),
                     int(night.attrs["sequence"]), float(night.attrs["timestamp"]))
    g.attrs.update(passed=True, details=json.dumps(
        {"spectra": names, "threshold_sigma": threshold, **flags.summary()}
    ))
    _put(g, "flags", flags.flags, "1")
