"""Merge a run directory's part files into one self-describing ``run.h5``.

The merged file (root attributes ``format = "reach-receiver-run"``, ``format_version``,
``software`` (JSON: reach-receiver, numpy, h5py, python), ``status``, ``reason``,
``name``, ``metadata`` (JSON, the engine's run metadata))::

    /run/                         schedule_<i> (text, attr path), site (YAML), metadata (JSON)
    /measurements/NNNNNN_<kind>_<name>/   every measurement as written (run_store docstring)
    /observation_data/            the REACH / engine layout (calibration.hdf5_io), built from
        frequencies               channel centres k * channel_width_hz inside band_hz
        {src}_spectra, {src}_load_spectra, {src}_ns_spectra
                                  input 0, band channels; (n,) for one Dicke cycle,
                                  (n_cycles, n) for several; integration_s_* per row
        {src}_timestamps          mean time of each position, (3,) or (n_cycles, 3)
        {src}_s11, lna_s11        latest calibrated S11, cubic splines on Re and Im
    /observation_metadata/        attrs channel_width_hz, sources, calibrators
        temperatures/{src}        mean over the cycles, K (sources with a temperature)
        temperature_log/          timestamps, values (degC), attr channels
    /calibration/solution         hard link to the latest solution
    /calibration/calibrated/{name}   hard link to the latest calibrated spectrum of name
    /checks/NNN_<name>            hard links to the checks, in order
    /events/                      timestamps, kinds, messages

A source whose S11 is missing or does not cover the band (no extrapolation) is left out
of the engine layout and named in the ``warnings`` attribute of ``/observation_data``;
calibrators are the sources with a temperature except the antenna ``ant``.

Merging is atomic (:func:`~reach_receiver.store.parts.atomic_h5`) and idempotent: the
parts are deleted only after ``run.h5`` replaced its predecessor, and a new merge takes
the union of the measurements already in ``run.h5`` and the parts still present, so a
merge killed at any point can simply be run again.
"""

from __future__ import annotations

import contextlib
import json
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from scipy.interpolate import CubicSpline

from calibration.errors import FileFormatError
from calibration.hdf5_io import RECEIVER_RUN_FORMAT

from .parts import (
    FORMAT_VERSION,
    PARTS_DIR,
    UNITS_HZ,
    UNITS_K,
    UNITS_POWER,
    UNITS_REFLECTION,
    UNITS_S,
    UNITS_TEXT,
    StoreError,
    as_str,
    atomic_h5,
    clean_temporaries,
    dataset,
    fsync_directory,
    list_parts,
    safe_name,
)

log = logging.getLogger(__name__)

RUN_FILE = "run.h5"
ANTENNA = "ant"
RECEIVER = "lna"
_POSITIONS = (("source", "spectra"), ("load", "load_spectra"), ("ns", "ns_spectra"))
_PART_ATTRS = ("format", "format_version")


@dataclass(frozen=True)
class Record:
    """One stored record: where it lives (file, group) and what it is."""

    sequence: int
    kind: str
    name: str
    file: Path
    group: str


def group_name(sequence: int, kind: str, name: str) -> str:
    """Name of a measurement's group under ``/measurements``."""
    return f"{sequence:06d}_{kind}_{safe_name(name)}"


def band_channels(width_hz: float, band_hz: tuple[float, float]) -> slice:
    """Channels ``k`` whose centres ``k * width_hz`` lie in ``band_hz`` (1e-9 slack)."""
    first = int(np.ceil(band_hz[0] / width_hz - 1e-9))
    last = int(np.floor(band_hz[1] / width_hz + 1e-9))
    return slice(first, last + 1)


