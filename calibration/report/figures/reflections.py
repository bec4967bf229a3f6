"""Reflection coefficients of the calibrators, the antenna and the receiver (thesis fig. 2.10).

Left, the Smith chart (the complex plane of Gamma, with the grid of constant normalised
resistance and reactance, ``Gamma = (z - 1) / (z + 1)``), each source's trace over the
band with a dot at its lowest frequency; right, ``|Gamma|`` in dB against frequency.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

from ...model.data import CalibrationData, SourceData
from .style import (
    NEUTRAL,
    WIDTH_PX,
    Space,
    envelope,
    grid,
    legend_right,
    mhz,
    new_figure,
    source_styles,
    styled,
    suptitle,
)

ComplexArray = NDArray[np.complex128]

#: Normalised resistances and reactances of the chart's grid.
GRID_VALUES = (0.2, 0.5, 1.0, 2.0, 5.0)
#: The receiver's trace is labelled so.
RECEIVER = "receiver (LNA)"
#: A Smith chart (no tick labels) beside a plot in dB: little room left of the chart.
SMITH_SPACE = Space(left=0.2, wspace=0.9)


def _gamma(z: NDArray[Any]) -> ComplexArray:
    return np.asarray((z - 1) / (z + 1), dtype=complex)


def smith_grid(ax: Axes) -> None:
    """Draw the unit circle and the constant-r circles and constant-x arcs on ``ax``."""
    sweep = np.concatenate([-np.logspace(3, -3, 300), np.logspace(-3, 3, 300)])
    style: dict[str, Any] = {"color": "0.75", "lw": 0.6, "zorder": 0}
    unit = np.exp(1j * np.linspace(0, 2 * np.pi, 400))
    ax.plot(unit.real, unit.imag, color="0.4", lw=0.9, zorder=0)
    ax.plot([-1, 1], [0, 0], **style)
    for value in GRID_VALUES:
        circle = _gamma(value + 1j * sweep)
        ax.plot(circle.real, circle.imag, **style)
        ax.text(value / (1 + value) - 1 / (1 + value), 0.02, f"{value:g}", fontsize=7,
                color="0.45", ha="right", va="bottom")
        for sign in (1, -1):
            arc = _gamma(np.logspace(-3, 3, 300) + 1j * sign * value)
            ax.plot(arc.real, arc.imag, **style)
    ax.set_aspect("equal")
    ax.set_xlim(-1.05, 1.05)
    ax.set_ylim(-1.05, 1.05)
    ax.grid(False)
    for side in ("left", "bottom"):
        ax.spines[side].set_visible(False)
    ax.set_xticks([])
    ax.set_yticks([])


@styled
def reflections(
    data: CalibrationData, others: Mapping[str, SourceData] | None = None
) -> Figure:
    """The run's reflection coefficients: Smith chart and ``|Gamma|`` in dB.

    ``others`` are the sources that are not calibrators (e.g. the antenna ``ant``).
    """
    sources = {**data.sources, **dict(others or {})}
    traces = {name: src.gamma for name, src in sources.items()}
    traces[RECEIVER] = data.gamma_rec
    styles = source_styles(sources)
    styles[RECEIVER] = {"color": NEUTRAL, "ls": "-."}
    fig = new_figure(5.4)
    spec = grid(fig, 1, 2, SMITH_SPACE, width_ratios=(1, 1.25))
    smith, db = fig.add_subplot(spec[0, 0]), fig.add_subplot(spec[0, 1])
    smith_grid(smith)
    x = mhz(data.freq_hz)
    for name, gamma in traces.items():
        style = styles[name]
        smith.plot(gamma.real, gamma.imag, lw=1.1, **style)
        smith.plot(gamma.real[0], gamma.imag[0], "o", color=style["color"], ms=4)
        level = 20 * np.log10(np.maximum(np.abs(gamma), 1e-12))
        db.plot(*envelope(x, level, WIDTH_PX // 2), label=name, **style)
    smith.set_title(f"Smith chart ({x[0]:.0f}-{x[-1]:.0f} MHz, ● at {x[0]:.0f} MHz)")
    db.set_xlabel("frequency (MHz)")
    db.set_ylabel("|Γ| (dB)")
    db.set_title("reflection magnitude")
    legend_right(fig, spec, *db.get_legend_handles_labels())
    suptitle(fig, "Reflection coefficients of the sources and the receiver")
    return fig
