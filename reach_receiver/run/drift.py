"""After each calibration, whether the receiver drifted since the previous solution.

The ``calibrate`` step hands its new solution here before storing it. The previous
solution is the one made earlier in the same run, else the newest one among the runs
beside this one (the daemon's data directory, a ``reach-run --out`` directory): the
solution the receiver was calibrated with until now. The drift that matters is the
antenna's: it is calibrated with both, on the channels both solutions cover, as this run
measured it or, where this run has not (an observing run calibrates before its first
antenna cycle), as the previous solution's run did (its hand-over's spectrum and S11 on
the same channels). Only where neither run measured the antenna is the comparison made
on this calibration's validation source, a calibrator: each solution is pinned to its own
measurement of it, where the model averaging's spread between two solutions shows most
(over six simulated stable weeks its differences scattered 1.18 times their stated
variance against 0.8-1.0 on the antenna).
:func:`~reach_receiver.run.checks.compare_on_source` tests the difference against both
solutions' credible intervals (one chi-square per calibration over 5 MHz sub-bands, and
the matched test along the shift that the LNA's noise waves scaled together would give:
its temperature, the likeliest drift). Both
calibrations use this run's receiver S11, so its trace noise is common to them.

The verdict is a check of the run (``calibration_drift``: passed, or the size and band
of the drift), a log line, and, under ``reachd``, a reading of
``reach_calibration_drift_sigma`` for the monitor, whose ``calibration drift`` alarm
(:data:`~reach_receiver.config.monitoring.DEFAULT_ALARMS`: 3.9 sigma, a false-alarm
probability of 1e-4 per calibration) is raised at WARNING with the drift's size and band
and cleared at INFO by the next calibration that agrees with its predecessor. The alarm's
threshold (the site's ``monitoring.alarms``, by the name ``calibration drift``) is also the
check's.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import h5py
import numpy as np
from numpy.typing import NDArray

from calibration.core.errors import CalibrationError
from calibration.model.data import CalibrationData, SourceData
from calibration.model.noise_waves import design_terms
from calibration.season.recalibrate import cycle_inputs, run_cycles
from calibration.solve.solvers import AnySolution, band_hz
from reach_receiver.config.monitoring import DEFAULT_ALARMS, DRIFT_ALARM, DRIFT_METRIC
from reach_receiver.errors import ReceiverError
from reach_receiver.monitor.readings import Reading
from reach_receiver.store import RUN_FILE, RunContents, read_run_file
from reach_receiver.store.handover import ANTENNA

from .checks import DriftVerdict, compare_on_source
from .context import RunContext

log = logging.getLogger(__name__)

#: Runs looked through (newest first) for the previous solution.
RUNS_SEARCHED = 20


@dataclass(frozen=True)
class Previous:
    """The solution the receiver was calibrated with until now, and where it was made."""

    solution: AnySolution
    timestamp: float | None
    where: str
    #: That run as stored (``None``: this run), read for its antenna only when needed.
    contents: RunContents | None = None


def antenna_of_run(
    contents: RunContents, band: tuple[float, float]
) -> tuple[SourceData | None, NDArray[np.float64] | None]:
    """The antenna as a run measured it, if it did, on the solution's ``band``.

    An observing run's last calibrated antenna cycle (its own hand-over: the cycle and the
    S11s it was calibrated with), else the antenna of the run's hand-over (the data a
    solve of it reads: a calibrating run that measured the antenna).
    """
    if not any(m.kind == "dicke" and m.name == ANTENNA for m in contents.measurements):
        return None, None
    try:
        if contents.merged and contents.of_kind("calibrated"):
            where = str(contents.path)
            with h5py.File(contents.path, "r") as f:
                cycles = run_cycles(f, where)
                last = cycles.calibrated[-1]
                inputs = cycle_inputs(cycles.by_number, json.loads(last.attrs["handover"]),
                                      band, where)
            return inputs.source, inputs.freq_hz
        data, others = contents.calibration_data()
    except (ReceiverError, CalibrationError, OSError, ValueError, KeyError) as err:
        log.info("calibration drift: the previous run's antenna cannot be read: %s", err)
        return None, None
    antenna = others.get(ANTENNA)
    return (antenna, data.freq_hz) if antenna is not None else (None, None)


def previous_solution(run: RunContext, directory: Path | None = None) -> Previous | None:
    """The solution made earlier in this run, else the newest among the runs beside it."""
    if run.solution is not None:
        return Previous(run.solution, None, "earlier in this run")
    own = run.store.directory.resolve()
    parent = own.parent if directory is None else directory
    runs = sorted((p for p in parent.glob("*") if p.is_dir() and p.resolve() != own),
                  reverse=True)
    for path in runs[:RUNS_SEARCHED]:
        target = path / RUN_FILE if (path / RUN_FILE).exists() else path
        if target is path and not (path / "parts").is_dir():
            continue
        try:
            contents = read_run_file(target)
            stored = contents.of_kind("solution")
            solution = contents.solution() if stored else None
        except (ReceiverError, CalibrationError, OSError, ValueError, KeyError):
            continue
        if solution is not None:
            return Previous(solution, stored[-1].timestamp, f"run {path.name}", contents)
    return None


def drift_source(validation: SourceData, previous: Previous, data: CalibrationData) -> SourceData:
    """What the two solutions are compared on (module docstring).

    The antenna if either run measured it on these channels, else this calibration's
    validation source.
    """
    if validation.name == ANTENNA or previous.contents is None:
        return validation
    antenna, freq = antenna_of_run(previous.contents, band_hz(previous.solution))
    if antenna is None or freq is None or freq.shape != data.freq_hz.shape \
            or not np.allclose(freq, data.freq_hz):
        return validation
    return antenna


def threshold_sigma(run: RunContext) -> float:
    """The ``calibration drift`` alarm's threshold: the site's, else the default."""
    for rules in (run.site.monitoring.alarms, DEFAULT_ALARMS):
        for rule in rules:
            if rule.name == DRIFT_ALARM and rule.above is not None:
                return rule.above
    raise AssertionError("the default alarms hold the calibration drift's")


def _when(previous: Previous) -> str:
    if previous.timestamp is None:
        return f"the solution {previous.where}"
    stamp = datetime.fromtimestamp(previous.timestamp, tz=timezone.utc)
    return f"the solution of {stamp:%Y-%m-%d %H:%M} UTC ({previous.where})"


def note(verdict: DriftVerdict, source: str, previous: Previous) -> str:
    """The drift in words: source, size and band, against which solution, joint sigma."""
    lo, hi = verdict.band_hz
    return (f"on {source!r}: {verdict.size_k:+.3g} K ({abs(verdict.size_sigma):.1f} sigma) "
            f"over {lo / 1e6:.1f}-{hi / 1e6:.1f} MHz against {_when(previous)}; "
            f"joint {verdict.sigma:.1f} sigma over {verdict.dof} sub-bands")


def compare_solutions(
    solution: AnySolution, previous: AnySolution, data: CalibrationData, source: SourceData
) -> DriftVerdict | None:
    """``solution`` (made from ``data``) against ``previous`` on ``source`` (module docstring).

    Both calibrate ``source`` with ``data``'s receiver reflection, on the channels both
    cover; ``None`` when the previous solution cannot calibrate them (another band, a
    per-channel solution on other channels).
    """
    lo = max(band_hz(solution)[0], band_hz(previous)[0])
    hi = min(band_hz(solution)[1], band_hz(previous)[1])
    keep = (data.freq_hz >= lo) & (data.freq_hz <= hi)
    if keep.sum() < 2:
        log.info("calibration drift: the previous solution's band does not overlap this one")
        return None
    freq, gamma_rec = data.freq_hz[keep], data.gamma_rec[keep]
    source = source.select(keep)
    try:
        new = solution.calibrate(freq, gamma_rec, source)
        old = previous.calibrate(freq, gamma_rec, source)
    except CalibrationError as err:  # a per-channel solution on other channels
        log.info("calibration drift: the previous solution cannot calibrate this run: %s", err)
        return None
    theta = solution.evaluate(freq)
    # The LNA's noise waves scaled together (its temperature, sim.drift) move the
    # calibrated temperature along their own part of eq. 3.27.
    terms = design_terms(source.gamma, gamma_rec)
    template = terms.x_unc * theta[0] + terms.x_cos * theta[1] + terms.x_sin * theta[2]
    return compare_on_source(new, old, template=template)


def check_drift(
    run: RunContext, solution: AnySolution, data: CalibrationData, validation: SourceData
) -> DriftVerdict | None:
    """Compare ``solution`` (made from ``data``) with the previous one on the antenna.

    The antenna is this run's (``validation``) or the previous run's, else ``validation``
    (:func:`drift_source`). Records the check, logs the verdict and, under ``reachd``,
    hands the monitor its reading; ``None`` when there is nothing to compare with.
    """
    previous = previous_solution(run)
    if previous is None:
        log.info("calibration drift: no previous solution to compare with")
        return None
    source = drift_source(validation, previous, data)
    verdict = compare_solutions(solution, previous.solution, data, source)
    if verdict is None:
        return None
    threshold = threshold_sigma(run)
    drifted = verdict.drifted(threshold)
    words = note(verdict, source.name, previous)
    measured = "this run" if source is validation else previous.where
    details = {**verdict.as_dict(), "threshold_sigma": threshold, "source": source.name,
               "source_measured_in": measured, "previous": previous.where,
               "previous_time": previous.timestamp}
    run.record_check("calibration_drift", not drifted, words, details)
    if drifted:
        log.warning("calibration drift %s (threshold %g sigma)", words, threshold)
    else:
        log.info("calibration drift: none, %s", words)
    if run.watch is not None:
        reading = Reading(DRIFT_METRIC, verdict.sigma, "sigma", run.clock.now(), note=words)
        run.watch.monitor.record([reading], run.watch)
    return verdict
