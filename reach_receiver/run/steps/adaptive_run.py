"""The ``calibrate_adaptive`` step's execution: measure, hand over, decide, store, repeat.

The planner (:class:`calibration.design.adaptive.AdaptivePlanner`) sees the run's
hand-over (:meth:`reach_receiver.store.RunStore.engine_view`, every Dicke cycle of each
source so far) restricted to the step's calibrators, and the antenna's latest calibrated
reflection on the same channels. Each decision is stored as an ``adaptive_decision``
check (its details the decision's record) before its measurement starts, so that a run
killed mid-cycle keeps every decision it acted on.
"""

from __future__ import annotations

import dataclasses
import json
import logging
from typing import TYPE_CHECKING, Any

import h5py
import numpy as np
from numpy.typing import NDArray

from calibration.design.adaptive import (
    POSITIONS,
    AdaptivePlanner,
    AdaptiveSettings,
    Decision,
)
from calibration.io.run_records import ADAPTIVE_DECISION
from calibration.model.data import CalibrationData
from reach_receiver.store.handover import RECEIVER, interpolate_s11
from reach_receiver.store.parts import as_str

from ..context import CheckFailed, RunContext
from .spectra import dicke_cycle

if TYPE_CHECKING:
    from .adaptive import CalibrateAdaptive

log = logging.getLogger(__name__)

#: The name of the checks that hold the step's decisions in the run file.
DECISION_CHECK = ADAPTIVE_DECISION


def decision_line(step: int, decision: Decision, target_mk: float | None) -> str:
    """One decision in at most 80 columns: its step, the predicted error, choice or stop."""
    goal = f" (target {target_mk:g})" if target_mk is not None else ""
    head = f"adaptive {step}: {decision.predicted_mk:.2f} mK{goal}"
    if decision.choice is None:
        return f"{head}, stop: {decision.stop_reason}"[:80]
    c = decision.choice
    return f"{head} -> {c.source} {c.seconds:g} s, {c.predicted_mk:.2f} mK"[:80]


def _stored(run: RunContext, kind: str) -> list[tuple[int, str, dict[str, Any]]]:
    """(number, name, attributes) of the stored records of ``kind``."""
    out = []
    for record in run.store.records(kind):
        with h5py.File(record.file, "r") as f:
            g = f[record.group]
            out.append((record.sequence, record.name, {k: g.attrs[k] for k in g.attrs}))
    return out


def _previous_decisions(run: RunContext, where: str) -> list[tuple[int, dict[str, Any]]]:
    """The stored decisions of the interrupted run of the step at ``where`` (carried copies).

    Those of an earlier run of it that stopped (a ``repeat``'s repetitions) are left out.
    """
    found: list[tuple[int, dict[str, Any]]] = []
    for number, name, attrs in _stored(run, "check"):
        if name != DECISION_CHECK:
            continue
        details = json.loads(as_str(attrs.get("details", "{}")))
        if details.get("where") != where:
            continue
        if found and found[-1][1].get("choice") is None:
            found = []
        found.append((number, details))
    return found


def _antenna_s11(run: RunContext, antenna: str, freq_hz: NDArray[Any]) -> NDArray[np.complex128]:
    """The antenna's latest calibrated S11 on ``freq_hz`` (the hand-over's splines)."""
    latest = None
    for record in run.store.records("s11"):
        if record.name == antenna:
            with h5py.File(record.file, "r") as f:
                g = f[record.group]
                if bool(g.attrs["calibrated"]):
                    latest = (g["frequencies"][()], g["s11"][()])
    if latest is None:
        raise CheckFailed(
            f"calibrate_adaptive needs {antenna}'s S11: add {antenna!r} to an s11 step before it"
        )
    gamma = interpolate_s11(latest[0], latest[1], freq_hz)
    if gamma is None:
        raise CheckFailed(f"{antenna}'s S11 does not cover the calibration band; sweep it wider")
    return gamma


def _check_reflections(run: RunContext, step: CalibrateAdaptive) -> None:
    """Before anything moves: the receiver, every calibrator and the antenna have an S11."""
    have = {r.name for r in run.store.records("s11")}
    missing = [n for n in (RECEIVER, *step.sources, step.antenna) if n not in have]
    if missing:
        raise CheckFailed(
            f"calibrate_adaptive needs the S11 of {', '.join(missing)}: "
            "add them to an s11 step before it"
        )


