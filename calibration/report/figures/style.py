"""The one look of every figure: sizes, fonts, colours, units, and how a figure is made.

Figures are :class:`matplotlib.figure.Figure` objects made without :mod:`matplotlib.pyplot`
(no global figure registry, no display, no backend state): they render with Agg when
saved, so the report, a status page and scripts can build them from any thread. Every
builder runs under :func:`styled`, which applies :data:`RC` for the artists it creates.

Sizes are chosen to be read at 100 % on a laptop screen: a full-width figure is
:data:`WIDTH_IN` inches wide at :data:`DPI` dots per inch (1150 pixels), with 10-11 pt text.

Layout is fixed, not searched: :func:`grid` places the axes with margins and gaps in
inches (:class:`Space`) sized for the labels these figures have (tick labels of up to
seven characters, one line of axis label and title), and a legend beside the axes is
measured once (:func:`legend_right`). Matplotlib's constrained layout would find the
same places, but it measures every axes' labels twice per draw plus a draw of its own,
and was two thirds of a report's time.
"""

from __future__ import annotations

import contextlib
import functools
import gc
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ParamSpec

import matplotlib as mpl
import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties
from matplotlib.gridspec import GridSpec
from matplotlib.legend import Legend
from numpy.typing import NDArray

from ...model.noise_waves import PARAMETERS

