"""Read a run back: a merged ``run.h5`` or a run directory that was never merged.

:func:`read_run_file` lists the measurements in order with the run description and
status; arrays are read on demand (:meth:`RunContents.read`), and
:meth:`RunContents.calibration_data` gives what the engine's
:func:`calibration.io.hdf5_io.read_run` returns for the merged file. An unmerged directory
(a run still going, or killed and not yet recovered) is read from its parts without
changing it: its engine view is built in a temporary merged file.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from calibration.core.errors import FileFormatError
from calibration.io.hdf5_io import RECEIVER_RUN_FORMAT, read_run
from calibration.io.solution_file import read_solution_group
from calibration.model.data import CalibrationData, SourceData
from calibration.solve.solvers import AnySolution

from .merge import (
    RUN_FILE,
    Record,
    RecordFiles,
    collect,
    description,
    group_name,
    recorded_status,
    records_in_file,
    write_run_file,
)
from .parts import as_str, list_parts

_SKIP_ATTRS = {"kind", "name", "sequence", "timestamp"}


@dataclass(frozen=True)
class Measurement:
    """One stored measurement: its number, kind, name, time and group in the merged file.

    ``attrs`` holds the group's other attributes, JSON attributes decoded.
    """

    sequence: int
    kind: str
    name: str
    timestamp: float
    group: str
    attrs: Mapping[str, Any]
    file: Path
    location: str


def _value(key: str, value: Any) -> Any:
    if isinstance(value, bytes | str):
        text = as_str(value)
        if key in ("settings", "details", "verification", "switch_state", "counters"):
            return json.loads(text)
        return text
    if isinstance(value, np.ndarray):
        return [as_str(v) for v in value] if value.dtype.kind in "OSU" else value
    return value.item() if isinstance(value, np.generic) else value


def _arrays(group: Any, prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, obj in group.items():
        if isinstance(obj, h5py.Group):
            out.update(_arrays(obj, f"{prefix}{key}/"))
        else:
            value = obj[()]
            out[prefix + key] = as_str(value) if isinstance(value, bytes) else np.asarray(value)
    return out


@dataclass(frozen=True)
class RunContents:
    """A run as stored: description, status and the measurements in order."""

    path: Path
    merged: bool
    name: str
    status: str
    reason: str
    schedule_files: tuple[tuple[str, str], ...]
    site_yaml: str
    metadata: Mapping[str, Any]
    software: Mapping[str, str]
    channel_width_hz: float
    band_hz: tuple[float, float]
    measurements: tuple[Measurement, ...]

    def of_kind(self, kind: str) -> list[Measurement]:
        """The measurements of one kind (``"dicke"``, ``"s11"``...), in order."""
        return [m for m in self.measurements if m.kind == kind]

    def read(self, measurement: Measurement) -> dict[str, Any]:
        """Every dataset of a measurement, keyed by path inside its group (``"ns/spectrum"``)."""
        with h5py.File(measurement.file, "r") as f:
            return _arrays(f[measurement.location])

    def solution(self) -> AnySolution | None:
        """The latest calibration solution of the run (of any solver), if one was made."""
        found = self.of_kind("solution")
        if not found:
            return None
        with h5py.File(found[-1].file, "r") as f:
            return read_solution_group(f[found[-1].location]["solution"], found[-1].file)

    def calibration_data(self) -> tuple[CalibrationData, dict[str, SourceData]]:
        """What :func:`calibration.io.hdf5_io.read_run` returns for the merged run."""
        if self.merged:
            return read_run(self.path)
        with tempfile.TemporaryDirectory(prefix="reach-run-") as tmp:
            target = Path(tmp) / RUN_FILE
            write_run_file(target, self.path)
            return read_run(target)


def _measurement(record: Record, g: Any) -> Measurement:
    attrs = {k: _value(k, v) for k, v in g.attrs.items() if k not in _SKIP_ATTRS}
    attrs.pop("format", None)
    attrs.pop("format_version", None)
    return Measurement(
        record.sequence,
        record.kind,
        record.name,
        float(g.attrs["timestamp"]),
        f"/measurements/{group_name(record.sequence, record.kind, record.name)}",
        attrs,
        record.file,
        record.group,
    )


def read_run_file(path: Path) -> RunContents:
    """Read ``run.h5`` or a run directory (merged or not); the files are not changed."""
    path = Path(path)
    if path.is_dir() and (path / RUN_FILE).is_file() and not list_parts(path):
        path = path / RUN_FILE
    if path.is_dir():
        records = collect(path)
        merged = False
    else:
        if not path.is_file():
            raise FileNotFoundError(2, "no such run file or directory", str(path))
        try:
            with h5py.File(path, "r") as f:
                found = as_str(f.attrs.get("format", ""))
        except OSError as err:
            raise FileFormatError(f"{path}: not a readable HDF5 file ({err})") from err
        if found != RECEIVER_RUN_FORMAT:
            raise FileFormatError(f"{path}: not a {RECEIVER_RUN_FORMAT!r} file")
        records = records_in_file(path)
        merged = True
    desc_record = next((r for r in records if r.kind == "run"), None)
    if desc_record is None:
        raise FileFormatError(f"{path}: no run description")
    with RecordFiles() as files:
        with files.group(desc_record) as g:
            desc = description(g)
        status, reason = recorded_status(records, files) or ("unfinished", "")
        measurements = []
        for r in records:
            if r.kind not in ("run", "status"):
                with files.group(r) as g:
                    measurements.append(_measurement(r, g))
    return RunContents(
        path=path,
        merged=merged,
        status=status,
        reason=reason,
        measurements=tuple(measurements),
        **desc,
    )
