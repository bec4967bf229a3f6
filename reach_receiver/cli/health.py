"""The receiver's health on the command line: ``reach-run status`` and ``reach-run metrics``.

* ``reach-run status`` (or ``--status``) prints the daemon's state, then its raised alarms
  and the latest reading of every series from the ``health`` part of its ``status``
  reply (:func:`format_health`): one line per series, grouped by metric, the readings
  that are not nominal marked, stale ones with their age.
* ``reach-run metrics NAME --since 24h [--until ...] [--csv FILE]`` prints or exports a
  series of the daemon's metrics database (:func:`metrics_main`): ``NAME`` is a series key
  (``reach_tc08_temperature_celsius{channel=1,component=MS1 switch}``), a metric (all its
  series), or a metric with some labels (``reach_device_up{device=tec}``). A name the
  database does not hold is refused with the closest names it does hold (exit 2);
  ``--csv`` exports one series (``time_utc,unix_s,<key> (<unit>),status``), without
  ``NAME`` the command lists the series the database holds.

``--since`` and ``--until`` take a duration back from now (``90s``, ``15m``, ``24h``,
``30d``, ``2w``), an ISO time (``2026-03-01``, ``2026-03-01T18:00Z``, UTC unless an
offset is given) or Unix seconds (:func:`parse_time`). "Now" is the site's clock (a
``reach-sim``'s compressed one when the site file has a ``simulation`` section).
"""

from __future__ import annotations

import argparse
import dataclasses
import difflib
import math
import re
import sys
import time
from collections.abc import Mapping, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from reach_receiver.config.site import find_site, load_site
from reach_receiver.errors import ReceiverError

# The monitor package (its database, its access server) is imported by the commands that
# read it, not by ``reach-run status``, which starts in a tenth of a second without it.
if TYPE_CHECKING:
    from reach_receiver.monitor.database import MetricsDatabase

#: At most this many lines of a series by default (``--all`` prints every point).
SUMMARY_LINES = 40

#: Seconds per unit of a ``--since`` duration.
UNITS_S = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0, "w": 7 * 86400.0}
_DURATION = re.compile(r"^\s*(\d+(?:\.\d*)?)\s*([smhdw])\s*$")


def parse_time(text: str, now: float) -> float:
    """Unix seconds of ``text``: a duration before ``now``, an ISO time, or Unix seconds.

    Raises
    ------
    ValueError
        With a message naming the accepted forms.
    """
    match = _DURATION.match(text)
    if match:
        return now - float(match.group(1)) * UNITS_S[match.group(2)]
    try:
        return float(text)
    except ValueError:
        pass
    try:
        stamp = datetime.fromisoformat(text.strip().replace("Z", "+00:00"))
    except ValueError:
        raise ValueError(
            f"{text!r} is not a time: give a duration back from now (90s, 15m, 24h, 30d, 2w), "
            "an ISO time (2026-03-01T18:00Z) or Unix seconds"
        ) from None
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=timezone.utc)
    return stamp.timestamp()


# --------------------------------------------------------------------------- status
def _value(value: float | None, unit: str) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if unit == "B":
        return f"{value / 1e9:.2f} GB"
    if unit == "s" and abs(value) >= 3600:
        return f"{value / 3600:.1f} h"
    shown = f"{value:.4g}" if unit != "1" or value != int(value) else f"{int(value)}"
    return f"{shown} {unit}" if unit not in ("1", "") else shown