def records_in_file(path: Path) -> list[Record]:
    """The records of a merged run file: description, previous status, measurements."""
    records = [Record(0, "run", "description", path, "/run")]
    try:
        with h5py.File(path, "r") as f:
            status = f.attrs.get("status")
            if status is not None:
                # The status of a previous merge: older than any status part still present.
                records.append(Record(-1, "status", as_str(status), path, "/"))
            for g in f.get("measurements", {}).values():
                seq, kind, name = (g.attrs[k] for k in ("sequence", "kind", "name"))
                records.append(Record(int(seq), as_str(kind), as_str(name), path, g.name))
    except (OSError, KeyError) as err:
        raise FileFormatError(f"{path}: unreadable run file ({err})") from err
    return sorted(records, key=lambda r: r.sequence)


def collect(directory: Path) -> list[Record]:
    """Every record of a run directory by number: ``run.h5``'s, then its parts (parts win)."""
    old = directory / RUN_FILE
    records = {r.sequence: r for r in records_in_file(old)} if old.is_file() else {}
    for part in list_parts(directory):
        try:
            with h5py.File(part.path, "r") as f:
                name = as_str(f.attrs.get("name", part.name))
        except OSError as err:
            raise FileFormatError(f"{part.path}: unreadable part ({err})") from err
        records[part.sequence] = Record(part.sequence, part.kind, name, part.path, "/")
    return [records[k] for k in sorted(records)]


class RecordFiles:
    """Opens the files of records: a merged file stays open, a part only while it is used.

    Part files are opened one at a time, so a night of thousands of parts never runs
    into the limit on open file descriptors.
    """

    def __init__(self) -> None:
        self._open: dict[Path, Any] = {}

    def __enter__(self) -> RecordFiles:
        return self

    def __exit__(self, *exc: object) -> None:
        for f in self._open.values():
            f.close()
        self._open.clear()

    @contextlib.contextmanager
    def group(self, record: Record) -> Iterator[Any]:
        """The record's HDF5 group, open for the duration of the ``with`` block."""
        if record.file.parent.name != PARTS_DIR:
            if record.file not in self._open:
                self._open[record.file] = h5py.File(record.file, "r")
            yield self._open[record.file][record.group]
        else:
            with h5py.File(record.file, "r") as f:
                yield f[record.group]


def _copy_into(src: Any, dst: Any) -> None:
    for key in src:
        src.copy(src[key], dst, name=key)
    dst.attrs.update({k: v for k, v in src.attrs.items() if k not in _PART_ATTRS})


def recorded_status(records: list[Record], files: RecordFiles) -> tuple[str, str] | None:
    """``(status, reason)`` of the latest status record, ``None`` without one."""
    ends = [r for r in records if r.kind == "status"]
    if not ends:
        return None
    with files.group(ends[-1]) as g:
        return as_str(g.attrs["status"]), as_str(g.attrs.get("reason", ""))


def write_run_file(
    target: Path, directory: Path, status: str | None = None, reason: str = ""
) -> list[Record]:
    """Write the merged run of ``directory`` to ``target`` atomically; parts stay."""
    records = collect(directory)
    first = next((r for r in records if r.kind == "run"), None)
    if first is None:
        raise StoreError(f"{directory}: no run description (part 000000 or run.h5)")
    with RecordFiles() as files, files.group(first) as desc:
        end = (status, reason) if status is not None else recorded_status(records, files)
        if end is None:
            end = ("interrupted", "the writer stopped before finishing; merged from its parts")
        meta = as_str(desc["metadata"][()])
        attrs = {
            "format": RECEIVER_RUN_FORMAT,
            "format_version": FORMAT_VERSION,
            "software": as_str(desc.attrs["software"]),
            "status": end[0],
            "reason": end[1],
            "name": as_str(desc.attrs["run_name"]),
            "metadata": meta,
        }
        with atomic_h5(target, attrs) as f:
            _copy_into(desc, f.create_group("run"))
            out = f.create_group("measurements")
            for r in records:
                if r.kind not in ("status", "run"):
                    with files.group(r) as g:
                        _copy_into(g, out.create_group(group_name(r.sequence, r.kind, r.name)))
            _derived(f)
    return records


