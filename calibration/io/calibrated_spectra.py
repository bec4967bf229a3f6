"""The calibrated antenna spectra of a receiver's run file, with their error's parts.

A receiver's run file (``format = "reach-receiver-run"``, ``reach_receiver/store/merge.py``)
keeps every measurement under ``/measurements/NNNNNN_<kind>_<name>``. The observe step
stores each calibrated cycle as a ``calibrated`` measurement::

    frequencies (Hz), mean, std (K), flags (1), std_calibration, std_radiometer (K)
    attrs handover (JSON: {"cycles": {source: [dicke number]}, "s11": {name: number}})

and after its cycles the night's flags, a ``check`` ``rfi_night_<source>`` (``flags``
``(cycle, channel)``, attr details' ``spectra`` naming the rows), ORed in here.

``std_calibration`` is the solution's error: one draw of the noise-wave posterior,
shared by every spectrum that solution calibrates (thesis eq. 3.41's ``x^T Cov(c) x``);
``std_radiometer`` the cycle's own radiometer noise (the radiometer equation through
eq. 3.27), independent between cycles; the rest of ``std`` (in quadrature) is the S11s'
trace noise, shared by the cycles calibrated with the same sweeps. The solution used is
the latest ``solution`` measurement before the spectrum (the run's ``run.solution``); it is
known across runs by a digest of its stored posterior. The spectrum's time is the mean
time stamp of its Dicke cycle's source position (``dicke`` measurement ``source/timestamps``)
and its LST that time's apparent sidereal time
(:func:`calibration.core.sidereal.apparent_lst_h`) at the site of ``/run/site``.

:func:`read_calibrated_spectra` reads one run file and nothing else: a pure function of
the file, which a season maps over its runs.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from typing import Any

import h5py
import numpy as np
import yaml
from numpy.typing import NDArray

from ..core.errors import FileFormatError, InvalidDataError
from ..core.sidereal import apparent_lst_h
from .hdf5_io import RECEIVER_RUN_FORMAT, PathLike, attr_text

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

__all__ = [
    "RunSpectra", "Site", "SolutionRecord", "open_run_file", "read_calibrated_spectra",
]


@dataclass(frozen=True)
class Site:
    """Where the spectra were taken: the site file's ``site`` section."""

    name: str
    longitude_deg: float
    latitude_deg: float


@dataclass(frozen=True)
class SolutionRecord:
    """A solution that calibrated spectra: its digest, run file and measurement."""

    digest: str
    run: str
    measurement: str
    timestamp: float
    method: str


@dataclass(frozen=True)
class RunSpectra:
    """The calibrated spectra of one run, ``(n_spectra, n_channels)`` arrays in K.

    ``solution[i]`` indexes :attr:`solutions`; ``sweeps[i]`` names the S11 sweeps spectrum
    ``i`` was calibrated with (run file and measurement numbers): spectra of one name
    share their trace-noise error.
    """

    path: str
    run_name: str
    site: Site
    freq_hz: FloatArray
    names: tuple[str, ...]
    mean: FloatArray
    std_radiometer: FloatArray
    std_calibration: FloatArray
    std_reflection: FloatArray
    flags: BoolArray
    time_s: FloatArray
    integration_s: FloatArray
    lst_h: FloatArray
    solution: NDArray[np.int64]
    solutions: tuple[SolutionRecord, ...]
    sweeps: tuple[str, ...]


def solution_digest(group: h5py.Group) -> str:
    """SHA-1 of every dataset's name and bytes in a solution group (its identity)."""
    digest = hashlib.sha1(usedforsecurity=False)

    def add(name: str, item: Any) -> None:
        if isinstance(item, h5py.Dataset):
            digest.update(name.encode())
            digest.update(np.ascontiguousarray(item[()]).tobytes())

    group.visititems(add)
    return digest.hexdigest()[:16]


def read_site(f: h5py.File, path: str) -> Site:
    """The site a run file records (its ``run/site`` YAML): name, longitude, latitude.

    :class:`~calibration.core.errors.FileFormatError` names ``path`` where it is missing
    or malformed.
    """
    try:
        document = yaml.safe_load(attr_text(f["run/site"][()])) or {}
        place = document["site"]
        return Site(
            str(place.get("name", "unnamed site")),
            float(place["longitude_deg"]),
            float(place["latitude_deg"]),
        )
    except (KeyError, TypeError, ValueError, yaml.YAMLError) as err:
        raise FileFormatError(
            f"{path}: no site longitude_deg/latitude_deg in /run/site ({err}); the LSTs need them"
        ) from err


def _source_times(dicke: h5py.Group) -> tuple[float, float]:
    """Mean time stamp (s) and integration (s) of a Dicke cycle's source position."""
    source = dicke["source"]
    stamps = np.asarray(source["timestamps"][()], dtype=float)
    integration = float(source.attrs.get("integration_s", 0.0))
    n = int(source.attrs.get("n_spectra", max(stamps.size, 1)))
    return float(np.mean(stamps)), integration * max(n, 1)


def read_calibrated_spectra(path: PathLike) -> RunSpectra:
    """Every calibrated spectrum of a receiver's run file with its error's parts.

    Raises :class:`~calibration.core.errors.InvalidDataError` (a run without calibrated
    spectra, or spectra without their error's parts) or
    :class:`~calibration.core.errors.FileFormatError` (not a receiver's run file).
    """
    where = os.fspath(path)
    with open_run_file(where) as f:
        return _read(f, where)


