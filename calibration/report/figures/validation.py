"""Leave-one-out residuals beside the in-sample ones (:mod:`calibration.report.loo`).

One panel per calibrator: its residual (calibrated minus known temperature, K) held out of
the solve, as bin means, with the held-out prediction's ±1 sigma of a bin mean (shaded),
and beside it the in-sample residual with its own (grey, dashed). In-sample residuals at the
noise and held-out residuals many sigma off are the mark of a model fitting the noise or
missing structure the others cannot see. A refused solve says why.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from .sources import TITLE, binned, rms
from .style import (
    LEGEND_ROW_IN,
    NEUTRAL,
    Space,
    axes_grid,
    legend_below,
    mhz,
    new_figure,
    note,
    styled,
    suptitle,
)

FloatArray = NDArray[np.float64]
#: A calibrator's residual, the predicted sd of its calibration part (correlated across
#: channels) and of the rest (the radiometer noise and thermometry, independent), per
#: channel (K); or the refusal's message.
Residual = tuple[FloatArray, FloatArray, FloatArray] | str


def binned_sd(
    x: FloatArray, sd_calibration: FloatArray, sd_noise: FloatArray, fitted: bool = False
) -> tuple[FloatArray, FloatArray]:
    """The predicted sd of each bin's mean residual: ``sqrt(<s_cal^2> + <s_noise^2> / n)``.

    The calibration error is smooth and does not average down over a bin of ``n``
    channels; the radiometer noise does. A residual of the calibrators the solution was
    ``fitted`` to has the noise less what the fit absorbed,
    ``sqrt(max(<s_noise^2> / n - <s_cal^2>, 0))`` (``E[r r^T] = Sigma - X Cov X^T``,
    :mod:`calibration.choice.model_checks`).
    """
    bx, cal = binned(x, sd_calibration**2)
    width = max(1, x.size // bx.size)
    _, noise = binned(x, sd_noise**2)
    if fitted:
        return bx, np.sqrt(np.maximum(noise / width - cal, 0.0))
    return bx, np.sqrt(cal + noise / width)


def _wrapped(text: str, width: int = 44, lines: int = 4) -> str:
    words, out, line = text.split(), [], ""
    for word in words:
        if len(line) + len(word) + 1 > width:
            out.append(line)
            line = word
        else:
            line = f"{line} {word}".strip()
    out.append(line)
    return "\n".join(out[:lines]) + (" ..." if len(out) > lines else "")


@styled
def held_out_residuals(
    freq_hz: FloatArray,
    held: Mapping[str, Residual],
    in_sample: Mapping[str, tuple[FloatArray, FloatArray, FloatArray]] | None = None,
    columns: int = 4,
) -> Figure:
    """Each calibrator's held-out residual with its prediction, beside the in-sample one.

    ``held[name]`` is :data:`Residual` on ``freq_hz``; ``in_sample[name]`` the same for the
    solution fitted with every calibrator. Residuals are drawn as bin means
    (:func:`~calibration.report.figures.sources.binned`) with their own predicted sd
    (:func:`binned_sd`); the titles give the per-channel RMS over the predicted sd.
    """
    in_sample = in_sample or {}
    n = len(held)
    columns = max(1, min(columns, n))
    rows = max(1, -(-n // columns))
    fig = new_figure(1.2 + 2.1 * rows)
    if not held:
        note(fig.add_subplot(), "no calibrator held out")
        return fig
    space = Space(bottom=0.6 + LEGEND_ROW_IN, wspace=0.85, hspace=0.5)
    axes, bottom = axes_grid(fig, n, columns, space=space, sharex=False)
    x = mhz(freq_hz)
    entries: dict[str, Any] = {}
    for i, (ax, (name, value)) in enumerate(zip(axes, held.items(), strict=True)):
        if isinstance(value, str):
            ax.text(0.5, 0.5, f"{name} held out: refused\n{_wrapped(value)}", ha="center",
                    va="center", fontsize=8, transform=ax.transAxes)
            ax.set_axis_off()
            ax.set_title(f"{name}: refused", **TITLE)
            continue
        residual, cal, noise = value
        predicted = np.sqrt(cal**2 + noise**2)
        bx, by = binned(x, residual)
        _, bs = binned_sd(x, cal, noise)
        ax.fill_between(bx, -bs, bs, color="C3", alpha=0.2, lw=0,
                        label="held out: predicted ±1σ of the bin mean")
        ax.plot(bx, by, color="C3", lw=1.4, label="held out: residual (binned)")
        limit = 1.3 * max(float(np.max(np.abs(by))), float(np.max(bs)), 1e-9)
        title = f"{name}: held out {rms(residual):.3g} K = {rms(residual) / rms(predicted):.2f} σ"
        if name in in_sample:
            r_in, c_in, n_in = in_sample[name]
            s_in = np.sqrt(c_in**2 + n_in**2)
            ix, iy = binned(x, r_in)
            _, isd = binned_sd(x, c_in, n_in, fitted=True)
            ax.plot(ix, iy, color=NEUTRAL, lw=1.0, label="in-sample: residual (binned)")
            for sign in (1, -1):
                ax.plot(ix, sign * isd, color=NEUTRAL, ls="--", lw=0.8,
                        label="in-sample: predicted ±1σ" if sign > 0 else None)
            title += f"\nin-sample {rms(r_in) * 1e3:.3g} mK = {rms(r_in) / rms(s_in):.2f} σ"
        ax.set_ylim(-limit, limit)
        ax.set_title(title, **TITLE)
        if i % columns == 0:
            ax.set_ylabel("calibrated − known (K)")
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(label, handle)
    for ax in bottom:
        ax.set_xlabel("frequency (MHz)")
    if entries:
        legend_below(fig, list(entries.values()), list(entries), columns=len(entries))
    suptitle(fig, "Leave-one-out: each calibrator held out of the solve, beside its in-sample fit")
    return fig
