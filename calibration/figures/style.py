"""The one look of every figure: sizes, fonts, colours, units, and how a figure is made.

Figures are :class:`matplotlib.figure.Figure` objects made without :mod:`matplotlib.pyplot`
(no global figure registry, no display, no backend state): they render with Agg when
saved, so the report, a status page and scripts can build them from any thread. Every
builder runs under :func:`styled`, which applies :data:`RC` for the artists it creates.

Sizes are chosen to be read at 100 % on a laptop screen: a full-width figure is
:data:`WIDTH_IN` inches wide at :data:`DPI` dots per inch (1150 pixels), with 10-11 pt text.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, ParamSpec

import matplotlib as mpl
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

from ..noise_waves import PARAMETERS

__all__ = [
    "BAND_ALPHA",
    "DPI",
    "NEUTRAL",
    "PARAMETER_COLOURS",
    "PARAMETER_LABELS",
    "RC",
    "WIDTH_IN",
    "axes_grid",
    "envelope",
    "legend_outside",
    "mhz",
    "new_figure",
    "note",
    "save_png",
    "source_styles",
    "styled",
]

P = ParamSpec("P")

WIDTH_IN = 11.5
DPI = 100
#: A full-width figure's width in pixels.
WIDTH_PX = int(WIDTH_IN * DPI)

RC: dict[str, Any] = {
    "font.size": 10,
    "axes.titlesize": 10.5,
    "axes.titleweight": "bold",
    # Titles at the top of the axes, as matplotlib places them when no tick labels are on
    # top (none are, in these figures): the same pixels, without the search for top
    # labels that costs a fifth of a many-panel figure's drawing.
    "axes.titley": 1.0,
    "axes.labelsize": 10,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "grid.linewidth": 0.6,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "legend.fontsize": 9,
    "legend.frameon": False,
    "xtick.labelsize": 9,
    "ytick.labelsize": 9,
    "lines.linewidth": 1.2,
    "axes.formatter.useoffset": False,
    "axes.formatter.limits": (-4, 5),
    "figure.dpi": DPI,
    "savefig.dpi": DPI,
}

#: Axis labels of the noise-wave parameters, with their unit.
PARAMETER_LABELS = {
    "unc": r"$T_\mathrm{unc}$",
    "cos": r"$T_\mathrm{cos}$",
    "sin": r"$T_\mathrm{sin}$",
    "NS": r"$T_\mathrm{NS}$",
    "L": r"$T_\mathrm{L}$",
}
#: One colour per noise-wave parameter, in every figure.
PARAMETER_COLOURS = dict(zip(PARAMETERS, ("C0", "C1", "C2", "C3", "C4"), strict=True))
#: The colour of data without a source (the receiver's LNA, a whole run).
NEUTRAL = "0.25"
#: Shading of the 68 % and 95 % bands.
BAND_ALPHA = (0.45, 0.2)


def styled(build: Callable[P, Figure]) -> Callable[P, Figure]:
    """Run a figure builder under :data:`RC` (the style applies to artists made inside)."""

    @functools.wraps(build)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> Figure:
        with mpl.rc_context(RC):  # type: ignore[arg-type]
            return build(*args, **kwargs)

    return wrapper


def new_figure(height_in: float, width_in: float = WIDTH_IN) -> Figure:
    """A figure with constrained layout (labels never overlap), not registered anywhere."""
    return Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")


def axes_grid(
    fig: Figure, n: int, columns: int, sharex: bool = True
) -> tuple[list[Axes], list[Axes]]:
    """``n`` axes in rows of ``columns``; returns (used axes, their bottom-row subset).

    Unused cells are removed; only the lowest axes of each column get x labels.
    """
    rows = max(1, -(-n // columns))
    grid = fig.subplots(rows, columns, sharex=sharex, squeeze=False).ravel()
    used = list(grid[:n])
    for ax in grid[n:]:
        ax.remove()
    bottom = [ax for i, ax in enumerate(used) if i + columns >= n]
    for ax in used:
        ax.tick_params(labelbottom=ax in bottom)
    return used, bottom


def mhz(freq_hz: NDArray[np.float64]) -> NDArray[np.float64]:
    """Frequencies in MHz, the unit of every frequency axis."""
    return np.asarray(freq_hz, dtype=float) / 1e6


def envelope(
    x: NDArray[np.float64], y: NDArray[np.float64], pixels: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A line of many points reduced to what ``pixels`` columns can show.

    The points are cut into runs of consecutive samples, two per pixel column, and each
    run keeps its lowest and highest point in their order: the drawn line covers the same
    pixels as the full one (a noisy spectrum keeps its scatter, a spike its peak), at four
    points per column. Lines with fewer than three points per column are returned
    as they are. Drawing time in matplotlib grows with the points, not with the pixels.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    per = y.size // max(2 * int(pixels), 1)
    if per < 3 or y.ndim != 1:
        return x, y
    runs = y.size // per
    block = y[: runs * per].reshape(runs, per)
    nan = np.isnan(block)
    lo = np.where(nan, np.inf, block).argmin(axis=1)  # an all-NaN run keeps a NaN: a gap
    hi = np.where(nan, -np.inf, block).argmax(axis=1)
    start = np.arange(runs) * per
    index = np.stack([np.minimum(lo, hi), np.maximum(lo, hi)], axis=1) + start[:, None]
    index = np.concatenate([index.ravel(), np.arange(runs * per, y.size)])
    return x[index], y[index]


def source_styles(names: Iterable[str]) -> dict[str, dict[str, Any]]:
    """Line colour and style per source, in the order given.

    The ten strong colours of tab10 solid, then again dashed, then dotted: pale colours
    do not read on a screen.
    """
    dashes = ("-", "--", ":")
    return {
        name: {"color": f"C{i % 10}", "ls": dashes[(i // 10) % len(dashes)]}
        for i, name in enumerate(names)
    }


def note(ax: Axes, text: str) -> None:
    """Write ``text`` in the middle of an empty axes (a figure that has nothing to show)."""
    ax.set_axis_off()
    ax.text(0.5, 0.5, text, ha="center", va="center", wrap=True, fontsize=12,
            transform=ax.transAxes)


def legend_outside(fig: Figure, axes: Sequence[Axes], columns: int = 1) -> None:
    """One legend for the whole figure, to the right of the axes (never over data)."""
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside right center", ncols=columns)


def save_png(fig: Figure, path: str | Path) -> Path:
    """Render ``fig`` to a PNG with Agg at :data:`DPI`; returns the path."""
    out = Path(path)
    fig.savefig(out, format="png", dpi=DPI)
    return out
