"""The adaptive calibration's course: the antenna's predicted error against instrument time.

Each decision of the adaptive step (:mod:`calibration.design.adaptive`) states the antenna's
predicted calibration error ``sqrt(V)``, ``V = tr(C A)`` over the band of interest
(docs/adaptive.md; thesis eqs. 3.36, 3.41), after the instrument time spent so far; the
figure draws it (on a logarithmic scale where it falls more than threefold) with the
target and the budget, and names the calibrator each decision chose (by colour).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FormatStrFormatter, LogLocator

from .style import NEUTRAL, Space, grid, legend_right, new_figure, note, source_styles, styled

#: The radiometer equation's slope: an error falling as 1/sqrt(time), for the eye.
_SLOPE = -0.5


@styled
def adaptive_course(decisions: Sequence[Mapping[str, Any]]) -> Figure:
    """Predicted antenna error (mK) against instrument time (h), one point per decision."""
    fig = new_figure(4.2)
    if not decisions:
        note(fig.add_subplot(), "this run has no adaptive calibration")
        return fig
    hours = np.array([float(d["elapsed_s"]) for d in decisions]) / 3600.0
    mk = np.array([float(d["predicted_mk"]) for d in decisions])
    chosen = [(d.get("choice") or {}).get("source") for d in decisions]
    names = list(dict.fromkeys(c for c in chosen if c))
    styles = source_styles(names)
    spec = grid(fig, 1, 1, Space(left=0.9, top=0.45))
    ax = fig.add_subplot(spec[0, 0])
    ax.plot(hours, mk, color=NEUTRAL, lw=1.0, zorder=1)
    for name in names:
        at = [i for i, c in enumerate(chosen) if c == name]
        ax.scatter(hours[at], mk[at], s=28, color=styles[name]["color"], zorder=2, label=name)
    stop = decisions[-1]
    ax.scatter(hours[-1:], mk[-1:], s=60, marker="*", color="k", zorder=3, label="stop")
    if hours.size > 1 and hours[0] > 0:
        t = np.linspace(hours[0], hours[-1], 50)
        ax.plot(t, mk[0] * (t / hours[0]) ** _SLOPE, ls=":", color="0.6", lw=0.9,
                label=r"$\propto t^{-1/2}$ from the first")
    target = stop.get("target_mk")
    if target is not None:
        ax.axhline(float(target), color="C2", ls="--", lw=1.0, label=f"target {target:g} mK")
    ax.axvspan(0.0, hours[0], color="0.9", zorder=0, label="first pass")
    budget_h = float(stop.get("budget_s") or np.inf) / 3600.0
    if budget_h <= 1.3 * hours[-1]:  # else it would squeeze the decisions to one side
        ax.axvline(budget_h, color="C3", ls="--", lw=1.0, label=f"budget {budget_h:.3g} h")
    ax.set_xlim(0.0, None)
    if mk.max() > 3 * mk.min():  # a logarithmic axis only where it spans a factor
        ax.set_yscale("log")
        ax.yaxis.set_minor_locator(LogLocator(subs="all"))
        ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.yaxis.set_minor_formatter(FormatStrFormatter("%g"))
    ax.set_xlabel("instrument time (h, switching included)")
    ax.set_ylabel("antenna's predicted error (mK)")
    reason = stop.get("stop_reason") or "running"
    ax.set_title(
        f"Adaptive calibration: {len(decisions)} decisions, {mk[-1]:.3g} mK after "
        f"{hours[-1]:.2f} h (stop: {reason}; budget {budget_h:.3g} h)"
    )
    legend_right(fig, spec)
    return fig