def open_run_file(path: str) -> h5py.File:
    """``path`` open for reading, checked to be a receiver's run file.

    :class:`~calibration.core.errors.InvalidDataError` if there is no such file,
    :class:`~calibration.core.errors.FileFormatError` if it is not HDF5 or not a run file.
    """
    if not os.path.isfile(path):
        raise InvalidDataError(f"{path}: no such run file")
    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise FileFormatError(f"{path}: not an HDF5 run file ({err})") from err
    fmt = attr_text(f.attrs.get("format", ""))
    if fmt != RECEIVER_RUN_FORMAT or "measurements" not in f:
        f.close()
        raise FileFormatError(
            f"{path}: not a receiver's run file (format {fmt!r}); a season reads the "
            "run.h5 files reach-run writes"
        )
    return f


def _read(f: h5py.File, where: str) -> RunSpectra:
    groups = sorted(f["measurements"].values(), key=lambda g: int(g.attrs["sequence"]))
    by_number = {int(g.attrs["sequence"]): g for g in groups}
    solutions: list[SolutionRecord] = []
    rows: list[dict[str, Any]] = []
    for g in groups:
        kind = attr_text(g.attrs["kind"])
        if kind == "solution" and "solution" in g:
            solutions.append(SolutionRecord(
                solution_digest(g["solution"]), where, g.name.rsplit("/", 1)[-1],
                float(g.attrs["timestamp"]), attr_text(g["solution"].attrs.get("method", "")),
            ))
        elif kind == "calibrated":
            rows.append(spectrum_row(g, by_number, where, len(solutions) - 1))
        elif kind == "check" and attr_text(g.attrs["name"]).startswith("rfi_night_"):
            _night_flags(g, rows)
    if not rows:
        raise InvalidDataError(
            f"{where}: no calibrated spectra (observe calibrates its cycles once the run has "
            "a solution); leave this run out of the season"
        )
    freq = rows[0]["freq"]
    for row in rows[1:]:
        if row["freq"].shape != freq.shape or not np.allclose(row["freq"], freq, rtol=1e-9):
            raise InvalidDataError(f"{where}: calibrated spectra on different frequency grids")
    site = read_site(f, where)
    times = np.array([r["time"] for r in rows])

    def stack(key: str) -> FloatArray:
        return np.asarray(np.stack([r[key] for r in rows]), dtype=float)

    return RunSpectra(
        path=where,
        run_name=attr_text(f.attrs.get("name", os.path.basename(os.path.dirname(where)))),
        site=site,
        freq_hz=freq,
        names=tuple(r["name"] for r in rows),
        mean=stack("mean"),
        std_radiometer=stack("std_radiometer"),
        std_calibration=stack("std_calibration"),
        std_reflection=stack("std_reflection"),
        flags=np.stack([r["flags"] for r in rows]),
        time_s=times,
        integration_s=np.array([r["integration"] for r in rows]),
        lst_h=apparent_lst_h(times, site.longitude_deg),
        solution=np.array([r["solution"] for r in rows], dtype=np.int64),
        solutions=tuple(solutions),
        sweeps=tuple(r["sweeps"] for r in rows),
    )


def _night_flags(g: h5py.Group, rows: list[dict[str, Any]]) -> None:
    """OR a night's flags (observe's ``rfi_night_<source>`` check) into the spectra it names."""
    names = json.loads(attr_text(g.attrs.get("details", "{}"))).get("spectra", [])
    if "flags" not in g or not names:
        return
    flags = np.asarray(g["flags"][()], dtype=bool)
    latest = {row["name"]: row for row in rows}  # the latest of a name: the one flagged
    for name, row_flags in zip(names, flags, strict=False):
        row = latest.get(name)
        if row is not None and row["flags"].shape == row_flags.shape:
            row["flags"] = row["flags"] | row_flags


def spectrum_row(
    g: h5py.Group, by_number: dict[int, h5py.Group], where: str, solution: int
) -> dict[str, Any]:
    """One calibrated measurement as plain arrays, with its time and solution."""
    name = f"{where}:{g.name}"
    missing = [k for k in ("std_radiometer", "std_calibration") if k not in g]
    if missing or "handover" not in g.attrs:
        raise InvalidDataError(
            f"{name}: no {', '.join(missing) or 'handover'} (a run file older than the season): "
            "its error cannot be split into radiometer and calibration parts; leave it out"
        )
    if solution < 0:
        raise InvalidDataError(f"{name}: no solution stored before this calibrated spectrum")
    handover = json.loads(attr_text(g.attrs["handover"]))
    cycles = [n for numbers in handover.get("cycles", {}).values() for n in numbers]
    if len(cycles) != 1 or int(cycles[0]) not in by_number:
        raise InvalidDataError(f"{name}: its hand-over names no single Dicke cycle {cycles}")
    time, integration = _source_times(by_number[int(cycles[0])])
    mean = np.asarray(g["mean"][()], dtype=float)
    std = np.asarray(g["std"][()], dtype=float)
    radiometer = np.asarray(g["std_radiometer"][()], dtype=float)
    calibration = np.asarray(g["std_calibration"][()], dtype=float)
    reflection = np.sqrt(np.maximum(std**2 - radiometer**2 - calibration**2, 0.0))
    flags = np.asarray(g["flags"][()], dtype=bool)
    flags |= ~(np.isfinite(mean) & np.isfinite(std) & (radiometer > 0))
    sweeps = ",".join(f"{k}={v}" for k, v in sorted(handover.get("s11", {}).items()))
    return {
        "name": attr_text(g.attrs["name"]), "freq": np.asarray(g["frequencies"][()], dtype=float),
        "mean": mean, "std_radiometer": radiometer, "std_calibration": calibration,
        "std_reflection": reflection, "flags": flags, "time": time,
        "integration": integration, "solution": solution, "sweeps": f"{where}:{sweeps}",
    }