def format_health(health: Mapping[str, Any] | None, now: float | None = None) -> list[str]:
    """The ``health`` of a daemon's ``status`` reply as lines readable at a glance."""
    from reach_receiver.monitor.readings import parse_key

    if not health:
        return ["health: no readings (the daemon has no monitor)"]
    now = time.time() if now is None else now
    alarms = list(health.get("alarms", []))
    readings = list(health.get("readings", []))
    cadence = float(health.get("cadence_s", 60.0))
    lines = [f"alarms: {len(alarms)} raised" if alarms else "alarms: none"]
    lines += [f"  ! {alarm}" for alarm in alarms]
    if not readings:
        return [*lines, "readings: none yet"]
    newest = max(float(r["t"]) for r in readings)
    ago = f", {now - newest:.0f} s ago" if now >= newest else ""
    stamp = datetime.fromtimestamp(newest, tz=timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    lines.append(f"readings (every {cadence:g} s; latest {stamp}{ago}):")
    metric_before = None
    for r in readings:
        metric, labels = parse_key(str(r["key"]))
        name = metric.removeprefix("reach_")
        label = ", ".join(labels.values())
        head = name if metric != metric_before else " " * len(name)
        metric_before = metric
        text = f"  {head}  {label}".rstrip()
        flags = "" if r["status"] == "nominal" else f"  [{r['status']}]"
        age = now - float(r["t"])
        if age > 2 * cadence:
            flags += f"  ({age:.0f} s old)"
        # Within 80 columns: name 44, value 9, "[unknown]" and "(86400 s old)".
        text = text if len(text) <= 44 else text[:41] + "..."
        lines.append(f"{text:<44} {_value(r['value'], str(r['unit'])):>9}{flags}")
    return lines


# --------------------------------------------------------------------------- metrics
def metrics_parser() -> argparse.ArgumentParser:
    """The command line of ``reach-run metrics``."""
    from .commands import subparser

    p = subparser("metrics", "Summarise, print or export a series of the daemon's metrics "
                  "database: by default each series' count, first and last, min/mean/max and "
                  f"at most {SUMMARY_LINES} evenly spaced points.")
    p.add_argument("name", nargs="?", help="series key, metric, or metric{label=value}; "
                   "without it, the series the database holds")
    p.add_argument("--since", default="24h", help="start: 24h, 30d, an ISO time or Unix s "
                   "(default 24h)")
    p.add_argument("--until", default=None, help="end (default: now)")
    p.add_argument("--csv", type=Path, metavar="FILE", help="write CSV here ('-': stdout)")
    p.add_argument("--all", action="store_true", help="every point, not the summary")
    p.add_argument("--json", action="store_true", help="every point as JSON")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--site", type=Path, help="site file ($REACH_SITE, /etc/reach/site.yaml)")
    where.add_argument("--database", type=Path, help="the metrics file itself")
    return p


def metrics_main(argv: Sequence[str]) -> int:
    """``reach-run metrics``: 0 when printed, 1 for a missing database, 2 for bad input."""
    args = metrics_parser().parse_args(argv)
    try:
        if args.database is not None:
            path, now = args.database, time.time()
        else:
            site = load_site(find_site(args.site))
            path = site.monitoring.database_path(site.daemon.state_directory())
            now = site.clock().now()
        since = parse_time(args.since, now)
        until = parse_time(args.until, now) if args.until else math.inf
    except (ReceiverError, ValueError) as err:
        print(f"reach-run metrics: {err}", file=sys.stderr)
        return 2
    from reach_receiver.monitor.database import MetricsDatabase

    if not path.is_file():
        print(f"reach-run metrics: no metrics database at {path} (has reachd run?)",
              file=sys.stderr)
        return 1
    database = MetricsDatabase(path)
    try:
        return _show(database, args, since, until)
    finally:
        database.close()


def _show(database: MetricsDatabase, args: argparse.Namespace, since: float,
          until: float) -> int:
    from reach_receiver.monitor.database import write_csv

    if args.name is None:
        for key in database.keys(None):
            print(key)
        return 0
    keys = database.keys(args.name)
    if not keys:
        print(f"reach-run metrics: no series {args.name!r}{_close(database, args.name)}",
              file=sys.stderr)
        return 2
    if args.csv is not None:
        if len(keys) > 1:
            print(f"reach-run metrics: {args.name!r} is {len(keys)} series; --csv writes one: "
                  + ", ".join(keys), file=sys.stderr)
            return 2
        (key,) = keys
        points = database.series(key, since, until)
        text = write_csv(points, key, database.unit(key))
        if str(args.csv) == "-":
            sys.stdout.write(text)
        else:
            args.csv.write_text(text, encoding="utf-8")
            print(f"{len(points)} rows of {key} written to {args.csv}")
        return 0
    if args.json:
        from .commands import dumps

        print(dumps({key: {"unit": database.unit(key), "points": [
            dataclasses.asdict(p) for p in database.series(key, since, until)]}
            for key in keys}))
        return 0
    for key in keys:
        points = database.series(key, since, until)
        if args.all:
            _print_series(key, database.unit(key), points)
        else:
            _print_summary(key, database.unit(key), points)
    return 0


def _print_summary(key: str, unit: str, points: Sequence[Any]) -> None:
    """Count, first and last, min/mean/max, and at most SUMMARY_LINES evenly spaced points."""
    print(f"{key} ({unit}): {len(points)} points")
    if not points:
        return
    values = [p.value for p in points if math.isfinite(p.value)]
    first, last = (_stamp(points[i].t) for i in (0, -1))
    print(f"  from {first} to {last} UTC")
    if values:
        mean = sum(values) / len(values)
        print(f"  min {_value(min(values), unit)}  mean {_value(mean, unit)}  "
              f"max {_value(max(values), unit)}")
    step = max(1, math.ceil(len(points) / SUMMARY_LINES))
    shown = list(points[::step])
    if len(points) > len(shown):
        print(f"  every {step}th point (all: --all, --csv FILE or --json):")
    _print_points(unit, shown)


def _stamp(t: float) -> str:
    return datetime.fromtimestamp(t, tz=timezone.utc).strftime("%Y-%m-%d %H:%M:%S")


def _print_series(key: str, unit: str, points: Sequence[Any]) -> None:
    print(f"{key} ({unit}): {len(points)} points")
    _print_points(unit, points)


def _print_points(unit: str, points: Sequence[Any]) -> None:
    for p in points:
        stamp = _stamp(p.t)
        flag = "" if p.status == "nominal" else f"  [{p.status}]"
        mean = "  (15-min mean)" if p.resolution_s > 60 else ""
        print(f"  {stamp}  {_value(p.value, unit)}{flag}{mean}")


def _close(database: MetricsDatabase, name: str) -> str:
    """``; close names: ...`` from the series keys and metrics the database holds."""
    from reach_receiver.monitor.readings import parse_key

    keys = database.keys()
    metrics = sorted({parse_key(k)[0] for k in keys})
    close = difflib.get_close_matches(name, metrics + keys, n=5, cutoff=0.5)
    metric = parse_key(name)[0]
    if metric in metrics:  # a known metric with labels none of its series has
        close = [k for k in keys if parse_key(k)[0] == metric][:8]
    if not close:
        return f"; the database holds {len(metrics)} metrics (list them: reach-run metrics)"
    return "; close names: " + ", ".join(close)
