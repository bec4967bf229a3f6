"""The one hand-over from a run to the calibration engine: which measurements, and how.

A calibration made during a run (the ``calibrate`` step), the run file's engine layout
(``/observation_data``, which ``reach-cal solve run.h5`` reads) and a run read back
(:meth:`~reach_receiver.store.reader.RunContents.calibration_data`) all come from here:

1. :func:`select` chooses the measurements by one rule, recorded as a :class:`HandOver`:

   * the band: the channels whose centres ``k * channel_width_hz`` lie in ``band_hz``;
   * the receiver's and each source's reflection: its latest S11 taken with the VNA's
     error correction on (after an SOL calibration);
   * the spectra: every Dicke cycle of each source so far, averaged (the engine's
     convention for 2-D spectra), integration times added;
   * the calibrators: the sources other than the antenna ``ant`` with a thermocouple
     temperature in every chosen cycle; their temperature is the mean of the cycles'
     (each the mean of its readings during its own source position), with the
     root-sum-square of the cycles' standard errors over their number;
   * every TC-08 port's mean over the source's cycles (``thermocouples_k``: its
     cable's temperature, :mod:`reach_receiver.store.corrections`);
   * a source whose S11 is missing or does not cover the band (no extrapolation), or
     whose spectra do not cover the band's channels, is left out with a warning.

2. :func:`write_layout` writes the chosen measurements in REACH's layout (the
   calibration engine's :mod:`calibration.io.hdf5_io`), with the hand-over itself as the
   ``handover`` attribute (JSON) of ``/observation_metadata``.

3. :func:`engine_layout` reads that layout back with the engine's own reader
   (:func:`calibration.io.hdf5_io.read_run_layout`, the body of ``read_run``) from a file
   built in memory: the numbers the engine sees during a run are, bit for bit, those
   ``reach-cal`` reads from the merged run file.

S11s are interpolated onto the channels by cubic splines through their real and
imaginary parts (:func:`interpolate_s11`): the REACH sources' reflections are smooth
on the VNA's grid (the 10 m cable's ripple has a period of about 10 MHz). Each sweep's
trace noise, estimated from its own scatter on the VNA's grid
(:func:`calibration.model.reflection_noise.trace_noise`), goes beside it as ``{src}_s11_std``
(``lna_s11_std``), so that the solver, the error bars and the floor carry it; how many
channels share one sweep point's error goes beside them (``reflection_correlation_channels``
of ``observation_metadata``: the sweep step over the channel width, ~8 for REACH), which
the posterior's covariance needs: a fit averaging thousands of channels sees an error
shared by 8 of them 8 times less reduced than independent ones.
"""

from __future__ import annotations

import io
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from calibration.io.hdf5_io import RECEIVER_RUN_FORMAT, RunLayout, read_run_layout
from calibration.io.receiver_grid import band_channels, interpolate_s11
from calibration.model.reflection_noise import trace_noise
from reach_receiver.frontend.layout import NOISE_SOURCE_MODEL

from .parts import (
    FORMAT_VERSION,
    UNITS_HZ,
    UNITS_K,
    UNITS_POWER,
    UNITS_REFLECTION,
    UNITS_S,
    as_str,
    dataset,
)

#: The validation source: never a calibrator, calibrated with each new solution.
ANTENNA = "ant"
#: The name of the receiver's own reflection among the S11s.
RECEIVER = "lna"
POSITIONS = (("source", "spectra"), ("load", "load_spectra"), ("ns", "ns_spectra"))

Groups = Mapping[int, Any]
"""Measurement number -> its open HDF5 group (attributes ``kind`` and ``name``)."""


def channel_frequencies(channel_width_hz: float, channels: slice) -> NDArray[np.float64]:
    """The centre frequencies of a slice of channels (Hz)."""
    return channel_width_hz * np.arange(channels.start, channels.stop, dtype=float)


