"""The status page's figures, from what the daemon has stored (read-only).

Each builder returns a :class:`matplotlib.figure.Figure` in the engine's style
(:mod:`calibration.report.figures.style`, Agg, no pyplot) and says so in the figure when it has
nothing to show yet:

* :func:`dicke_spectra`: the latest Dicke cycle of the newest run that has one (a running
  run's parts count: :func:`~reach_receiver.store.read_run_file` reads them unmerged),
  its three positions' spectra (the receiver's input, in dB of the spectrometer's
  arbitrary unit) and their ``Q`` (thesis eq. 3.9) over the run's band;
* :func:`s11s`: the latest S11 of every target in the newest run with S11s, on a Smith
  chart and in dB (the chart of :func:`calibration.report.figures.reflections`);
* :func:`temperatures_last_day`: every temperature series of the metrics database
  (:meth:`~reach_receiver.monitor.database.MetricsDatabase.series`) over the last day,
  drawn by :func:`calibration.report.figures.temperatures`;
* :func:`current_solution`: the newest run's latest ``/calibration/solution`` drawn by
  :func:`calibration.report.figures.noise_wave_parameters`;
* :func:`adaptive_progress`: the newest run with an adaptive calibration (running or
  done), its antenna's predicted error falling against instrument time
  (:func:`calibration.report.figures.adaptive_course`); on the page only once there is one
  (:func:`adaptive_decisions`).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from calibration.io.run_records import ADAPTIVE_DECISION
from calibration.model.noise_waves import q_from_powers
from calibration.report.figures import adaptive_course, noise_wave_parameters
from calibration.report.figures.reflections import SMITH_SPACE, smith_grid
from calibration.report.figures.style import (
    NEUTRAL,
    WIDTH_PX,
    Space,
    axes_grid,
    envelope,
    grid,
    legend_right,
    mhz,
    new_figure,
    note,
    styled,
    suptitle,
)
from reach_receiver.config.monitoring import AlarmRule
from reach_receiver.errors import ReceiverError
from reach_receiver.monitor.database import MetricsDatabase
from reach_receiver.monitor.readings import parse_key
from reach_receiver.store import RUN_FILE, Measurement, RunContents, read_run_file

from .status_panels import DASHES, OKABE_ITO, temperature_panels

__all__ = [
    "CAPTIONS",
    "FIGURES",
    "adaptive_decisions",
    "adaptive_progress",
    "current_solution",
    "data_version",
    "dicke_spectra",
    "last_spectrum",
    "runs_newest_first",
    "s11s",
    "temperatures_last_day",
]

#: Seconds of metrics the temperatures figure shows.
DAY_S = 86400.0
#: The temperature series: the metrics whose unit is degrees Celsius, but not setpoints.
TEMPERATURE_UNIT = "degC"
#: Runs searched, newest first, for a figure's data.
RUNS_SEARCHED = 20
_POSITIONS = (("source", "source"), ("load", "reference load"), ("ns", "noise source"))


def runs_newest_first(runs: Path) -> Iterator[RunContents]:
    """The runs under ``runs`` (closed or still running), newest first; unreadable skipped."""
    directories = sorted((p for p in runs.glob("*") if p.is_dir()), reverse=True)
    for directory in directories[:RUNS_SEARCHED]:
        if not (directory / RUN_FILE).exists() and not (directory / "parts").is_dir():
            continue
        try:
            yield read_run_file(directory / RUN_FILE if (directory / RUN_FILE).exists()
                                else directory)
        except (ReceiverError, OSError, ValueError, KeyError):
            continue


def _newest_with(runs: Path, kind: str) -> tuple[RunContents, list[Measurement]] | None:
    """The newest run holding measurements of ``kind``, and those measurements."""
    for contents in runs_newest_first(runs):
        found = contents.of_kind(kind)
        if found:
            return contents, found
    return None


def _stamp(t: float) -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(t))


def _empty(text: str, height_in: float = 2.4) -> Figure:
    fig = new_figure(height_in)
    note(fig.add_subplot(), text)
    return fig


@styled
def dicke_spectra(runs: Path) -> Figure:
    """The latest Dicke cycle's three spectra (dB) and ``Q`` against frequency."""
    newest = _newest_with(runs, "dicke")
    if newest is None:
        return _empty("no Dicke cycle recorded yet")
    contents, cycles = newest
    cycle = cycles[-1]
    arrays = contents.read(cycle)
    n = arrays["source/spectrum"].shape[-1]
    freq = np.arange(n) * contents.channel_width_hz
    band = (freq >= contents.band_hz[0]) & (freq <= contents.band_hz[1])
    if not band.any():
        band[:] = True
    power = {p: np.asarray(arrays[f"{p}/spectrum"], float)[0, band] for p, _ in _POSITIONS}
    x = mhz(freq[band])
    fig = new_figure(5.6)
    axes, bottom = axes_grid(fig, 4, 2, space=Space(top=0.6))
    for ax, (position, label) in zip(axes, _POSITIONS, strict=False):
        level = 10 * np.log10(np.maximum(power[position], 1e-30))
        ax.plot(*envelope(x, level, WIDTH_PX // 2), color=NEUTRAL, lw=0.8)
        ax.set_title(f"{position}: switch on the {label}")
        ax.set_ylabel("power (dB, arbitrary)")
    with np.errstate(divide="ignore", invalid="ignore"):
        q = q_from_powers(power["source"], power["load"], power["ns"])
    axes[3].plot(*envelope(x, q, WIDTH_PX // 2), color="C0", lw=0.8)
    axes[3].set_title("Q = (source − load) / (noise source − load)")
    axes[3].set_ylabel("Q")
    for ax in bottom:
        ax.set_xlabel("frequency (MHz)")
    suptitle(
        fig, f"Latest Dicke cycle: {cycle.name}, {_stamp(cycle.timestamp)} (run {contents.name})"
    )
    return fig


@styled
def s11s(runs: Path) -> Figure:
    """The latest S11 of each target of the newest run with S11s: Smith chart and dB."""
    newest = _newest_with(runs, "s11")
    if newest is None:
        return _empty("no S11 measured yet")
    contents, found = newest
    latest = {m.name: m for m in found}  # in order: the last of each name wins
    styles: dict[str, dict[str, Any]] = {
        name: {"color": OKABE_ITO[i % len(OKABE_ITO)], "ls": DASHES[i // len(OKABE_ITO) % 3]}
        for i, name in enumerate(latest)
    }
    fig = new_figure(6.4)
    spec = grid(fig, 2, 2, SMITH_SPACE, width_ratios=(1, 1.25))
    smith = fig.add_subplot(spec[:, 0])
    db = fig.add_subplot(spec[0, 1])
    phase = fig.add_subplot(spec[1, 1], sharex=db)
    smith_grid(smith)
    for name, measurement in latest.items():
        arrays = contents.read(measurement)
        gamma = np.asarray(arrays["s11"], dtype=complex)
        x = mhz(np.asarray(arrays["frequencies"], dtype=float))
        smith.plot(*_thin(gamma.real, gamma.imag), lw=1.0, **styles[name])
        level = 20 * np.log10(np.maximum(np.abs(gamma), 1e-12))
        db.plot(*envelope(x, level, WIDTH_PX // 2), label=name, **styles[name])
        degrees = np.degrees(np.unwrap(np.angle(gamma)))
        phase.plot(*envelope(x, degrees, WIDTH_PX // 2), **styles[name])
    phase.set_xlabel("frequency (MHz)")
    db.set_ylabel("|Γ| (dB)")
    phase.set_ylabel("phase of Γ (°, unwrapped)")
    smith.set_title("Smith chart")
    db.set_title("reflection magnitude and phase")
    legend_right(fig, spec, *db.get_legend_handles_labels())
    last = max(m.timestamp for m in latest.values())
    suptitle(fig, f"Latest S11s: run {contents.name}, to {_stamp(last)}")
    return fig


def _thin(x: np.ndarray, y: np.ndarray, points: int = WIDTH_PX) -> tuple[np.ndarray, np.ndarray]:
    """Every n-th point of a curve, at most about ``points`` of them.

    A Smith chart's curve is smooth at that density; all of a VNA's points would only
    make the image larger.
    """
    step = max(1, len(x) // points)
    return x[::step], y[::step]


def _label(key: str) -> str:
    """``cold junction``, ``teensy 0x18``, ``tec``: what a person calls the sensor."""
    metric, labels = parse_key(key)
    if "component" in labels:
        return labels["component"]
    short = metric.removeprefix("reach_").removesuffix("_celsius").replace("_temperature", "")
    return " ".join([short, *labels.values()])


@styled
def temperatures_last_day(
    database: MetricsDatabase | None, now: float, rules: Sequence[AlarmRule] = ()
) -> Figure:
    """The metrics database's temperatures over the last day on a UTC clock.

    The thresholds of ``rules`` (the site's alarms) are drawn (:mod:`.status_panels`).
    """
    if database is None:
        return _empty("the metrics database is not open")
    known = database.keys()
    keys = [
        k for k in known
        if database.unit(k) == TEMPERATURE_UNIT and "setpoint" not in parse_key(k)[0]
    ]
    fig = temperature_panels(database, keys, now, DAY_S, rules)
    if fig is None:
        return _empty("no temperature in the metrics database over the last day")
    suptitle(fig, f"Temperatures over the last day (metrics database, to {_stamp(now)})")
    return fig


def current_solution(runs: Path) -> Figure:
    """The noise-wave parameters of the newest run's latest solution."""
    newest = _newest_with(runs, "solution")
    solution = newest[0].solution() if newest is not None else None
    if newest is None or solution is None:
        return styled(_empty)("no calibration solution yet")
    fig = noise_wave_parameters(solution)
    suptitle(fig, f"{fig.get_suptitle()}: run {newest[0].name}")
    return fig


def adaptive_decisions(runs: Path) -> tuple[str, list[Mapping[str, Any]]] | None:
    """The newest run with adaptive decisions (a running run's parts count): name, decisions."""
    for contents in runs_newest_first(runs):
        found = [m for m in contents.of_kind("check") if m.name == ADAPTIVE_DECISION]
        if found:
            details = [m.attrs.get("details", {}) for m in found]
            decisions = [json.loads(d) if isinstance(d, str | bytes) else d for d in details]
            return contents.name, sorted(decisions, key=lambda d: int(d.get("step", 0)))
    return None


def adaptive_progress(runs: Path) -> Figure:
    """The newest adaptive calibration's predicted error against instrument time."""
    newest = adaptive_decisions(runs)
    if newest is None:
        return styled(_empty)("no adaptive calibration yet")
    fig = adaptive_course(newest[1])
    suptitle(fig, f"run {newest[0]}")
    return fig


#: The page's figures by name, each built from the runs directory, the database, the
#: daemon's clock and the site's alarm rules.
FIGURES: dict[str, Callable[[Path, MetricsDatabase | None, float, Sequence[AlarmRule]],
                            Figure]] = {
    "spectra": lambda runs, db, now, rules: dicke_spectra(runs),
    "s11": lambda runs, db, now, rules: s11s(runs),
    "temperatures": lambda runs, db, now, rules: temperatures_last_day(db, now, rules),
    "solution": lambda runs, db, now, rules: current_solution(runs),
    "adaptive": lambda runs, db, now, rules: adaptive_progress(runs),
}
#: Figures on the page only when :data:`SHOWN_WHEN` says they have something to show.
SHOWN_WHEN: dict[str, Callable[[Path], bool]] = {
    "adaptive": lambda runs: adaptive_decisions(runs) is not None,
}


#: What each figure shows, in words (the image's alternative text).
CAPTIONS = {
    "spectra": "the latest Dicke cycle's spectra and Q",
    "s11": "the latest S11s",
    "temperatures": "the temperatures of the last day",
    "solution": "the current solution's noise-wave parameters",
    "adaptive": "the adaptive calibration's predicted antenna error against time",
}


def _stat(path: Path) -> tuple[str, int, int] | None:
    try:
        info = path.stat()
    except OSError:
        return None
    return path.name, info.st_mtime_ns, info.st_size


def data_version(name: str, runs: Path, database: MetricsDatabase | None) -> str:
    """A string that changes when the data behind figure ``name`` change (cheap: stats only).

    The run figures depend on the runs searched (each run file, and each part of a run
    still running); the temperatures on the metrics database (its file and its WAL).
    """
    if name == "temperatures":
        if database is None:
            return "closed"
        wal = database.path.with_name(database.path.name + "-wal")
        return repr((_stat(database.path), _stat(wal)))
    directories = sorted((p for p in runs.glob("*") if p.is_dir()), reverse=True)
    seen: list[object] = []
    for directory in directories[:RUNS_SEARCHED]:
        seen.append((directory.name, _stat(directory / RUN_FILE)))
        parts = directory / "parts"
        if parts.is_dir():
            seen.extend(_stat(p) for p in sorted(parts.iterdir()))
    return repr(seen)


def last_spectrum(runs: Path) -> float | None:
    """The time of the newest stored Dicke cycle (a running run's parts included)."""
    newest = _newest_with(runs, "dicke")
    return None if newest is None else float(newest[1][-1].timestamp)
