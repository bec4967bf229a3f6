"""The writer of a run: one durable part file per measurement, merged at the end.

:class:`RunStore` is what the scheduler's runner holds. Each ``add_*`` writes one part
(:mod:`reach_receiver.store.parts`) and returns only once it is on disk, so a run
killed at any moment (SIGKILL, power cut) loses at most the measurement in progress;
:func:`~reach_receiver.store.merge.merge_run` turns the parts into ``run.h5`` at
:meth:`RunStore.finish`, or afterwards to recover a killed run.

Contents of the measurement kinds (each becomes ``/measurements/NNNNNN_<kind>_<name>``)::

    s11          frequencies (Hz), s11 (complex reflection); attrs calibrated, settings (JSON)
    dicke        {source,load,ns}/spectrum (n_inputs, n_channels; power (arbitrary)),
                 {source,load,ns}/timestamps (s); attrs integration_s, n_spectra,
                 switch_state (JSON), counters (JSON); temperature (K, when known)
    spectrum     spectrum, timestamps; attrs integration_s, switch_state (JSON)
    temperatures timestamps (s), values (n_times, n_channels; degC); attr channels
    monitoring   timestamps (s), series, values, status (one row per health reading);
                 attrs keys, units (per series), status_names
    check        attrs passed, details (JSON); one dataset per array (units from its name)
    solution     solution/ (the engine's solution layout); attr verification (JSON)
    calibrated   frequencies (Hz), mean (K), std (K), flags (1), lower_68, upper_68,
                 lower_95, upper_95 (K; the credible intervals' ends)
    event        attrs event, message

Names of S11 measurements are source names (REACH names) and ``lna`` for the receiver.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.metadata
import logging
import platform
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from calibration.io.hdf5_io import RunLayout
from calibration.io.solution_file import write_solution_group
from calibration.model.data import CalibrationData, SourceData
from calibration.solve.solvers import AnySolution

from .handover import RECEIVER, HandOver, engine_layout, select
from .merge import RUN_FILE, Record, merge_run
from .parts import (
    PARTS_DIR,
    UNITS_C,
    UNITS_HOURS,
    UNITS_HZ,
    UNITS_K,
    UNITS_NONE,
    UNITS_POWER,
    UNITS_REFLECTION,
    UNITS_S,
    StoreError,
    as_str,
    clean_temporaries,
    dataset,
    fsync_directory,
    list_parts,
    make_shared_directory,
    to_json,
    write_part,
)

log = logging.getLogger(__name__)

#: Dicke positions (thesis 2.1.1): the source, the reference load, the noise source.
DICKE_POSITIONS = ("source", "load", "ns")
STATUSES = ("completed", "interrupted", "failed")
#: Attributes a part file writes for itself, not copied from another run's measurement.
_OWN_ATTRS = {"format", "format_version", "kind", "name", "sequence", "timestamp"}
_UNIT_SUFFIXES = (("_hz", UNITS_HZ), ("_k", UNITS_K), ("_c", UNITS_C), ("_s", UNITS_S))


@dataclass(frozen=True)
class EngineView:
    """The run so far as the engine sees it, and what the hand-over chose.

    ``layout`` is ``None`` when there is nothing to show the engine (no LNA S11, or no
    spectra whose S11 covers the band); ``handover.warnings`` then says why.
    """

    layout: RunLayout | None
    handover: HandOver

    @functools.cached_property
    def data(self) -> CalibrationData | None:
        """The calibrators as the engine's run, ``None`` without any."""
        if self.layout is None or not self.layout.calibrators:
            return None
        return self.layout.split()[0]

    @functools.cached_property
    def others(self) -> dict[str, SourceData]:
        """The sources that are not calibrators (the antenna), by name."""
        return {} if self.layout is None else self.layout.others()


def software_versions() -> dict[str, str]:
    """Versions of reach-receiver, numpy, h5py and Python, as stored in every run."""
    try:
        ours = importlib.metadata.version("reach-receiver")
    except importlib.metadata.PackageNotFoundError:
        ours = "not installed"
    return {
        "reach-receiver": ours,
        "numpy": np.__version__,
        "h5py": h5py.__version__,
        "python": platform.python_version(),
    }


