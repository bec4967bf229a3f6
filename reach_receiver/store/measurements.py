"""What each measurement kind of a run holds: the ``add_*`` writers of a run store.

Each writer checks its inputs, then hands :meth:`RunStore._add
<reach_receiver.store.run_store.RunStore>` a function that fills one part file, so a
measurement is on disk, durably, when the writer returns.

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
                 lower_95, upper_95 (K; the credible intervals' ends); std_calibration,
                 std_radiometer (K: the solution's error, shared by every spectrum it
                 calibrates, and the radiometer noise, independent per spectrum; the
                 rest of std is the S11s' trace noise); attr handover (JSON: the cycle
                 and S11s used)
    event        attrs event, message

Names of S11 measurements are source names (REACH names) and ``lna`` for the receiver.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from calibration.io.solution_file import write_solution_group
from calibration.solve.solvers import AnySolution

from .handover import HandOver
from .parts import (
    UNITS_C,
    UNITS_HOURS,
    UNITS_HZ,
    UNITS_K,
    UNITS_NONE,
    UNITS_POWER,
    UNITS_REFLECTION,
    UNITS_S,
    as_str,
    dataset,
    to_json,
)

#: Dicke positions (thesis 2.1.1): the source, the reference load, the noise source.
DICKE_POSITIONS = ("source", "load", "ns")
#: Attributes a part file writes for itself, not copied from another run's measurement.
_OWN_ATTRS = {"format", "format_version", "kind", "name", "sequence", "timestamp"}
_UNIT_SUFFIXES = (("_hz", UNITS_HZ), ("_k", UNITS_K), ("_c", UNITS_C), ("_s", UNITS_S))


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



class MeasurementWriters:
    """The ``add_*`` methods of :class:`~reach_receiver.store.run_store.RunStore`."""

    def _add(self, kind: str, name: str, timestamp: float, fill: Callable[[Any], None]) -> int:
        """Write one part durably; return its measurement number (the store's)."""
        raise NotImplementedError

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
        errors: Mapping[str, Any] | None = None, handover: HandOver | None = None,
    ) -> None:
        """Store a calibrated spectrum: mean, standard deviation (K) and channel flags.

        ``intervals``: the credible intervals' ends by name (K; ``lower_68``, ``upper_68``,
        ...), what the std alone does not give for a model-averaged solution. ``errors``:
        parts of the std by name (K; ``std_calibration``, ``std_radiometer``), which a
        season's average needs apart; ``handover``: the cycle and S11s calibrated.
        """

        def fill(f: Any) -> None:
            dataset(f, "frequencies", np.asarray(freq_hz, dtype=float), UNITS_HZ)
            dataset(f, "mean", np.asarray(mean, dtype=float), UNITS_K)
            dataset(f, "std", np.asarray(std, dtype=float), UNITS_K)
            dataset(f, "flags", np.asarray(flags, dtype=bool), UNITS_NONE)
            for key, values in {**(intervals or {}), **(errors or {})}.items():
                dataset(f, key, np.asarray(values, dtype=float), UNITS_K)
            if handover is not None:
                f.attrs["handover"] = handover.to_json()

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


__all__ = ["DICKE_POSITIONS", "MeasurementWriters", "units_for"]