@dataclass(frozen=True)
class HandOver:
    """What a calibration used: the band, and the measurements by their run numbers.

    ``cycles`` maps each source to its Dicke cycles, ``s11`` each source (and ``lna``) to
    its S11; ``warnings`` says what was left out and why.
    """

    band_hz: tuple[float, float]
    channel_width_hz: float
    cycles: Mapping[str, tuple[int, ...]]
    s11: Mapping[str, int]
    calibrators: tuple[str, ...]
    warnings: tuple[str, ...] = ()
    temperatures_k: Mapping[str, float] = field(default_factory=dict)
    thermocouples_k: Mapping[str, Mapping[int, float]] = field(default_factory=dict)
    corrections: Mapping[str, Any] = field(default_factory=dict)

    @property
    def channels(self) -> slice:
        """The band's channels."""
        return band_channels(self.channel_width_hz, self.band_hz)

    @property
    def sources(self) -> tuple[str, ...]:
        """Every source of the layout, in the order of their first cycle."""
        return tuple(self.cycles)

    @property
    def measurements(self) -> tuple[int, ...]:
        """Every measurement used, by number."""
        used = {*self.s11.values(), *(n for seqs in self.cycles.values() for n in seqs)}
        return tuple(sorted(used))

    def renumbered(self, numbers: Mapping[int, int]) -> HandOver:
        """The same hand-over with its measurements named by new numbers.

        A resumed run stores copies of an earlier run's measurements under its own
        numbers (:func:`reach_receiver.run.resume.carry`); a carried calibration's
        hand-over must name the copies. ``KeyError`` when one of them was not copied.
        """
        return replace(
            self,
            cycles={k: tuple(numbers[n] for n in v) for k, v in self.cycles.items()},
            s11={k: numbers[n] for k, n in self.s11.items()},
        )

    def to_json(self) -> str:
        """The hand-over as JSON, as a run file records it."""
        return json.dumps(
            {
                "band_hz": list(self.band_hz),
                "channel_width_hz": self.channel_width_hz,
                "cycles": {k: list(v) for k, v in self.cycles.items()},
                "s11": dict(self.s11),
                "calibrators": list(self.calibrators),
                "temperatures_k": dict(self.temperatures_k),
                "thermocouples_k": {k: dict(v) for k, v in self.thermocouples_k.items()},
                "corrections": dict(self.corrections),
                "warnings": list(self.warnings),
            }
        )

    @classmethod
    def from_json(cls, text: str) -> HandOver:
        """Read :meth:`to_json`'s output back."""
        value = json.loads(text)
        return cls(
            band_hz=(float(value["band_hz"][0]), float(value["band_hz"][1])),
            channel_width_hz=float(value["channel_width_hz"]),
            cycles={k: tuple(int(n) for n in v) for k, v in value["cycles"].items()},
            s11={k: int(v) for k, v in value["s11"].items()},
            calibrators=tuple(value["calibrators"]),
            warnings=tuple(value.get("warnings", ())),
            temperatures_k={k: float(v) for k, v in value.get("temperatures_k", {}).items()},
            thermocouples_k={
                k: {int(p): float(t) for p, t in v.items()}
                for k, v in value.get("thermocouples_k", {}).items()
            },
            corrections=value.get("corrections", {}),
        )


def _kind_name(group: Any) -> tuple[str, str]:
    return as_str(group.attrs["kind"]), as_str(group.attrs["name"])


