"""The status page: what ``reachd`` is doing, for a person at the end of an SSH tunnel.

``daemon: {status_port: N}`` in the site file serves, on ``127.0.0.1:N`` only::

    ssh -L 8470:127.0.0.1:8470 reach@backend     # then open http://127.0.0.1:8470/

* ``/``: the state and since when, the current job and step with the time left, the
  queue, the raised alarms (the daemon's and the health monitor's) and the latest
  health readings, with one image per figure of :mod:`.status_figures` (the latest
  Dicke spectra, the S11s, the temperatures of the last day, the current solution);
  the page reloads itself every :data:`REFRESH_S` seconds (a ``meta`` refresh: no
  script);
* ``/figure/<name>.png``: a figure, drawn on request by one worker thread (so a page
  never takes more than one core from a run) and kept for :data:`CACHE_S` seconds;
* ``/status.json``: the daemon's ``status`` reply, as the control socket gives it.

Read-only by construction: the handler answers ``GET`` (and ``HEAD``) and nothing
else, and it holds no reference to anything that acts (it gets the status as a
function returning a dict). The host is :data:`HOST`, a constant: the page cannot be
bound to another interface, so nobody reaches it without an SSH login first.

Built on the standard library's :class:`http.server.ThreadingHTTPServer`: four routes,
no forms, no sessions; a web framework would add a dependency and an attack surface and
save a few lines.
"""

from __future__ import annotations

import html
import json
import logging
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from io import BytesIO
from pathlib import Path
from typing import Any

from reach_receiver.monitor.database import MetricsDatabase
from reach_receiver.schedule.timing import hms

__all__ = ["CACHE_S", "HOST", "REFRESH_S", "FigureCache", "StatusPage", "render_page"]

log = logging.getLogger(__name__)

#: The only address the page is served on.
HOST = "127.0.0.1"
#: Seconds between the page's reloads.
REFRESH_S = 15
#: Seconds a drawn figure is served again before it is drawn anew.
CACHE_S = 10.0
#: Seconds a request waits for its figure.
RENDER_TIMEOUT_S = 60.0

Status = Callable[[], Mapping[str, Any]]
Render = Callable[[str], bytes]


class FigureCache:
    """PNGs by name, drawn by one worker thread, each kept for ``ttl_s`` seconds.

    Two requests for the same stale figure wait for the same drawing.
    """

    def __init__(self, render: Render, names: tuple[str, ...], ttl_s: float = CACHE_S) -> None:
        self.render, self.names, self.ttl_s = render, names, ttl_s
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="status-figures")
        self._lock = threading.Lock()
        self._kept: dict[str, tuple[float, bytes]] = {}
        self._drawing: dict[str, Any] = {}

    def get(self, name: str) -> bytes:
        """The PNG of figure ``name`` (``KeyError`` for an unknown name)."""
        if name not in self.names:
            raise KeyError(name)
        with self._lock:
            kept = self._kept.get(name)
            if kept is not None and time.monotonic() - kept[0] < self.ttl_s:
                return kept[1]
            future = self._drawing.get(name)
            if future is None:
                future = self._drawing[name] = self._pool.submit(self._draw, name)
        return bytes(future.result(timeout=RENDER_TIMEOUT_S))

    def _draw(self, name: str) -> bytes:
        try:
            png = self.render(name)
            with self._lock:
                self._kept[name] = (time.monotonic(), png)
            return png
        finally:
            with self._lock:
                self._drawing.pop(name, None)

    def close(self) -> None:
        """Stop the worker (a drawing under way finishes)."""
        self._pool.shutdown(wait=True, cancel_futures=True)


def _table(rows: list[tuple[str, str]]) -> str:
    cells = "".join(f"<tr><th>{html.escape(k)}</th><td>{v}</td></tr>" for k, v in rows)
    return f"<table>{cells}</table>"


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