def merge_run(directory: Path, status: str | None = None, reason: str = "") -> Path:
    """Merge the parts of ``directory`` into ``run.h5`` (idempotent; also recovery).

    Parameters
    ----------
    status, reason
        How the run ended; by default the writer's own record (:meth:`RunStore.finish`),
        or ``"interrupted"`` when the writer was killed. Never merge a run while its
        writer is still adding parts.
    """
    directory = Path(directory)
    target = directory / RUN_FILE
    parts = list_parts(directory)
    if target.is_file() and not parts and status is None:
        clean_temporaries(directory)
        return target
    write_run_file(target, directory, status, reason)
    for part in parts:
        part.path.unlink()
    if parts:
        fsync_directory(parts[0].path.parent)
    clean_temporaries(directory)
    log.info("merged %d parts into %s", len(parts), target)
    return target


def _interpolate(g: Any, freq: np.ndarray) -> np.ndarray | None:
    f_s11, s11 = np.asarray(g["frequencies"][()]), np.asarray(g["s11"][()])
    if f_s11.size < 4 or freq[0] < f_s11[0] or freq[-1] > f_s11[-1]:
        return None
    re = CubicSpline(f_s11, s11.real)(freq)
    im = CubicSpline(f_s11, s11.imag)(freq)
    return np.asarray(re + 1j * im, dtype=complex)


def _str_array(values: list[str]) -> np.ndarray:
    return np.array(values, dtype=h5py.string_dtype())


def _derived(f: Any) -> None:
    """Build the engine layout, ``/calibration``, ``/checks`` and ``/events``."""
    groups = [f["measurements"][k] for k in sorted(f["measurements"])]
    by_kind: dict[str, list[Any]] = {}
    for g in groups:
        by_kind.setdefault(as_str(g.attrs["kind"]), []).append(g)
    _engine_layout(f, by_kind)
    cal = f.create_group("calibration")
    if by_kind.get("solution"):
        cal["solution"] = by_kind["solution"][-1]["solution"]
    calibrated = cal.create_group("calibrated")
    for g in by_kind.get("calibrated", []):
        key = safe_name(as_str(g.attrs["name"]))
        if key in calibrated:
            del calibrated[key]
        calibrated[key] = g
    checks = f.create_group("checks")
    for i, g in enumerate(by_kind.get("check", [])):
        checks[f"{i:03d}_{safe_name(as_str(g.attrs['name']))}"] = g
    events = f.create_group("events")
    found = by_kind.get("event", [])
    dataset(events, "timestamps", [float(g.attrs["timestamp"]) for g in found], UNITS_S)
    dataset(events, "kinds", _str_array([as_str(g.attrs["event"]) for g in found]), UNITS_TEXT)
    dataset(events, "messages", _str_array([as_str(g.attrs["message"]) for g in found]), UNITS_TEXT)