def select(
    groups: Groups,
    band_hz: tuple[float, float],
    channel_width_hz: float,
    *,
    cycles: Mapping[str, Sequence[int]] | None = None,
) -> HandOver:
    """Choose the measurements of a calibration by the module's rule.

    Parameters
    ----------
    groups
        The run's measurements so far, by number.
    band_hz, channel_width_hz
        The band and the spectrometer's channel width.
    cycles
        Use exactly these Dicke cycles (source -> numbers) instead of every cycle.
    """
    latest_s11: dict[str, int] = {}
    found: dict[str, list[int]] = {}
    for number in sorted(groups):
        kind, name = _kind_name(groups[number])
        if kind == "s11" and bool(groups[number].attrs["calibrated"]):
            latest_s11[name] = number
        elif kind == "dicke" and cycles is None:
            found.setdefault(name, []).append(number)
    chosen = {k: list(v) for k, v in (cycles.items() if cycles is not None else found.items())}
    channels = band_channels(channel_width_hz, band_hz)
    freq = channel_frequencies(channel_width_hz, channels)
    lo, hi = band_hz
    warnings: list[str] = []

    def covered(name: str) -> bool:
        if name not in latest_s11:
            warnings.append(f"{name}: no calibrated S11; left out of the engine layout")
            return False
        g = groups[latest_s11[name]]
        if interpolate_s11(g["frequencies"][()], g["s11"][()], freq[[0, -1]]) is None:
            warnings.append(f"{name}: S11 does not cover {lo:.0f}-{hi:.0f} Hz; left out")
            return False
        return True

    s11: dict[str, int] = {}
    if covered(RECEIVER):
        s11[RECEIVER] = latest_s11[RECEIVER]
    used: dict[str, tuple[int, ...]] = {}
    calibrators: list[str] = []
    temperatures: dict[str, float] = {}
    ports: dict[str, dict[int, float]] = {}
    for source, numbers in chosen.items():
        widths = {groups[n]["source/spectrum"].shape[1] for n in numbers}
        if len(widths) != 1 or min(widths) < channels.stop:
            warnings.append(f"{source}: spectra do not cover the band channels; left out")
            continue
        if not covered(source):
            continue
        used[source] = tuple(numbers)
        s11[source] = latest_s11[source]
        if all("thermocouples" in groups[n] for n in numbers):
            read = np.array([groups[n]["thermocouples"][()] for n in numbers])
            n_read = np.isfinite(read).sum(axis=0)
            total = np.where(np.isfinite(read), read, 0.0).sum(axis=0)
            ports[source] = {p: float(total[p] / k) for p, k in enumerate(n_read) if k}
        known = ["temperature" in groups[n] for n in numbers]
        if source != ANTENNA and all(known):
            calibrators.append(source)
            temperatures[source] = float(np.mean([groups[n]["temperature"][()] for n in numbers]))
        elif source != ANTENNA and any(known):
            warnings.append(f"{source}: a cycle has no temperature; not used as a calibrator")
    return HandOver(
        band_hz=(float(lo), float(hi)),
        channel_width_hz=float(channel_width_hz),
        cycles=used,
        s11=s11,
        calibrators=tuple(calibrators),
        warnings=tuple(warnings),
        temperatures_k=temperatures,
        thermocouples_k=ports,
    )


def _str_array(values: Sequence[str]) -> NDArray[Any]:
    return np.array(list(values), dtype=h5py.string_dtype())