def render_page(status: Mapping[str, Any], figures: tuple[str, ...], now: float) -> str:
    """The page's HTML for a ``status`` reply (:mod:`.protocol`) and the figures' names.

    ``now`` is the wall-clock time of the page (the figures may run on a simulated clock).
    """
    esc = html.escape
    job = status.get("job") or {}
    left = status.get("left_s")
    health = status.get("health") or {}
    alarms = [*(status.get("alarms") or []), *(health.get("alarms") or [])]
    since = status.get("since")
    rows = [
        ("state", f'<span class="state">{esc(str(status.get("state")))}</span>'
                  + (f" since {esc(_utc(since))}" if since else "")),
        ("job", esc(f"{job.get('id')} {job.get('name')}") if job else "none"),
        ("step", esc(str(status.get("step"))) if status.get("step") else "none"),
        ("time left", esc(hms(float(left))) if left is not None else "—"),
        ("queue", esc(", ".join(f"job {j}" for j in status.get("queue") or [])) or "empty"),
    ]
    if status.get("paused"):
        rows.append(("queue paused", "yes: an operator's resume is needed"))
    alarm_html = (
        "<ul class=\"alarms\">" + "".join(f"<li>{esc(str(a))}</li>" for a in alarms) + "</ul>"
        if alarms else '<p class="ok">no alarm raised</p>'
    )
    stamp = int(now)
    images = "".join(
        f'<figure><img src="/figure/{name}.png?t={stamp}" alt="{name}" width="1150"></figure>'
        for name in figures
    )
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta http-equiv="refresh" content="{REFRESH_S}">
<title>reachd: {esc(str(status.get("state")))}</title>
<style>
body {{ font-family: system-ui, sans-serif; margin: 1em auto; max-width: 1180px;
       color: #222; padding: 0 1em; }}
h1 {{ font-size: 1.4em; margin: 0.2em 0; }}
table {{ border-collapse: collapse; margin: 0.4em 0; }}
th, td {{ text-align: left; padding: 0.15em 0.8em 0.15em 0; vertical-align: top; }}
.state {{ font-weight: bold; font-size: 1.2em; }}
.alarms li {{ color: #b00; font-weight: bold; }}
.ok {{ color: #070; }}
tr.warn td {{ color: #a60; }} tr.error td {{ color: #b00; }}
figure {{ margin: 1em 0; }} img {{ max-width: 100%; border: 1px solid #ddd; }}
</style></head><body>
<h1>REACH receiver: reachd</h1>
<p>{esc(str(status.get("status", "")))}<br><small>as of {esc(_utc(now))};
reloads every {REFRESH_S} s; read-only</small></p>
{_table(rows)}
<h2>Alarms</h2>
{alarm_html}
{_readings(health)}
<h2>Figures</h2>
{images}
</body></html>
"""


def _utc(t: float) -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(float(t)))


class _Handler(BaseHTTPRequestHandler):
    """GET and HEAD only; the page, one figure, or the status as JSON."""

    page: StatusPage  # set on the subclass the server is made with
    server_version = "reachd-status"

    def do_GET(self) -> None:  # the name http.server dispatches to
        path = self.path.split("?", 1)[0]
        if path in ("/", "/index.html"):
            text = render_page(self.page.status(), self.page.figures.names, time.time())
            self._send(200, "text/html; charset=utf-8", text.encode())
        elif path == "/status.json":
            self._send(200, "application/json", json.dumps(self.page.status()).encode())
        elif path.startswith("/figure/") and path.endswith(".png"):
            name = path.removeprefix("/figure/").removesuffix(".png")
            try:
                png = self.page.figures.get(name)
            except KeyError:
                self._send(404, "text/plain", b"no such figure\n")
                return
            except Exception:  # a figure that cannot be drawn is logged, the page lives on
                log.exception("status page: figure %s could not be drawn", name)
                self._send(500, "text/plain", b"the figure could not be drawn (see the log)\n")
                return
            self._send(200, "image/png", png)
        else:
            self._send(404, "text/plain", b"not found\n")

    def do_HEAD(self) -> None:
        self.do_GET()

    def _send(self, code: int, kind: str, body: bytes) -> None:
        self.send_response(code)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def log_message(self, format: str, *args: Any) -> None:
        log.debug("status page %s: " + format, self.client_address[0], *args)


class StatusPage:
    """The page's server (module docstring): :meth:`start`, :meth:`close`.

    Parameters
    ----------
    port
        The port on :data:`HOST` (0: any free port; :attr:`address` says which).
    status
        The daemon's ``status`` reply (called from the server's threads).
    runs
        The daemon's runs directory.
    database
        The metrics database, or ``None`` while it is not open.
    now
        The daemon's clock, for the figures' "last day" (a simulator's clock runs fast).
    """

    def __init__(
        self,
        port: int,
        status: Status,
        runs: Path,
        database: Callable[[], MetricsDatabase | None],
        now: Callable[[], float] = time.time,
    ) -> None:
        from . import status_figures  # matplotlib: only for a daemon that serves the page

        self.port, self.status, self.runs, self.database, self.now = (
            port, status, runs, database, now
        )
        self._builders = status_figures.FIGURES
        self.figures = FigureCache(self._render, tuple(self._builders))
        self._server: ThreadingHTTPServer | None = None
        self._thread: threading.Thread | None = None

    def _render(self, name: str) -> bytes:
        from calibration.figures.style import DPI

        fig = self._builders[name](self.runs, self.database(), self.now())
        out = BytesIO()
        fig.savefig(out, format="png", dpi=DPI)
        return out.getvalue()

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port)."""
        if self._server is None:
            raise RuntimeError("the status page is not started")
        host, port = self._server.server_address[:2]
        return str(host), int(port)

    @property
    def url(self) -> str:
        """``http://127.0.0.1:<port>/``."""
        host, port = self.address
        return f"http://{host}:{port}/"

    def start(self) -> None:
        """Bind :data:`HOST` and serve from a thread."""
        handler = type("Handler", (_Handler,), {"page": self})
        self._server = ThreadingHTTPServer((HOST, self.port), handler)
        self._server.daemon_threads = True
        self._thread = threading.Thread(
            target=self._server.serve_forever, kwargs={"poll_interval": 0.2},
            name="status-page", daemon=True,
        )
        self._thread.start()
        log.info("status page on %s (read-only, this host only)", self.url)

    def close(self) -> None:
        """Stop serving, then stop the figures' worker."""
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.figures.close()
