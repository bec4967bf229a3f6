"""The status page's temperature panels: a UTC clock, and the alarm thresholds drawn.

One panel per temperature metric of the metrics database (the TC-08's thermocouples,
the Teensy's sensors, the TEC), a line per sensor, over the last day, on a time axis in
``HH:MM`` UTC (the operator's log and the alarms speak UTC). Each enabled alarm rule on
the metric is a dashed horizontal line at its threshold, named, so a reading's distance
to its alarm is seen at a glance. Lines are reduced to the figure's pixel width first
(:func:`calibration.report.figures.style.envelope`): a day of minute data would otherwise make
a large SVG of points no screen can show.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence

import numpy as np
from matplotlib.dates import DateFormatter, date2num
from matplotlib.figure import Figure

from calibration.report.figures.style import WIDTH_PX, axes_grid, envelope, new_figure
from reach_receiver.config.monitoring import AlarmRule
from reach_receiver.monitor.database import MetricsDatabase
from reach_receiver.monitor.readings import parse_key

__all__ = ["OKABE_ITO", "temperature_panels"]

#: Eight colours told apart with any common colour-vision deficiency (Okabe and Ito).
OKABE_ITO = ("#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00", "#F0E442",
             "#000000")
#: Line styles cycled after the eight colours.
DASHES = ("-", "--", ":")


def _sensor(key: str) -> str:
    metric, labels = parse_key(key)
    return labels.get("component") or " ".join(labels.values()) or metric


def _title(metric: str) -> str:
    return metric.removeprefix("reach_").removesuffix("_celsius").replace("_", " ")


def temperature_panels(
    database: MetricsDatabase, keys: Sequence[str], now: float, span_s: float,
    rules: Sequence[AlarmRule] = (),
) -> Figure | None:
    """The panels of ``keys`` since ``now - span_s`` (``None`` when no key has a reading)."""
    by_metric: dict[str, list[tuple[str, np.ndarray, np.ndarray]]] = {}
    for key in keys:
        points = database.series(key, now - span_s, now)
        if points:
            t = np.array([p.t for p in points], float)
            v = np.array([p.value for p in points], float)
            by_metric.setdefault(parse_key(key)[0], []).append((key, t, v))
    if not by_metric:
        return None
    fig = new_figure(0.4 + 2.3 * len(by_metric))
    axes, bottom = axes_grid(fig, len(by_metric), 1)
    utc = dt.timezone.utc
    for ax, (metric, lines) in zip(axes, sorted(by_metric.items()), strict=True):
        for i, (key, t, v) in enumerate(lines):
            x = date2num([dt.datetime.fromtimestamp(s, utc) for s in t])
            ax.plot(*envelope(np.asarray(x, float), v, WIDTH_PX // 2),
                    color=OKABE_ITO[i % len(OKABE_ITO)],
                    ls=DASHES[(i // len(OKABE_ITO)) % len(DASHES)], lw=1.0, label=_sensor(key))
        for rule in rules:
            if rule.metric != metric or not rule.enabled:
                continue
            for limit, side in ((rule.above, "above"), (rule.below, "below")):
                if limit is not None:
                    ax.axhline(limit, color="#b00", ls="--", lw=0.9)
                    ax.annotate(f"alarm {rule.name}: {side} {limit:g} C", (0.005, limit),
                                xycoords=("axes fraction", "data"), color="#b00", fontsize=8,
                                va="bottom")
        ax.set_title(_title(metric))
        ax.set_ylabel("°C")
        if len(lines) > 1:
            ax.legend(fontsize=7, ncols=min(len(lines), 5), loc="best")
    for ax in bottom:
        ax.xaxis.set_major_formatter(DateFormatter("%H:%M", tz=utc))
        ax.set_xlabel("time (HH:MM UTC)")
    return fig