def write_layout(f: Any, groups: Groups, handover: HandOver) -> None:
    """Write the hand-over's measurements in REACH's layout into the open file ``f``."""
    channels = handover.channels
    freq = channel_frequencies(handover.channel_width_hz, channels)
    obs = f.create_group("observation_data")
    dataset(obs, "frequencies", freq, UNITS_HZ)
    meta = f.create_group("observation_metadata")
    temps = meta.create_group("temperatures")

    def gamma(name: str) -> NDArray[np.complex128]:
        g = groups[handover.s11[name]]
        value = interpolate_s11(g["frequencies"][()], g["s11"][()], freq)
        if value is None:  # select() checked the coverage
            raise ValueError(f"S11 of {name} does not cover the band")
        return value

    def noise(name: str, dataset_name: str) -> None:
        # The sweep's trace noise, from its own scatter on the VNA's grid, per channel
        # (calibration.model.reflection_noise.trace_noise; nothing where it cannot tell).
        g = groups[handover.s11[name]]
        sigma = trace_noise(g["s11"][()])
        if sigma is not None:
            dataset(obs, dataset_name, np.full(freq.size, sigma), "1", measurement=g.name)

    if RECEIVER in handover.s11:
        g = groups[handover.s11[RECEIVER]]
        dataset(obs, "lna_s11", gamma(RECEIVER), UNITS_REFLECTION, measurement=g.name)
        noise(RECEIVER, "lna_s11_std")
    for source, numbers in handover.cycles.items():
        rows = [groups[n] for n in numbers]
        for position, suffix in POSITIONS:
            data = np.stack([g[f"{position}/spectrum"][0, channels] for g in rows])
            dataset(obs, f"{source}_{suffix}", data[0] if len(rows) == 1 else data, UNITS_POWER)
        spectra = obs[f"{source}_spectra"]
        for position, _ in POSITIONS:
            per_row = [float(g[position].attrs["integration_s"]) for g in rows]
            spectra.attrs[f"integration_s_{position}"] = float(np.mean(per_row))
            if len(set(per_row)) > 1:  # cycles of unequal length: averaged weighted by time
                spectra.attrs[f"row_integration_s_{position}"] = per_row
        spectra.attrs["measurements"] = _str_array([g.name for g in rows])
        times = np.array([[_mean_time(g, p) for p, _ in POSITIONS] for g in rows])
        dataset(
            obs,
            f"{source}_timestamps",
            times[0] if len(rows) == 1 else times,
            UNITS_S,
            columns=_str_array([p for p, _ in POSITIONS]),
        )
        s11 = groups[handover.s11[source]]
        dataset(obs, f"{source}_s11", gamma(source), UNITS_REFLECTION, measurement=s11.name)
        noise(source, f"{source}_s11_std")
        if source in handover.calibrators:
            per_cycle = [float(g["temperature"][()]) for g in rows]
            stds = [float(g["temperature"].attrs.get("std_k", 0.0)) for g in rows]
            dataset(
                temps,
                source,
                float(np.mean(per_cycle)),
                UNITS_K,
                per_cycle_k=per_cycle,
                timestamps=[float(g.attrs["timestamp"]) for g in rows],
                std_k=float(np.sqrt(np.sum(np.square(stds))) / len(stds)),
            )
    meta.attrs.update(
        channel_width_hz=handover.channel_width_hz,
        sources=_str_array(handover.sources),
        calibrators=_str_array(handover.calibrators),
        reflection_correlation_channels=_shared_channels(groups, handover),
        band_hz=np.array(handover.band_hz),
        handover=handover.to_json(),
    )
    obs.attrs["warnings"] = _str_array(handover.warnings)


def _shared_channels(groups: Groups, handover: HandOver) -> float:
    """Channels that share one sweep point's error: the widest S11 step / channel width.

    The splines carry each point's trace noise onto the channels around it
    (:mod:`calibration.solve.correlated_reflections`); 1 where a sweep is finer than the channels.
    """
    steps = [
        float(np.median(np.diff(groups[number]["frequencies"][()])))
        for number in handover.s11.values()
        if groups[number]["frequencies"].size > 1
    ]
    return max([1.0] + [step / handover.channel_width_hz for step in steps])


def _mean_time(group: Any, position: str) -> float:
    stamps = group[f"{position}/timestamps"]
    return float(np.mean(stamps[()])) if stamps.size else float(group.attrs["timestamp"])


def engine_layout(
    groups: Groups, handover: HandOver, metadata: str, name: str = "<run so far>"
) -> RunLayout:
    """What the engine reads from :func:`write_layout`'s layout, built in memory.

    ``metadata`` is the run's metadata (JSON), as the merged run file's root carries it.
    """
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        f.attrs.update(format=RECEIVER_RUN_FORMAT, format_version=FORMAT_VERSION)
        f.attrs.update(metadata=metadata, noise_source_model=NOISE_SOURCE_MODEL)
        write_layout(f, groups, handover)
        return read_run_layout(f, name)
