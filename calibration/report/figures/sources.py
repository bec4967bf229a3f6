"""Calibrated sources against their known temperatures (thesis figs. 4.13-4.15).

Each panel is one source calibrated with the solution: its residual (calibrated minus
known temperature, K) per channel and binned, against the predicted ±1 sigma of its own
radiometer noise (``CalibratedSpectrum.std_measurement``, shaded) and of the calibration
(``std_calibration``, dashed), and where the averaged models disagree the part of the
latter that is their spread (``std_model_choice``, dotted). A source without a known
temperature (an antenna) shows its calibrated temperature with its total ±1 sigma instead.
The title gives the residual's RMS over the RMS of the predicted total sigma: about 1 when
the error bars are honest.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

from ...solve.solution import CalibratedSpectrum
from .style import (
    LEGEND_ROW_IN,
    NEUTRAL,
    WIDTH_PX,
    Space,
    axes_grid,
    envelope,
    legend_below,
    mhz,
    new_figure,
    note,
    styled,
    suptitle,
)

FloatArray = NDArray[np.float64]

#: Bins of the binned residual across the band.
BINS = 48
#: A source's spread between the averaged models is drawn where it is at least this share
#: of its calibration variance (:attr:`CalibratedSpectrum.model_choice_share`).
SHOWN_CHOICE_SHARE = 0.05
#: Panel titles: normal weight, to fit a quarter of the width.
TITLE: dict[str, Any] = {"fontsize": 10, "fontweight": "normal"}


def rms(values: FloatArray) -> float:
    """Root mean square."""
    return float(np.sqrt(np.mean(np.square(values))))


def binned(x: FloatArray, y: FloatArray, bins: int = BINS) -> tuple[FloatArray, FloatArray]:
    """Means of ``x`` and ``y`` over ``bins`` runs of consecutive channels."""
    n = max(1, x.size // bins)
    usable = (x.size // n) * n
    return x[:usable].reshape(-1, n).mean(axis=1), y[:usable].reshape(-1, n).mean(axis=1)


def _residual_panel(
    ax: Axes, name: str, spectrum: CalibratedSpectrum, reference: FloatArray, pixels: int
) -> None:
    x = mhz(spectrum.freq_hz)
    residual = spectrum.mean - reference
    meas, cal = spectrum.std_measurement, spectrum.std_calibration
    ax.plot(*envelope(x, residual, pixels), color="C0", lw=0.5, alpha=0.5,
            label="residual per channel")
    bx, by = binned(x, residual)
    ax.plot(bx, by, color=NEUTRAL, lw=1.3, label=f"residual, {x.size // bx.size}-channel bins")
    choice, shown = spectrum.std_model_choice, spectrum.model_choice_share >= SHOWN_CHOICE_SHARE
    for sign in (1, -1):
        ax.plot(*envelope(x, sign * meas, pixels), color="C1", lw=1.3,
                label="radiometer noise ±1σ" if sign > 0 else None)
        ax.plot(*envelope(x, sign * cal, pixels), color="k", ls="--", lw=0.9,
                label="calibration ±1σ" if sign > 0 else None)
        if shown:
            ax.plot(*envelope(x, sign * choice, pixels), color="C3",
                    ls=":", lw=1.5, label="of which the choice of model" if sign > 0 else None)
    ratio = rms(residual) / rms(spectrum.std)
    ax.set_title(f"{name}: {rms(residual) * 1e3:.3g} mK RMS = {ratio:.2f} σ", **TITLE)
    limit = 4 * max(float(np.max(meas)), float(np.max(np.abs(by))), 1e-9)
    ax.set_ylim(-limit, limit)


def _temperature_panel(ax: Axes, name: str, spectrum: CalibratedSpectrum, pixels: int) -> None:
    x = mhz(spectrum.freq_hz)
    step = max(1, x.size // (2 * pixels))  # the band is smooth: every step-th channel
    lo, hi = spectrum.mean - spectrum.std, spectrum.mean + spectrum.std
    ax.fill_between(x[::step], lo[::step], hi[::step], color="0.8", lw=0, label="total ±1σ")
    ax.plot(*envelope(x, spectrum.mean, pixels), color="C0", lw=0.6)
    ax.set_title(f"{name}: calibrated T (no reference)", **TITLE)


@styled
def calibrated_sources(
    spectra: Mapping[str, CalibratedSpectrum],
    references: Mapping[str, FloatArray] | None = None,
    columns: int = 4,
) -> Figure:
    """One panel per calibrated source: residual against ``references[name]`` (K).

    ``references`` holds the known temperature of each source that has one (calibrators:
    their measured physical temperature; a simulation's antenna: its true temperature).
    """
    references = references or {}
    n = len(spectra)
    columns = max(1, min(columns, n))
    rows = max(1, -(-n // columns))
    fig = new_figure(1.2 + 1.9 * rows)
    if not spectra:
        note(fig.add_subplot(), "no calibrated source to show")
        return fig
    # Room between the rows for the panels' titles, and below for a legend.
    space = Space(bottom=0.6 + LEGEND_ROW_IN, wspace=0.85, hspace=0.42)
    axes, bottom = axes_grid(fig, n, columns, space=space)
    pixels = WIDTH_PX // columns
    for i, (ax, (name, spectrum)) in enumerate(zip(axes, spectra.items(), strict=True)):
        reference = references.get(name)
        if reference is None:
            _temperature_panel(ax, name, spectrum, pixels)
            ax.set_ylabel("T (K)")
        else:
            _residual_panel(ax, name, spectrum, np.asarray(reference, float), pixels)
            if i % columns == 0:
                ax.set_ylabel("calibrated − known (K)")
    for ax in bottom:
        ax.set_xlabel("frequency (MHz)")
    with_reference = [ax for ax, name in zip(axes, spectra, strict=True) if name in references]
    if with_reference:
        entries: dict[str, Any] = {}  # every panel's, once: the choice of model is not in all
        for ax in with_reference:
            for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
                entries.setdefault(label, handle)
        legend_below(fig, list(entries.values()), list(entries), columns=len(entries))
    suptitle(
        fig, "Calibrated sources: residual against the known temperature, and the predicted noise"
    )
    return fig
