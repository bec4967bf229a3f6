"""``reach-run status``: the daemon's ``status`` reply as a few lines within 80 columns.

State and since when, the job and its step with the time left, the queue, the alarms,
the last calibration (the daemon's ``solutions`` request) and the link of every device
(the ``reach_device_up`` readings). The readings themselves are ``status --all``.
"""

from __future__ import annotations

import re
import textwrap
import time
from collections.abc import Mapping
from datetime import datetime, timezone
from typing import Any

WIDTH = 80
_DEVICE = re.compile(r"^reach_device_up\{device=([^,}]+)\}$")


def _ago(t: float | None, now: float) -> str:
    if t is None:
        return ""
    stamp = datetime.fromtimestamp(float(t), tz=timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return f"{stamp} ({duration(now - float(t))} ago)"


def duration(seconds: float) -> str:
    """A span as an operator reads it: ``45 s``, ``12 min``, ``3.4 h``, ``2.0 d``."""
    seconds = max(0.0, seconds)
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} d"


def _fit(line: str) -> str:
    return line if len(line) <= WIDTH else line[: WIDTH - 3] + "..."


def summary_lines(reply: Mapping[str, Any], now: float | None = None) -> list[str]:
    """The summary of a ``status`` reply (with ``last_calibration`` added by the client).

    The state's change is told against the wall clock, the last calibration against the
    daemon's own clock (``now`` in the reply), which for a simulated receiver runs faster.
    """
    wall = time.time() if now is None else now
    now = float(reply.get("now") or wall) if now is None else now
    since = _ago(reply.get("since"), wall)  # the state machine's times are the wall clock
    lines = [f"state:     {reply.get('state', '?')}" + (f" since {since}" if since else "")]
    job = reply.get("job")
    if job:
        lines.append(f"job:       {job.get('id')} {job.get('name', '')}")
        if reply.get("step"):
            lines.append(f"step:      {reply['step']}")
        if reply.get("left_s") is not None:
            lines.append(f"time left: {duration(float(reply['left_s']))}")
    else:
        lines.append("job:       none")
    queue = reply.get("queue") or []
    paused = " (paused)" if reply.get("paused") else ""
    if queue or paused:
        lines.append(f"queue:     {', '.join(map(str, queue)) or 'empty'}{paused}")
    health = reply.get("health") or {}
    alarms = [*reply.get("alarms", []), *health.get("alarms", [])]
    lines.append(f"alarms:    {len(alarms)} raised" if alarms else "alarms:    none")
    lines += [f"  ! {alarm}" for alarm in alarms]
    calibration = reply.get("last_calibration")
    if calibration:
        lines.append(f"last calibration: {_ago(calibration.get('time'), now)}")
        lines.append(f"  {calibration.get('name', '')} ({calibration.get('status', '')}), "
                     f"{calibration.get('run', '')}")
    else:
        lines.append("last calibration: none")
    devices = []
    for reading in health.get("readings", []):
        match = _DEVICE.match(str(reading.get("key", "")))
        if match:
            value = reading.get("value")
            link = "up" if value == 1 else ("down" if value == 0 else "unknown")
            devices.append(f"{match.group(1)} {link}")
    text = ", ".join(devices) if devices else "no readings"
    lines += textwrap.wrap(text, WIDTH, initial_indent="devices:   ", subsequent_indent=" " * 11)
    return [_fit(line) for line in lines]