__all__ = [
    "BAND_ALPHA",
    "DPI",
    "NEUTRAL",
    "PARAMETER_COLOURS",
    "PARAMETER_LABELS",
    "RC",
    "WIDTH_IN",
    "Space",
    "axes_grid",
    "envelope",
    "grid",
    "legend_below",
    "legend_right",
    "mhz",
    "new_figure",
    "note",
    "save_png",
    "source_styles",
    "styled",
    "suptitle",
    "text_width_in",
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
        with mpl.rc_context(RC), collector_paused():  # type: ignore[arg-type]
            return build(*args, **kwargs)

    return wrapper


@contextlib.contextmanager
def collector_paused() -> Iterator[None]:
    """Python's cycle collector off while a figure is built or drawn.

    A figure makes tens of thousands of small objects (ticks, texts, transforms); the
    collector's passes over them, and over everything else a long-running process holds,
    were a tenth of a report's time. The figure's cycles are collected at the next pass
    after it. Process-wide: another thread's work goes without the collector meanwhile
    (a second or so), which costs it nothing but memory it gets back afterwards.
    """
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def new_figure(height_in: float, width_in: float = WIDTH_IN) -> Figure:
    """A figure on an Agg canvas, without a layout engine, not registered anywhere."""
    fig = Figure(figsize=(width_in, height_in), dpi=DPI)
    FigureCanvasAgg(fig)
    return fig


@dataclass(frozen=True)
class Space:
    """Margins around a grid of axes and gaps between its cells, in inches.

    The defaults hold, on the left and between columns, y tick labels of up to seven
    characters and a one-line y label; at the bottom, x tick labels and an x label; at
    the top, a figure title above the axes' titles; between rows, an axes title (the
    rows above share their x axis, their tick labels hidden).
    """

    left: float = 0.85
    right: float = 0.2
    top: float = 0.65
    bottom: float = 0.6
    wspace: float = 0.95
    hspace: float = 0.4


def grid(
    fig: Figure,
    rows: int,
    columns: int,
    space: Space | None = None,
    width_ratios: Sequence[float] | None = None,
) -> GridSpec:
    """A ``rows`` x ``columns`` grid placed by ``space`` (inches, at any figure size)."""
    space = space or Space()
    width, height = fig.get_size_inches()
    inner_w = width - space.left - space.right
    inner_h = height - space.top - space.bottom
    # matplotlib's gaps are fractions of the mean cell: convert the gaps in inches.
    wspace = columns * space.wspace / (inner_w - (columns - 1) * space.wspace)
    hspace = rows * space.hspace / (inner_h - (rows - 1) * space.hspace)
    return fig.add_gridspec(
        rows, columns, left=space.left / width, right=1 - space.right / width,
        bottom=space.bottom / height, top=1 - space.top / height,
        wspace=max(wspace, 0.0), hspace=max(hspace, 0.0), width_ratios=width_ratios,
    )


def axes_grid(
    fig: Figure, n: int, columns: int, sharex: bool = True, space: Space | None = None
) -> tuple[list[Axes], list[Axes]]:
    """``n`` axes in rows of ``columns``; returns (used axes, their bottom-row subset).

    Unused cells are left empty; only the lowest axes of each column get x labels.
    """
    rows = max(1, -(-n // columns))
    spec = grid(fig, rows, columns, space)
    used: list[Axes] = []
    for i in range(n):
        share = used[0] if sharex and used else None
        used.append(fig.add_subplot(spec[i // columns, i % columns], sharex=share))
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


def legend_below(fig: Figure, handles: Sequence[Any], labels: Sequence[str],
                 columns: int) -> Legend:
    """One legend for the whole figure, one row along its bottom edge (below the axes).

    The grid's bottom margin must hold it: :data:`LEGEND_ROW_IN` more than the x labels.
    """
    return fig.legend(handles, labels, loc="lower center", ncols=columns,
                      bbox_to_anchor=(0.5, 0.0), borderaxespad=0.2)


#: The height of one row of a legend below the axes (inches).
LEGEND_ROW_IN = 0.35


def legend_right(fig: Figure, spec: GridSpec, handles: Sequence[Any] | None = None,
                 labels: Sequence[str] | None = None, pad_in: float = 0.15) -> Legend:
    """One legend for the whole figure to the right of ``spec``'s axes (never over data).

    The legend is measured (its labels' text only, not the axes) and the grid's right
    edge moved to leave it room: labels of any length fit.
    """
    if handles is None or labels is None:
        handles, labels = fig.axes[0].get_legend_handles_labels()
    legend = fig.legend(handles, labels, loc="center right", bbox_to_anchor=(1.0, 0.5),
                        borderaxespad=0.2)
    width_px = legend.get_window_extent(fig.canvas.get_renderer()).width  # type: ignore[attr-defined]
    figure_w = fig.get_size_inches()[0]
    params = spec.get_subplot_params(fig)
    columns = spec.ncols
    inner = (params.right - params.left) * figure_w
    gap = params.wspace * inner / (columns + params.wspace * (columns - 1))  # inches
    right = 1 - (width_px / fig.dpi + pad_in) / figure_w
    inner = (right - params.left) * figure_w
    spec.update(right=right, wspace=columns * gap / (inner - (columns - 1) * gap))
    for ax in fig.axes:  # update() moves the axes of pyplot's figures only
        cell = ax.get_subplotspec()
        if cell is not None and cell.get_gridspec() is spec:
            ax.set_position(cell.get_position(fig))
    return legend


def text_width_in(fig: Figure, texts: Iterable[str], size: float) -> float:
    """The width of the widest of ``texts`` at ``size`` points on ``fig`` (inches)."""
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    prop = FontProperties(size=size)
    widths = [renderer.get_text_width_height_descent(t, prop, ismath=False)[0] for t in texts]
    return max(widths, default=0.0) / fig.dpi


def suptitle(fig: Figure, text: str) -> None:
    """The figure's bold title, its top :data:`TITLE_TOP_IN` below the figure's top edge."""
    fig.suptitle(text, fontweight="bold", y=1 - TITLE_TOP_IN / fig.get_size_inches()[1],
                 va="top")


#: The figure title's distance from the top edge (inches).
TITLE_TOP_IN = 0.08


def save_png(fig: Figure, path: str | Path) -> Path:
    """Render ``fig`` to a PNG with Agg at :data:`DPI`; returns the path."""
    out = Path(path)
    with collector_paused():  # zlib level 3: a third less time than 6, files 4 % larger
        fig.savefig(out, format="png", dpi=DPI, pil_kwargs={"compress_level": 3})
    return out
