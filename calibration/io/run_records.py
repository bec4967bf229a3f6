"""What a receiver's run file records beside the engine's layout, read for reports.

:func:`calibration.io.hdf5_io.read_run` reads the calibration data of a run file; a run file
of the receiver (``format = "reach-receiver-run"``, see ``reach_receiver/store/merge.py``)
also holds, all optional here (a file without them gives empty records)::

    /observation_metadata/temperature_log/{timestamps (s), values (degC)}, attr channels
    /calibration/calibrated/{name}/{frequencies (Hz), flags}   channel flags of a spectrum
    /checks/NNN_<name>          attrs passed, details (JSON); ``adaptive_decision`` checks
                                hold the adaptive calibration step's decisions
                                (:func:`adaptive_decisions`)
    /events/{timestamps, kinds, messages}
    /measurements/*_monitoring_*/{timestamps, series, values, status}, attrs keys, units,
                                status_names: the health readings taken during the run
    root attrs software (JSON of versions, or a plain string), status, reason

This module reads them with h5py alone: the engine does not import the receiver package.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from .hdf5_io import PathLike, attr_text

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

__all__ = [
    "ADAPTIVE_DECISION",
    "Check",
    "RunRecords",
    "TemperatureLog",
    "adaptive_decisions",
    "file_software",
    "read_run_records",
]

#: Health statuses that are not an alarm.
QUIET_STATUSES = ("nominal", "unknown")
#: The name of the checks that hold an adaptive calibration's decisions (one each: the
#: :meth:`calibration.design.adaptive.Decision.as_record` of it, with ``step``, ``target_mk``,
#: ``budget_s``, ``overhead_s`` and ``where``, the schedule line of its step).
ADAPTIVE_DECISION = "adaptive_decision"
#: Event kinds that only mark a schedule's progress.
PROGRESS_EVENTS = ("step",)


@dataclass(frozen=True)
class TemperatureLog:
    """Thermocouple readings: ``values_c`` is ``(n_times, n_channels)`` in degrees Celsius."""

    timestamps_s: FloatArray
    values_c: FloatArray
    channels: tuple[str, ...]


@dataclass(frozen=True)
class Check:
    """A check taken during the run (e.g. the VNA's test load) and its verdict."""

    name: str
    passed: bool
    details: Mapping[str, Any]


@dataclass(frozen=True)
class RunRecords:
    """Everything optional a run file records beside the calibration data."""

    temperature_log: TemperatureLog | None = None
    flags: Mapping[str, tuple[FloatArray, BoolArray]] = field(default_factory=dict)
    checks: tuple[Check, ...] = ()
    events: tuple[tuple[float, str, str], ...] = ()
    alarms: Mapping[str, tuple[str, int]] = field(default_factory=dict)
    software: str = ""
    status: str = ""
    reason: str = ""


def _json(value: Any) -> Any:
    with contextlib.suppress(json.JSONDecodeError, TypeError):
        return json.loads(attr_text(value))
    return attr_text(value)


def file_software(f: Any) -> str:
    """The ``software`` root attribute of an open file, as one line."""
    value = _json(f.attrs.get("software", ""))
    if isinstance(value, dict):
        return ", ".join(f"{k} {v}" for k, v in value.items())
    return str(value)


def _temperature_log(f: Any) -> TemperatureLog | None:
    g = f.get("observation_metadata/temperature_log")
    if not isinstance(g, h5py.Group) or "timestamps" not in g or "values" not in g:
        return None
    times = np.asarray(g["timestamps"][()], dtype=float)
    values = np.asarray(g["values"][()], dtype=float).reshape(times.size, -1)
    channels = tuple(attr_text(c) for c in np.atleast_1d(g.attrs.get("channels", [])))
    if len(channels) != values.shape[1]:
        channels = tuple(f"channel {i}" for i in range(values.shape[1]))
    return TemperatureLog(times, values, channels)


def _flags(f: Any) -> dict[str, tuple[FloatArray, BoolArray]]:
    g = f.get("calibration/calibrated")
    out: dict[str, tuple[FloatArray, BoolArray]] = {}
    for name, item in (g.items() if isinstance(g, h5py.Group) else ()):
        if isinstance(item, h5py.Group) and "flags" in item and "frequencies" in item:
            freq = np.asarray(item["frequencies"][()], dtype=float)
            out[name] = (freq, np.asarray(item["flags"][()], dtype=bool))
    return out


def _checks(f: Any) -> tuple[Check, ...]:
    g = f.get("checks")
    if not isinstance(g, h5py.Group):
        return ()
    return tuple(
        Check(
            attr_text(item.attrs.get("name", key)),
            bool(item.attrs.get("passed", False)),
            _json(item.attrs.get("details", "{}")) or {},
        )
        for key, item in sorted(g.items())
    )


def _events(f: Any) -> tuple[tuple[float, str, str], ...]:
    g = f.get("events")
    if not isinstance(g, h5py.Group) or not {"timestamps", "kinds", "messages"} <= set(g):
        return ()
    rows = zip(g["timestamps"][()], g["kinds"][()], g["messages"][()], strict=True)
    return tuple(
        (float(t), attr_text(k), attr_text(m))
        for t, k, m in rows if attr_text(k) not in PROGRESS_EVENTS
    )


def _alarms(f: Any) -> dict[str, tuple[str, int]]:
    """Per health series, its worst status other than nominal and how many readings had one."""
    g = f.get("measurements")
    out: dict[str, tuple[str, int]] = {}
    for key, item in (g.items() if isinstance(g, h5py.Group) else ()):
        if "_monitoring_" not in key or not {"series", "status"} <= set(item):
            continue
        keys = [attr_text(k) for k in np.atleast_1d(item.attrs.get("keys", []))]
        names = [attr_text(s) for s in np.atleast_1d(item.attrs.get("status_names", []))]
        for series, status in zip(item["series"][()], item["status"][()], strict=True):
            if not (0 <= status < len(names) and 0 <= series < len(keys)):
                continue
            if names[status] in QUIET_STATUSES:
                continue
            worst, count = out.get(keys[series], (names[status], 0))
            worst = max(worst, names[status], key=names.index)
            out[keys[series]] = (worst, count + 1)
    return out


def read_run_records(path: PathLike) -> RunRecords:
    """The optional records of a run file (module docstring); empty ones where absent."""
    with h5py.File(path, "r") as f:
        return RunRecords(
            temperature_log=_temperature_log(f),
            flags=_flags(f),
            checks=_checks(f),
            events=_events(f),
            alarms=_alarms(f),
            software=file_software(f),
            status=attr_text(f.attrs.get("status", "")),
            reason=attr_text(f.attrs.get("reason", "")),
        )


def adaptive_decisions(records: RunRecords) -> list[Mapping[str, Any]]:
    """The adaptive calibration's decisions of a run, in their order (empty without one)."""
    found = [c.details for c in records.checks if c.name == ADAPTIVE_DECISION]
    return sorted(found, key=lambda d: int(d.get("step", 0)))
