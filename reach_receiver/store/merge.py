"""Merge a run directory's part files into one self-describing ``run.h5``.

The merged file (root attributes ``format = "reach-receiver-run"``, ``format_version``,
``software`` (JSON: reach-receiver, numpy, h5py, python), ``status``, ``reason``,
``name``, ``metadata`` (JSON, the engine's run metadata))::

    /run/                         schedule_<i> (text, attr path), site (YAML), metadata (JSON)
    /measurements/NNNNNN_<kind>_<name>/   every measurement as written (measurements docstring)
    /observation_data/            the REACH / engine layout (calibration.io.hdf5_io), chosen
        frequencies               and written by the hand-over (:mod:`.handover`):
        {src}_spectra, {src}_load_spectra, {src}_ns_spectra
                                  input 0, band channels; (n,) for one Dicke cycle,
                                  (n_cycles, n) for several; integration_s_* per row
        {src}_timestamps          mean time of each position, (3,) or (n_cycles, 3)
        {src}_s11, lna_s11        latest calibrated S11, cubic splines on Re and Im
    /observation_metadata/        attrs channel_width_hz, band_hz, sources, calibrators,
                                  handover (JSON: what was used, by measurement number)
        temperatures/{src}        mean over the cycles, K (calibrators)
        temperature_log/          timestamps, values (degC), attr channels
    /calibration/solution         hard link to the latest solution
    /calibration/calibrated/{name}   hard link to the latest calibrated spectrum of name
    /checks/NNN_<name>            hard links to the checks, in order
    /events/                      timestamps, kinds, messages

The engine layout holds what the run's latest calibration used (its recorded hand-over),
so that ``reach-cal solve run.h5`` reproduces that solution; a run without a calibration
gets the hand-over's rule applied to all its measurements. Every measurement, used or
not, stays in ``/measurements``; what was left out is named in the ``warnings``
attribute of ``/observation_data``.

Merging is atomic (:func:`~reach_receiver.store.parts.atomic_h5`) and idempotent: the
parts are deleted only after ``run.h5`` replaced its predecessor (a disk too full for
the merged file is a :class:`reach_receiver.disk.DiskFull` that leaves every part in place), and a
new merge takes the union of the measurements already in ``run.h5`` and the parts still
present, so a merge killed (or refused) at any point can simply be run again.
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

from calibration.core.errors import FileFormatError
from calibration.io.hdf5_io import RECEIVER_RUN_FORMAT
from reach_receiver.frontend.layout import NOISE_SOURCE_MODEL

from .handover import HandOver, select, write_layout
from .parts import (
    FORMAT_VERSION,
    PARTS_DIR,
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
            "noise_source_model": NOISE_SOURCE_MODEL,
        }
        with atomic_h5(target, attrs, f"the merged run file ({target.name})") as f:
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


def _str_array(values: list[str]) -> np.ndarray:
    return np.array(values, dtype=h5py.string_dtype())


def _derived(f: Any) -> None:
    """Build the engine layout, ``/calibration``, ``/checks`` and ``/events``."""
    groups = [f["measurements"][k] for k in sorted(f["measurements"])]
    by_kind: dict[str, list[Any]] = {}
    for g in groups:
        by_kind.setdefault(as_str(g.attrs["kind"]), []).append(g)
    numbered = {int(g.attrs["sequence"]): g for g in groups}
    solutions = [g for g in by_kind.get("solution", []) if "handover" in g.attrs]
    if solutions:
        handover = HandOver.from_json(as_str(solutions[-1].attrs["handover"]))
    else:
        run = f["run"]
        band = tuple(float(v) for v in run.attrs["band_hz"])
        handover = select(numbered, (band[0], band[1]), float(run.attrs["channel_width_hz"]))
    write_layout(f, numbered, handover)
    warnings = list(handover.warnings)
    _temperature_log(f["observation_metadata"], by_kind.get("temperatures", []), warnings)
    f["observation_data"].attrs["warnings"] = _str_array(warnings)
    for text in warnings:
        log.warning("run layout: %s", text)
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