def _data(run: RunContext, step: CalibrateAdaptive) -> CalibrationData:
    """The hand-over of the run so far, restricted to the step's calibrators."""
    view = run.store.engine_view(run.site.band_hz)
    data = view.data
    have = set() if data is None else set(data.sources)
    missing = [n for n in step.sources if n not in have]
    if data is None or missing:
        why = "; ".join(view.handover.warnings)
        raise CheckFailed(
            f"the hand-over lacks calibrators {', '.join(missing) or step.sources}"
            + (f" ({why})" if why else "")
        )
    return dataclasses.replace(data, sources={n: data.sources[n] for n in step.sources})


def settings_of(
    step: CalibrateAdaptive, period_s: float, site_band_hz: tuple[float, float] | None = None
) -> AdaptiveSettings:
    """The planner's settings from the step (the step's overhead or the site's timing).

    The band of interest is the step's, else ``site_band_hz`` (the site's
    ``calibration.band_of_interest_hz``), else the whole calibration band.
    """
    return AdaptiveSettings(
        target_mk=step.target_mk,
        budget_s=step.budget_s,
        first_pass_s=step.first_pass_s,
        durations_s=step.durations_s,
        overhead_s=step.overhead(period_s),
        refresh_every=step.refresh_every,
        band_hz=step.band_hz or site_band_hz,
        antenna_temperature_k=step.antenna_k,
        antenna_index=step.antenna_index,
    )


def run_adaptive(step: CalibrateAdaptive, run: RunContext) -> None:
    """The first pass, then decisions and their cycles until a stop (stored and logged)."""
    _check_reflections(run, step)
    where = str(step.where)
    settings = settings_of(step, run.period_s, run.site.band_of_interest_hz)
    previous = _previous_decisions(run, where) if step.resumed else []
    elapsed = 0.0
    if previous:  # resumed: the instrument time goes on from the last decision
        number, last = previous[-1]
        if last.get("choice") is None:
            return
        elapsed = float(last["elapsed_s"])
        chosen = last["choice"]["source"]
        if any(n > number and name == chosen for n, name, _ in _stored(run, "dicke")):
            elapsed += settings.cost_s(float(last["choice"]["seconds"]))
    offset = len(previous)

    overheads: list[float] = []  # each cycle's clock time beyond its 3 t of integration

    def measure(source: str, seconds: float, label: str) -> None:
        nonlocal elapsed
        start = run.clock.now()
        dicke_cycle(run, source, seconds, label)
        took = run.clock.now() - start
        elapsed += took
        overheads.append(max(took - POSITIONS * seconds, 0.0))

    measured = {name for _, name, _ in _stored(run, "dicke")}
    todo = [s for s in step.sources if s not in measured]
    for index, source in enumerate(todo):
        measure(source, step.first_pass_s, f"first pass {index + 1}/{len(todo)}")
    data = _data(run, step)
    planner = AdaptivePlanner(settings, _antenna_s11(run, step.antenna, data.freq_hz))
    target = step.target_mk
    if step.target_fraction is not None:  # relative to the first pass (or to a resumed start)
        target = previous[0][1].get("target_mk") if previous else None
        if target is None:
            target = step.target_fraction * planner.predict_mk(data)
        planner.settings = dataclasses.replace(planner.settings, target_mk=target)
    while True:
        run.stop.check()
        if step.overhead_s is None and overheads:  # the instrument's own, as measured
            planner.settings = dataclasses.replace(
                planner.settings, overhead_s=float(np.median(overheads))
            )
        k = offset + len(planner.decisions)
        left = max(step.budget_s - elapsed, 0.0)
        run.progress.update(f"adaptive {k}: choosing", int(elapsed), int(step.budget_s), left)
        decision = planner.decide(data, elapsed)
        record = {**decision.as_record(), "step": k, "where": where, "target_mk": target,
                  "budget_s": step.budget_s, "overhead_s": planner.settings.overhead_s}
        run.store.add_check(DECISION_CHECK, True, timestamp=run.clock.now(), details=record)
        log.info("%s", decision_line(k, decision, target))
        if decision.choice is None:
            return
        c = decision.choice
        measure(c.source, c.seconds, f"adaptive {k}, {decision.predicted_mk:.1f} mK")
        data = _data(run, step)
