"""Figures of a run's raw material: Dicke powers, flagged channels, thermocouple readings.

* :func:`dicke_powers`: each source's three Dicke spectra (source, load, noise source;
  the spectrometer's arbitrary power unit) and the ``Q`` they give (eq. 3.9);
* :func:`flagged_channels`: which channels are flagged, per spectrum (a run without
  flags says so);
* :func:`temperatures`: every thermocouple channel against time.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from ...io.run_records import TemperatureLog
from ...model.data import CalibrationData, SourceData
from .style import (
    RC,
    WIDTH_PX,
    Space,
    axes_grid,
    envelope,
    grid,
    legend_right,
    mhz,
    new_figure,
    note,
    source_styles,
    styled,
    suptitle,
    text_width_in,
)

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
Flags = BoolArray | Mapping[str, BoolArray | tuple[FloatArray, BoolArray]]

Q_DEFINITION = (
    r"$Q = (P_\mathrm{source} - P_\mathrm{load})\,/\,(P_\mathrm{NS} - P_\mathrm{load})$"
)
#: What a power panel of a run without measured powers says.
NO_POWERS = (
    "no measured powers: imported run\n(the run file holds Q only; power_spectra = placeholder)"
)
_POSITIONS = (
    ("p_source", r"$P_\mathrm{source}$", "on the source"),
    ("p_load", r"$P_\mathrm{load}$", "on the reference load"),
    ("p_ns", r"$P_\mathrm{NS}$", "on the noise source"),
)


def _spread(sources: Mapping[str, SourceData], attr: str) -> float:
    """Largest relative difference between the sources' spectra of one Dicke position."""
    stack = np.stack([getattr(src, attr) for src in sources.values()])
    return float(np.max((stack.max(axis=0) - stack.min(axis=0)) / np.abs(stack.mean(axis=0))))