def units_for(name: str, value: np.ndarray) -> str:
    """Units of a check's array from its name: ``*_hz``, ``*_k``, ``*_c``, ``*_s``, complex."""
    if np.iscomplexobj(value):
        return UNITS_REFLECTION
    lowered = name.lower()
    if lowered in ("frequencies", "freq"):
        return UNITS_HZ
    if lowered == "timestamps":
        return UNITS_S
    return next((u for suffix, u in _UNIT_SUFFIXES if lowered.endswith(suffix)), UNITS_NONE)


def _per_position(what: str, value: Mapping[str, Any], required: bool = True) -> None:
    keys = set(value)
    if (required and keys != set(DICKE_POSITIONS)) or not keys <= set(DICKE_POSITIONS):
        raise ValueError(f"{what} must be keyed by the Dicke positions {DICKE_POSITIONS}: {keys}")


class RunStore:
    """Writes one run as durable part files in ``directory`` and merges them on finish.

    Parameters
    ----------
    directory
        The run's directory (created by :meth:`open`; must not hold another run).
    name
        Name of the run (e.g. the schedule's name and the start time).
    schedule_files
        ``(path, text)`` of the schedule and every file it includes.
    site_yaml
        The site configuration, verbatim.
    metadata
        Anything else worth keeping (JSON-serialisable); also the engine's run metadata.
    channel_width_hz
        Spectrometer channel width; channel ``k`` is centred on ``k * channel_width_hz``.
    band_hz
        Band of the engine layout: the channels whose centres lie in it.

    Notes
    -----
    Thread-safe: parts are numbered in the order their writes complete.
    """

    def __init__(
        self,
        directory: Path,
        *,
        name: str,
        schedule_files: Sequence[tuple[str, str]],
        site_yaml: str,
        metadata: Mapping[str, Any],
        channel_width_hz: float,
        band_hz: tuple[float, float] = (50e6, 130e6),
    ) -> None:
        if not (np.isfinite(channel_width_hz) and channel_width_hz > 0):
            raise ValueError(f"channel_width_hz must be > 0, got {channel_width_hz}")
        if not 0 <= band_hz[0] < band_hz[1]:
            raise ValueError(f"band_hz must be (low, high) with 0 <= low < high, got {band_hz}")
        self.directory = Path(directory)
        self.name = name
        self._schedule_files = [(str(p), str(t)) for p, t in schedule_files]
        self._site_yaml = site_yaml
        self._metadata = dict(metadata)
        self._channel_width_hz = float(channel_width_hz)
        self._band_hz = (float(band_hz[0]), float(band_hz[1]))
        self._lock = threading.Lock()
        self._next = 0
        self._records: list[Record] = []
        self._state = "new"

    @property
    def channel_width_hz(self) -> float:
        """The spectrometer's channel width (Hz)."""
        return self._channel_width_hz

    @property
    def band_hz(self) -> tuple[float, float]:
        """The run's band: the engine layout's, unless a calibration chose another."""
        return self._band_hz

    @property
    def is_open(self) -> bool:
        """Whether measurements can be added (opened, its end not yet recorded)."""
        return self._state == "open"

    @property
    def finished(self) -> bool:
        """Whether the run's end is recorded (its merge may still have failed)."""
        return self._state == "finished"

    @property
    def run_file(self) -> Path:
        """Where :meth:`finish` writes the merged run."""
        return self.directory / RUN_FILE

    def __enter__(self) -> RunStore:
        self.open()
        return self

    def __exit__(
        self, kind: type[BaseException] | None, err: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._state != "open":
            return
        if kind is None:
            self.finish("completed")
        elif issubclass(kind, KeyboardInterrupt):
            self.finish("interrupted", "Ctrl-C")
        else:
            self.finish("failed", f"{kind.__name__}: {err}")

    def open(self) -> None:
        """Create the directory and write the run-description part (number 0).

        When the description cannot be written (a full disk), the directory is removed
        again and the error raised: no run began.
        """
        if self._state != "new":
            raise StoreError(f"{self.directory}: run store already {self._state}")
        make_shared_directory(self.directory)
        if (self.directory / RUN_FILE).exists() or list_parts(self.directory):
            raise StoreError(f"{self.directory}: already holds a run; choose a new directory")
        make_shared_directory(self.directory / PARTS_DIR)
        fsync_directory(self.directory)
        clean_temporaries(self.directory)
        self._state = "open"
        try:
            self._add("run", "description", time.time(), self._write_description)
        except BaseException:
            self._state = "new"  # no run began: leave no empty run directory behind
            for empty in (self.directory / PARTS_DIR, self.directory):
                with contextlib.suppress(OSError):
                    empty.rmdir()
            raise

    def _write_description(self, f: Any) -> None:
        for i, (path, text) in enumerate(self._schedule_files):
            dataset(f, f"schedule_{i}", text, "text", path=path)
        f.attrs["schedule_files"] = [p for p, _ in self._schedule_files]
        dataset(f, "site", self._site_yaml, "text")
        dataset(f, "metadata", to_json(self._metadata), "JSON")
        f.attrs.update(
            run_name=self.name,
            channel_width_hz=self._channel_width_hz,
            band_hz=np.array(self._band_hz),
            software=to_json(software_versions()),
        )

    def _add(self, kind: str, name: str, timestamp: float, fill: Callable[[Any], None]) -> int:
        """Write one part durably; return its measurement number."""
        with self._lock:
            if self._state != "open":
                raise StoreError(f"{self.directory}: cannot add a {kind} to a {self._state} run")
            number = self._next
            path = write_part(self.directory, number, kind, name, timestamp, fill)
            self._records.append(Record(number, kind, name, path, "/"))
            self._next += 1
        log.debug("stored %s", path.name)
        return number

    def records(self, kind: str | None = None) -> list[Record]:
        """The measurements stored so far (of one kind), in order; no I/O."""
        with self._lock:
            return [r for r in self._records if kind is None or r.kind == kind]

    def engine_view(
        self,
        band_hz: tuple[float, float] | None = None,
        *,
        cycles: Mapping[str, Sequence[int]] | None = None,
    ) -> EngineView:
        """What the calibration engine sees of the run so far (the hand-over's rule).

        Parameters
        ----------
        band_hz
            The band; the run's by default.
        cycles
            Use exactly these Dicke cycles (source -> measurement numbers).
        """
        band = self._band_hz if band_hz is None else band_hz
        wanted = [r for r in self.records() if r.kind in ("s11", "dicke")]
        if cycles is not None:
            chosen = {n for numbers in cycles.values() for n in numbers}
            wanted = [r for r in wanted if r.kind == "s11" or r.sequence in chosen]
        with contextlib.ExitStack() as stack:
            groups = {r.sequence: stack.enter_context(h5py.File(r.file, "r")) for r in wanted}
            handover = select(groups, band, self._channel_width_hz, cycles=cycles)
            if RECEIVER not in handover.s11 or not handover.cycles:
                return EngineView(None, handover)
            layout = engine_layout(groups, handover, to_json(self._metadata))
        return EngineView(layout, handover)

    def add_s11(
        self,
        name: str,
        freq_hz: Any,
        s11: Any,
        *,
        timestamp: float,
        settings: Mapping[str, Any],
        calibrated: bool,
    ) -> int:
        """Store one reflection sweep of ``name`` (a source, or ``lna``) with the VNA settings."""
        freq = np.asarray(freq_hz, dtype=float)
        gamma = np.asarray(s11, dtype=complex)
        if freq.ndim != 1 or gamma.shape != freq.shape:
            raise ValueError(f"S11 of {name}: {gamma.shape} values for {freq.shape} frequencies")

        def fill(f: Any) -> None:
            dataset(f, "frequencies", freq, UNITS_HZ)
            dataset(f, "s11", gamma, UNITS_REFLECTION)
            f.attrs.update(calibrated=bool(calibrated), settings=to_json(dict(settings)))

        return self._add("s11", name, timestamp, fill)

    def add_dicke(
        self,
        source: str,
        *,
        spectra: Mapping[str, np.ndarray],
        timestamps: Mapping[str, Sequence[float]],
        integration_s: Mapping[str, float],
        n_spectra: Mapping[str, int],
        temperature_k: float | None,
        switch_states: Mapping[str, Mapping[str, str]],
        counters: Mapping[str, Mapping[str, int]],
        timestamp: float,
        temperature_std_k: float = 0.0,
        lst_h: Mapping[str, Sequence[float]] | None = None,
        thermocouples_k: Mapping[int, float] | None = None,
    ) -> int:
        """Store one Dicke cycle: per position the mean spectrum (n_inputs, n_channels).

        ``temperature_std_k`` is the uncertainty of ``temperature_k`` (K); ``lst_h`` the
        local sidereal time of each spectrum's mid-point, per position;
        ``thermocouples_k`` every TC-08 port's mean during the source position (K), for
        the temperatures of the sources' cables (dataset ``thermocouples``, NaN unread).
        """
        for what, value in (("spectra", spectra), ("timestamps", timestamps)):
            _per_position(what, value)
        _per_position("integration_s", integration_s)
        _per_position("n_spectra", n_spectra)
        _per_position("switch_states", switch_states, required=False)
        _per_position("counters", counters, required=False)
        arrays = {p: np.asarray(spectra[p], dtype=float) for p in DICKE_POSITIONS}
        shapes = {a.shape for a in arrays.values()}
        if len(shapes) != 1 or arrays["source"].ndim != 2:
            raise ValueError(f"Dicke spectra of {source} must share one 2-D shape: {shapes}")

        def fill(f: Any) -> None:
            f.attrs["source"] = source
            if temperature_k is not None:
                t = dataset(f, "temperature", float(temperature_k), UNITS_K)
                t.attrs["std_k"] = float(temperature_std_k)
            if thermocouples_k:
                ports = np.full(max(9, max(thermocouples_k) + 1), np.nan)  # TC-08 ports 0-8
                ports[list(thermocouples_k)] = list(thermocouples_k.values())
                dataset(f, "thermocouples", ports, UNITS_K)
            for p in DICKE_POSITIONS:
                g = f.create_group(p)
                dataset(g, "spectrum", arrays[p], UNITS_POWER)
                dataset(g, "timestamps", np.asarray(timestamps[p], dtype=float), UNITS_S)
                if lst_h is not None:
                    dataset(g, "lst", np.asarray(lst_h[p], dtype=float), UNITS_HOURS)
                g.attrs.update(
                    integration_s=float(integration_s[p]),
                    n_spectra=int(n_spectra[p]),
                    switch_state=to_json(dict(switch_states.get(p, {}))),
                    counters=to_json(dict(counters.get(p, {}))),
                )

        return self._add("dicke", source, timestamp, fill)

    def add_spectrum(
        self,
        name: str,
        spectrum: np.ndarray,
        *,
        timestamps: Sequence[float],
        integration_s: float,
        switch_state: Mapping[str, str],
        timestamp: float,
        lst_h: Sequence[float] | None = None,
    ) -> int:
        """Store one averaged spectrum outside a Dicke cycle (``lst_h`` per spectrum)."""

        def fill(f: Any) -> None:
            dataset(f, "spectrum", np.asarray(spectrum, dtype=float), UNITS_POWER)
            dataset(f, "timestamps", np.asarray(timestamps, dtype=float), UNITS_S)
            if lst_h is not None:
                dataset(f, "lst", np.asarray(lst_h, dtype=float), UNITS_HOURS)
            f.attrs.update(
                integration_s=float(integration_s), switch_state=to_json(dict(switch_state))
            )

        return self._add("spectrum", name, timestamp, fill)

    def add_temperatures(
        self, timestamps: Sequence[float], values_c: np.ndarray, channels: Sequence[str]
    ) -> None:
        """Store thermocouple readings: ``values_c`` is (n_times, n_channels), Celsius."""
        times = np.asarray(timestamps, dtype=float)
        values = np.asarray(values_c, dtype=float).reshape(times.size, -1)
        if times.ndim != 1 or times.size == 0 or values.shape[1] != len(channels):
            raise ValueError(f"temperatures {values.shape} for {times.shape} times, {channels}")

        def fill(f: Any) -> None:
            dataset(f, "timestamps", times, UNITS_S)
            dataset(f, "values", values, UNITS_C)
            f.attrs["channels"] = [str(c) for c in channels]

        self._add("temperatures", "log", float(times[-1]), fill)

    def add_monitoring(
        self,
        timestamps: Sequence[float],
        series: Sequence[int],
        values: Sequence[float],
        statuses: Sequence[int],
        *,
        keys: Sequence[str],
        units: Sequence[str],
        status_names: Sequence[str],
    ) -> None:
        """Store the health readings taken during the run, one row per reading.

        ``series[i]`` indexes ``keys``/``units``, ``statuses[i]`` indexes ``status_names``.
        """
        times = np.asarray(timestamps, dtype=float)
        if times.ndim != 1 or times.size == 0 or not len(series) == len(values) == times.size:
            raise ValueError("monitoring readings need as many series, values and times")

        def fill(f: Any) -> None:
            dataset(f, "timestamps", times, UNITS_S)
            dataset(f, "series", np.asarray(series, dtype=np.int32), UNITS_NONE)
            dataset(f, "values", np.asarray(values, dtype=float), UNITS_NONE)
            dataset(f, "status", np.asarray(statuses, dtype=np.int8), UNITS_NONE)
            f.attrs.update(keys=list(keys), units=list(units), status_names=list(status_names))

        self._add("monitoring", "health", float(times[-1]), fill)

    def add_check(
        self,
        name: str,
        passed: bool,
        *,
        timestamp: float,
        details: Mapping[str, Any],
        arrays: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        """Store a check's verdict, details and arrays (units from the array names)."""

        def fill(f: Any) -> None:
            f.attrs.update(passed=bool(passed), details=to_json(dict(details)))
            for key, value in (arrays or {}).items():
                arr = np.asarray(value)
                dataset(f, key, arr, units_for(key, arr))

        self._add("check", name, timestamp, fill)

    def add_solution(
        self,
        solution: AnySolution,
        *,
        timestamp: float,
        verification: Mapping[str, Any],
        handover: HandOver | None = None,
    ) -> int:
        """Store a calibration solution, how it was verified, and what it was made from."""

        def fill(f: Any) -> None:
            write_solution_group(f.create_group("solution"), solution)
            f.attrs["verification"] = to_json(dict(verification))
            if handover is not None:
                f.attrs["handover"] = handover.to_json()

        return self._add("solution", solution.method, timestamp, fill)

    def add_calibrated(
        self, name: str, freq_hz: Any, mean: Any, std: Any, flags: Any, *, timestamp: float,
        intervals: Mapping[str, Any] | None = None,
    ) -> None:
        """Store a calibrated spectrum: mean, standard deviation (K) and channel flags.

        ``intervals``: the credible intervals' ends by name (K; ``lower_68``, ``upper_68``,
        ...), what the std alone does not give for a model-averaged solution.
        """

        def fill(f: Any) -> None:
            dataset(f, "frequencies", np.asarray(freq_hz, dtype=float), UNITS_HZ)
            dataset(f, "mean", np.asarray(mean, dtype=float), UNITS_K)
            dataset(f, "std", np.asarray(std, dtype=float), UNITS_K)
            dataset(f, "flags", np.asarray(flags, dtype=bool), UNITS_NONE)
            for key, values in (intervals or {}).items():
                dataset(f, key, np.asarray(values, dtype=float), UNITS_K)

        self._add("calibrated", name, timestamp, fill)

    def add_copy(self, group: Any, *, origin: str) -> int:
        """Store a copy of a measurement of another run (a resumed run carries them on).

        The copy keeps the measurement's kind, name, time, data and attributes, and says
        where it came from (attribute ``carried_from``).
        """
        kind, name = as_str(group.attrs["kind"]), as_str(group.attrs["name"])

        def fill(f: Any) -> None:
            for key in group:
                group.copy(group[key], f, name=key)
            f.attrs.update({k: v for k, v in group.attrs.items() if k not in _OWN_ATTRS})
            f.attrs["carried_from"] = origin

        return self._add(kind, name, float(group.attrs["timestamp"]), fill)

    def add_event(self, kind: str, message: str, *, timestamp: float) -> None:
        """Store an event: a fault, the safe state, an operator's Ctrl-C."""

        def fill(f: Any) -> None:
            f.attrs.update(event=kind, message=message)

        self._add("event", kind, timestamp, fill)

    def finish(self, status: str, reason: str = "") -> Path:
        """Record how the run ended and merge it into ``run.h5``; returns its path.

        Called again (e.g. after the merge itself failed), it merges again with the new
        status.
        """
        if status not in STATUSES:
            raise ValueError(f"status must be one of {STATUSES}, got {status!r}")
        if self._state == "finished":
            return merge_run(self.directory, status, reason)

        def fill(f: Any) -> None:
            f.attrs.update(status=status, reason=reason)

        self._add("status", status, time.time(), fill)
        with self._lock:
            self._state = "finished"
        return merge_run(self.directory)