def _engine_layout(f: Any, by_kind: dict[str, list[Any]]) -> None:
    run = f["run"]
    width = float(run.attrs["channel_width_hz"])
    lo, hi = (float(v) for v in run.attrs["band_hz"])
    channels = band_channels(width, (lo, hi))
    freq = width * np.arange(channels.start, channels.stop, dtype=float)
    warnings: list[str] = []
    s11s = {as_str(g.attrs["name"]): g for g in by_kind.get("s11", []) if g.attrs["calibrated"]}
    cycles: dict[str, list[Any]] = {}
    for g in by_kind.get("dicke", []):
        cycles.setdefault(as_str(g.attrs["name"]), []).append(g)
    obs = f.create_group("observation_data")
    dataset(obs, "frequencies", freq, UNITS_HZ)
    meta = f.create_group("observation_metadata")
    temps = meta.create_group("temperatures")

    def gamma_of(name: str) -> np.ndarray | None:
        if name not in s11s:
            warnings.append(f"{name}: no calibrated S11; left out of the engine layout")
            return None
        gamma = _interpolate(s11s[name], freq)
        if gamma is None:
            warnings.append(f"{name}: S11 does not cover {lo:.0f}-{hi:.0f} Hz; left out")
        return gamma

    lna = gamma_of(RECEIVER)
    if lna is not None:
        dataset(obs, "lna_s11", lna, UNITS_REFLECTION, measurement=s11s[RECEIVER].name)
    sources, calibrators = [], []
    for src, rows in cycles.items():
        gamma = gamma_of(src)
        n_ch = rows[0]["source/spectrum"].shape[1]
        if any(g["source/spectrum"].shape[1] != n_ch for g in rows) or n_ch < channels.stop:
            warnings.append(f"{src}: spectra do not cover the band channels; left out")
            continue
        if gamma is None:
            continue
        for position, suffix in _POSITIONS:
            data = np.stack([g[f"{position}/spectrum"][0, channels] for g in rows])
            dataset(obs, f"{src}_{suffix}", data[0] if len(rows) == 1 else data, UNITS_POWER)
        spectra = obs[f"{src}_spectra"]
        for position, _ in _POSITIONS:
            per_row = [float(g[position].attrs["integration_s"]) for g in rows]
            spectra.attrs[f"integration_s_{position}"] = float(np.mean(per_row))
        spectra.attrs["measurements"] = _str_array([g.name for g in rows])
        times = np.array(
            [
                [
                    np.mean(g[f"{p}/timestamps"][()])
                    if g[f"{p}/timestamps"].size
                    else float(g.attrs["timestamp"])
                    for p, _ in _POSITIONS
                ]
                for g in rows
            ]
        )
        dataset(
            obs,
            f"{src}_timestamps",
            times[0] if len(rows) == 1 else times,
            UNITS_S,
            columns=_str_array([p for p, _ in _POSITIONS]),
        )
        dataset(obs, f"{src}_s11", gamma, UNITS_REFLECTION, measurement=s11s[src].name)
        known = [g for g in rows if "temperature" in g]
        if known:
            per_cycle = [float(g["temperature"][()]) for g in known]
            # Each cycle's error is its own; the mean's is the root-sum-square over n.
            stds = [float(g["temperature"].attrs.get("std_k", 0.0)) for g in known]
            dataset(
                temps,
                src,
                float(np.mean(per_cycle)),
                UNITS_K,
                per_cycle_k=per_cycle,
                timestamps=[float(g.attrs["timestamp"]) for g in known],
                std_k=float(np.sqrt(np.sum(np.square(stds))) / len(stds)),
            )
            if src != ANTENNA:
                calibrators.append(src)
        sources.append(src)
    meta.attrs.update(
        channel_width_hz=width, sources=_str_array(sources), calibrators=_str_array(calibrators)
    )
    _temperature_log(meta, by_kind.get("temperatures", []), warnings)
    obs.attrs["warnings"] = _str_array(warnings)
    for text in warnings:
        log.warning("run layout: %s", text)


def _temperature_log(meta: Any, logs: list[Any], warnings: list[str]) -> None:
    if not logs:
        return
    channels = [list(map(as_str, g.attrs["channels"])) for g in logs]
    if any(c != channels[0] for c in channels):
        warnings.append("temperature logs have different channels; see /measurements")
        return
    g = meta.create_group("temperature_log")
    dataset(g, "timestamps", np.concatenate([x["timestamps"][()] for x in logs]), UNITS_S)
    dataset(g, "values", np.concatenate([x["values"][()] for x in logs]), "degC")
    g.attrs["channels"] = _str_array(channels[0])


def description(f: Any) -> dict[str, Any]:
    """The run description of an open part 0 or ``/run`` group, as plain values."""
    files = [as_str(p) for p in np.atleast_1d(f.attrs.get("schedule_files", []))]
    return {
        "name": as_str(f.attrs["run_name"]),
        "schedule_files": tuple((p, as_str(f[f"schedule_{i}"][()])) for i, p in enumerate(files)),
        "site_yaml": as_str(f["site"][()]),
        "metadata": json.loads(as_str(f["metadata"][()])),
        "software": json.loads(as_str(f.attrs["software"])),
        "channel_width_hz": float(f.attrs["channel_width_hz"]),
        "band_hz": tuple(float(v) for v in f.attrs["band_hz"]),
    }