@styled
def dicke_powers(
    data: CalibrationData,
    others: Mapping[str, SourceData] | None = None,
    placeholder: bool = False,
) -> Figure:
    """The three Dicke spectra of every source and their ``Q``, against frequency.

    ``placeholder``: the run's spectra are stand-ins carrying only ``Q`` (an import's,
    run-file attribute ``power_spectra = "placeholder"``,
    :func:`calibration.io.hdf5_io.run_power_spectra`): the power panels say "no measured
    powers" instead of drawing them, and ``Q`` is drawn as imported.
    """
    sources = {**data.sources, **dict(others or {})}
    styles = source_styles(sources)
    fig = new_figure(7.0)
    spec = grid(fig, 2, 2)
    axes = [fig.add_subplot(spec[0, 0])]
    axes += [fig.add_subplot(spec[i // 2, i % 2], sharex=axes[0]) for i in range(1, 4)]
    bottom = axes[2:]
    for ax in axes[:2]:
        ax.tick_params(labelbottom=False)
    x = mhz(data.freq_hz)
    for name, src in sources.items():
        if not placeholder:
            for ax, (attr, _, _) in zip(axes, _POSITIONS, strict=False):
                ax.plot(*envelope(x, getattr(src, attr), WIDTH_PX // 2), lw=0.8, label=name,
                        **styles[name])
        axes[3].plot(*envelope(x, src.q, WIDTH_PX // 2), lw=0.8, label=name, **styles[name])
    for ax, (attr, label, title) in zip(axes, _POSITIONS, strict=False):
        if placeholder:
            ax.set_title(f"{label}: switch {title}")
            ax.text(0.5, 0.5, NO_POWERS, ha="center", va="center", fontsize=11,
                    transform=ax.transAxes, color="0.3")
            ax.set_yticks([])
            continue
        ax.set_ylabel(f"{label} (arbitrary power)")
        ax.set_title(f"{label}: switch {title}")
        if attr != "p_source":  # the same for every source but for the noise
            ax.set_title(f"{label}: {title} (sources differ by {_spread(sources, attr):.2%})")
    axes[3].set_ylabel("Q (eq. 3.9)")
    axes[3].set_title(Q_DEFINITION + (" as imported" if placeholder else ""))
    for ax in bottom:
        ax.set_xlabel("frequency (MHz)")
    legend_right(fig, spec, *axes[3].get_legend_handles_labels())
    suptitle(fig, "Dicke powers of the run" + (": none measured (imported run)" if placeholder
                                                else ""))
    return fig


def _rows(freq_hz: FloatArray, flags: Flags) -> dict[str, tuple[FloatArray, BoolArray]]:
    if not isinstance(flags, Mapping):
        flags = {"run": flags}
    out: dict[str, tuple[FloatArray, BoolArray]] = {}
    for name, value in flags.items():
        freq, mask = value if isinstance(value, tuple) else (freq_hz, value)
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != np.shape(freq):
            raise ValueError(f"flags of {name!r}: {mask.shape} for {np.shape(freq)} channels")
        out[name] = (np.asarray(freq, dtype=float), mask)
    return out


@styled
def flagged_channels(freq_hz: FloatArray, flags: Flags | None = None) -> Figure:
    """Flagged channels (``True`` = flagged) per spectrum, against frequency.

    ``flags`` is one mask over ``freq_hz``, or masks by name, each over ``freq_hz`` or
    with its own frequencies ``(freq_hz, mask)``; ``None`` (a run without flags) gives a
    figure that says so.
    """
    rows = _rows(np.asarray(freq_hz, dtype=float), flags) if flags is not None else {}
    fig = new_figure(1.6 + 0.35 * max(len(rows), 2))
    if not rows:
        text = "this run has no channel flags\n(no RFI flagging was stored with it)"
        note(fig.add_subplot(), text)
        return fig
    labels = [f"{name}: {np.count_nonzero(m)} ({np.mean(m):.2%})" for name, (_, m) in rows.items()]
    # The y tick labels name the spectra, of any length: the left margin is measured.
    left = text_width_in(fig, labels, RC["ytick.labelsize"]) + 0.25
    ax = fig.add_subplot(grid(fig, 1, 1, Space(left=left, top=0.4))[0, 0])
    for i, (freq, mask) in enumerate(rows.values()):
        x = mhz(freq)
        width = float(np.median(np.diff(x))) if x.size > 1 else 0.01
        flagged = x[mask]
        ax.broken_barh([(f - width / 2, width) for f in flagged], (i - 0.4, 0.8), color="C3")
    ax.set_yticks(range(len(rows)), labels)
    ax.set_ylim(len(rows) - 0.5, -0.5)
    band = mhz(np.asarray(freq_hz, dtype=float))
    ax.set_xlim(float(band[0]), float(band[-1]))
    ax.set_xlabel("frequency (MHz)")
    ax.grid(axis="y", visible=False)
    total = sum(int(np.count_nonzero(m)) for _, m in rows.values())
    if total == 0:
        ax.text(0.5, 0.5, "no channel flagged", transform=ax.transAxes, ha="center",
                va="center", fontsize=12, color="C2")
    ax.set_title(f"Flagged channels (red): {total} in {len(rows)} spectra")
    return fig


@styled
def temperatures(log: TemperatureLog | None, columns: int = 3) -> Figure:
    """Every thermocouple channel (degC) against the hours since the first reading."""
    if log is None or log.timestamps_s.size == 0:
        fig = new_figure(2.0)
        note(fig.add_subplot(), "this run has no thermocouple log")
        return fig
    n = len(log.channels)
    rows = -(-n // columns)
    fig = new_figure(1.0 + 1.8 * rows)
    axes, bottom = axes_grid(fig, n, columns, space=Space(top=0.6, hspace=0.42, wspace=0.8))
    hours = (log.timestamps_s - log.timestamps_s[0]) / 3600.0
    for k, (ax, channel) in enumerate(zip(axes, log.channels, strict=True)):
        values = log.values_c[:, k]
        ax.plot(*envelope(hours, values, WIDTH_PX // columns), color=f"C{k % 10}", lw=0.8)
        spread = np.ptp(values) if values.size else 0.0
        ax.set_title(f"{channel}: {np.mean(values):.2f} °C, p-p {spread:.2f} °C", fontsize=9.5)
        if k % columns == 0:
            ax.set_ylabel("°C")
    for ax in bottom:
        ax.set_xlabel("time since the first reading (h)")
    suptitle(fig, f"Thermocouples over the run ({hours[-1]:.1f} h)")
    return fig
