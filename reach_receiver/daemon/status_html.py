"""The status page's HTML: everything an operator needs in words, the figures beside it.

The page must read with images off (a satellite link may be too slow for them, or a
browser set not to load them): the state, the raised alarms in words, the last
calibration with its time and result, the recent jobs and how each ended, and the time
since the last spectrum are all text. The figures are ``<img>`` elements whose address
never changes (``/figure/<name>``): the browser revalidates them with the ``ETag`` it
holds and gets ``304 Not Modified`` until their data change (:mod:`.status_page`).
"""

from __future__ import annotations

import html
import time
from collections.abc import Mapping, Sequence
from typing import Any

from reach_receiver.schedule.timing import hms

__all__ = ["REFRESH_S", "render_page"]

#: Seconds between the page's reloads.
REFRESH_S = 15
#: Recent jobs listed.
RECENT_JOBS = 6

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 1em auto; max-width: 1180px;
       color: #222; padding: 0 0.6em; }
h1 { font-size: 1.3em; margin: 0.2em 0; } h2 { font-size: 1.1em; margin: 0.8em 0 0.2em; }
table { border-collapse: collapse; margin: 0.3em 0; }
th, td { text-align: left; padding: 0.1em 0.7em 0.1em 0; vertical-align: top; }
.state { font-weight: bold; font-size: 1.15em; }
.alarms li { color: #b00; } .alarms small { color: #555; overflow-wrap: anywhere; }
.ok { color: #070; } .failed, .aborted { color: #b00; } .cancelled { color: #a60; }
tr.warn td { color: #a60; } tr.error td { color: #b00; }
pre { white-space: pre-wrap; overflow-wrap: anywhere; margin: 0.2em 0; font-size: 0.9em; }
figure { margin: 1em 0; } img { max-width: 100%; height: auto; border: 1px solid #ddd; }
"""


def _utc(t: float) -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(float(t)))


def _age(seconds: float) -> str:
    """``42 s``, ``3 min``, ``2.5 h``, ``4.1 d``: an age a person reads at a glance."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    if seconds < 172800:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} d"


def _table(rows: list[tuple[str, str]]) -> str:
    cells = "".join(f"<tr><th>{html.escape(k)}</th><td>{v}</td></tr>" for k, v in rows)
    return f"<table>{cells}</table>"


def _alarms(status: Mapping[str, Any]) -> str:
    """The daemon's alarms, then the monitor's: each in words, its series as detail."""
    esc = html.escape
    items = [f"<li>{esc(str(a))}</li>" for a in status.get("alarms") or []]
    health = status.get("health") or {}
    details = health.get("alarm_details")
    if details:
        for d in details:
            series = d.get("series") or d.get("id") or ""
            items.append(f"<li>{esc(str(d.get('text') or d.get('name')))}"
                         + (f" <small>{esc(str(series))}</small>" if series else "") + "</li>")
    else:
        items += [f"<li>{esc(str(a))}</li>" for a in health.get("alarms") or []]
    if not items:
        return '<p class="ok">no alarm raised</p>'
    return f'<ul class="alarms">{"".join(items)}</ul>'


def _last_calibration(jobs: Sequence[Mapping[str, Any]]) -> str:
    """The newest completed job that printed a result: its time and what it printed."""
    esc = html.escape
    for job in reversed(jobs):
        if job.get("state") == "completed" and job.get("result"):
            when = job.get("ended") or job.get("started")
            lines = "\n".join(str(line) for line in job["result"])
            head = f"job {job.get('id')} {job.get('name')}" + (
                f", ended {_utc(when)} ({_age(time.time() - float(when))} ago)" if when else "")
            return f"<p>{esc(head)}</p><pre>{esc(lines)}</pre>"
    return "<p>no calibration result yet</p>"


def _jobs(jobs: Sequence[Mapping[str, Any]]) -> str:
    esc = html.escape
    rows = []
    for job in list(jobs)[-RECENT_JOBS:][::-1]:
        state = str(job.get("state"))
        when = job.get("ended") or job.get("started") or job.get("submitted")
        reason = str(job.get("reason") or "")
        rows.append(
            f'<tr><td>{esc(str(job.get("id")))}</td><td>{esc(str(job.get("name")))}</td>'
            f'<td class="{esc(state)}">{esc(state)}</td>'
            f"<td>{esc(_utc(when)[5:16]) if when else ''}</td><td>{esc(reason)}</td></tr>"
        )
    if not rows:
        return "<p>no job yet</p>"
    return ("<table><tr><th>job</th><th>name</th><th>outcome</th><th>UTC</th><th></th></tr>"
            + "".join(rows) + "</table>")


def _readings(health: Mapping[str, Any]) -> str:
    rows = []
    for r in health.get("readings") or []:
        value = "—" if r.get("value") is None else f"{r['value']:.4g} {r.get('unit', '')}"
        status = str(r.get("status", ""))
        rows.append(
            f'<tr class="{html.escape(status)}"><td>{html.escape(str(r.get("key")))}</td>'
            f"<td>{html.escape(value)}</td><td>{html.escape(status)}</td></tr>"
        )
    if not rows:
        return "<p>no health readings yet</p>"
    return (f"<details><summary>{len(rows)} health readings</summary><table>"
            f"<tr><th>series</th><th>value</th><th>status</th></tr>{''.join(rows)}</table>"
            "</details>")


def render_page(
    status: Mapping[str, Any],
    figures: Sequence[tuple[str, str]],
    now: float,
    jobs: Sequence[Mapping[str, Any]] = (),
    last_spectrum: float | None = None,
    clock_now: float | None = None,
) -> str:
    """The page's HTML.

    ``status`` is the daemon's ``status`` reply (:mod:`.protocol`); ``figures`` the
    figures' (name, caption); ``jobs`` the daemon's jobs, oldest first, each as the
    protocol shows it with its ``result`` lines; ``last_spectrum`` the time of the
    newest stored spectrum on the daemon's clock ``clock_now`` (a simulator's clock
    runs apart from the wall clock ``now``).
    """
    esc = html.escape
    job = status.get("job") or {}
    left = status.get("left_s")
    since = status.get("since")
    if last_spectrum is None:
        spectrum = "none stored yet"
    else:
        ago = max(0.0, (clock_now if clock_now is not None else now) - last_spectrum)
        spectrum = f"{_age(ago)} ago ({_utc(last_spectrum)})"
    rows = [
        ("state", f'<span class="state">{esc(str(status.get("state")))}</span>'
                  + (f" since {esc(_utc(since))}" if since else "")),
        ("job", esc(f"{job.get('id')} {job.get('name')}") if job else "none"),
        ("step", esc(str(status.get("step"))) if status.get("step") else "none"),
        ("time left", esc(hms(float(left))) if left is not None else "—"),
        ("queue", esc(", ".join(f"job {j}" for j in status.get("queue") or [])) or "empty"),
        ("last spectrum", esc(spectrum)),
    ]
    if status.get("paused"):
        rows.append(("queue paused", "yes: an operator's resume is needed"))
    images = "".join(
        f'<figure><img src="/figure/{name}" alt="{esc(caption)} (figure)" width="1150">'
        "</figure>"
        for name, caption in figures
    )
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta http-equiv="refresh" content="{REFRESH_S}">
<title>reachd: {esc(str(status.get("state")))}</title>
<style>{_STYLE}</style></head><body>
<h1>REACH receiver: reachd</h1>
<p>{esc(str(status.get("status", "")))}<br><small>as of {esc(_utc(now))};
reloads every {REFRESH_S} s; read-only</small></p>
{_table(rows)}
<h2>Alarms</h2>
{_alarms(status)}
<h2>Last calibration</h2>
{_last_calibration(jobs)}
<h2>Recent jobs</h2>
{_jobs(jobs)}
{_readings(status.get("health") or {})}
<h2>Figures</h2>
{images}
</body></html>
"""
