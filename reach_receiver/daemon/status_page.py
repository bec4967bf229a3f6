"""The status page: what ``reachd`` is doing, for a person at the end of an SSH tunnel.

``daemon: {status_port: N}`` in the site file serves, on ``127.0.0.1:N`` only::

    ssh -L 8470:127.0.0.1:8470 reach@backend     # then open http://127.0.0.1:8470/

* ``/``: the page in words (:mod:`.status_html`: state, alarms, last calibration,
  recent jobs, time since the last spectrum, health readings) with one image per figure
  of :mod:`.status_figures`; it reloads itself every :data:`REFRESH_S` seconds (a
  ``meta`` refresh: no script);
* ``/figure/<name>``: a figure, drawn by one worker thread (so a page never takes more
  than one core from a run) and drawn again only when its data change;
* ``/status.json``: the daemon's ``status`` reply, as the control socket gives it.

Made for a slow satellite link: every answer carries an ``ETag`` (a figure's from the
version of its data, :func:`.status_figures.data_version`, so a browser's revalidation
is answered ``304 Not Modified`` without drawing anything) and ``Cache-Control:
no-cache`` (kept, but revalidated at each reload); text and SVG are sent gzipped to a
client that accepts it; each figure is sent as SVG or as a palette PNG, whichever is
smaller once compressed. A reload in steady state costs the HTML and a few 304s.

Read-only by construction: the handler answers ``GET`` (and ``HEAD``) and nothing
else, and it holds no reference to anything that acts (it gets the status as a
function returning a dict). The host is :data:`HOST`, a constant: the page cannot be
bound to another interface, so nobody reaches it without an SSH login first.

Built on the standard library's :class:`http.server.ThreadingHTTPServer`: four routes,
no forms, no sessions; a web framework would add a dependency and an attack surface and
save a few lines.
"""

from __future__ import annotations

import email.utils
import gzip
import hashlib
import json
import logging
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from io import BytesIO
from pathlib import Path
from typing import Any

from reach_receiver.config.monitoring import AlarmRule
from reach_receiver.monitor.database import MetricsDatabase

from .status_html import REFRESH_S, render_page

__all__ = ["HOST", "REFRESH_S", "Body", "FigureCache", "StatusPage", "render_page"]

log = logging.getLogger(__name__)

#: The only address the page is served on.
HOST = "127.0.0.1"
#: Seconds a request waits for its figure.
RENDER_TIMEOUT_S = 60.0
#: Bodies smaller than this are sent as they are (gzip's header would not pay).
GZIP_MIN = 256
#: Kinds of content worth compressing.
COMPRESSIBLE = ("text/", "application/json", "image/svg+xml")

Status = Callable[[], Mapping[str, Any]]


@dataclass(frozen=True)
class Body:
    """One answer's content: its type, bytes, gzipped bytes (if smaller), tag and time."""

    kind: str
    data: bytes
    gzipped: bytes | None
    etag: str
    modified: float

    @classmethod
    def of(cls, kind: str, data: bytes, etag: str | None = None,
           modified: float | None = None) -> Body:
        """``data`` with its gzip (when compressible and smaller) and an ``ETag``."""
        packed = None
        if len(data) >= GZIP_MIN and kind.startswith(COMPRESSIBLE):
            packed = gzip.compress(data, compresslevel=6, mtime=0)
            packed = packed if len(packed) < len(data) else None
        tag = etag or _tag(data)
        return cls(kind, data, packed, tag, time.time() if modified is None else modified)


def _tag(content: bytes | str) -> str:
    raw = content.encode() if isinstance(content, str) else content
    return '"' + hashlib.sha256(raw).hexdigest()[:20] + '"'


#: Draws a figure: (content type, bytes).
Render = Callable[[str], tuple[str, bytes]]
#: The version of a figure's data.
Version = Callable[[str], str]


class FigureCache:
    """Figures by name, drawn by one worker thread, drawn again only when their data change.

    ``version(name)`` is cheap (file stats); a figure whose version is the one it was
    drawn at is served as kept. Two requests for the same stale figure wait for the same
    drawing.
    """

    def __init__(self, render: Render, version: Version, names: tuple[str, ...]) -> None:
        self.render, self.version, self.names = render, version, names
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="status-figures")
        self._lock = threading.Lock()
        self._kept: dict[str, Body] = {}
        self._drawing: dict[tuple[str, str], Any] = {}
        self.drawn = 0  # figures drawn so far (the benchmark and tests read it)

    def etag(self, name: str, version: str | None = None) -> str:
        """The ``ETag`` figure ``name`` has at its data's current version."""
        if name not in self.names:
            raise KeyError(name)
        return _tag(f"{name}\0{self.version(name) if version is None else version}")

    def get(self, name: str) -> Body:
        """Figure ``name`` at its data's current version (``KeyError`` for an unknown name)."""
        version = self.version(name) if name in self.names else ""
        tag = self.etag(name, version)
        with self._lock:
            kept = self._kept.get(name)
            if kept is not None and kept.etag == tag:
                return kept
            future = self._drawing.get((name, tag))
            if future is None:
                future = self._drawing[(name, tag)] = self._pool.submit(self._draw, name, tag)
        return future.result(timeout=RENDER_TIMEOUT_S)

    def _draw(self, name: str, tag: str) -> Body:
        try:
            kind, data = self.render(name)
            body = Body.of(kind, data, etag=tag)
            with self._lock:
                self._kept[name] = body
                self.drawn += 1
            return body
        finally:
            with self._lock:
                self._drawing.pop((name, tag), None)

    def close(self) -> None:
        """Stop the worker (a drawing under way finishes)."""
        self._pool.shutdown(wait=True, cancel_futures=True)


def smallest_image(figure: Any, dpi: float) -> tuple[str, bytes]:
    """``figure`` as SVG or as a palette PNG, whichever is smaller as sent (SVG gzipped).

    Dense lines are decimated to the figure's pixel width by the builders, so an SVG
    is often the smaller; a figure of many curves or filled areas may not be.
    """
    both = image_formats(figure, dpi)
    kind = min(both, key=lambda k: both[k][1])
    return kind, both[kind][0]


def image_formats(figure: Any, dpi: float) -> dict[str, tuple[bytes, int]]:
    """``figure`` as a palette PNG and as SVG: each one's bytes and its size as sent."""
    from matplotlib import rc_context
    from PIL import Image

    raw = BytesIO()
    figure.savefig(raw, format="png", dpi=dpi)
    image = Image.open(BytesIO(raw.getvalue())).convert("RGB")
    png = BytesIO()
    image.quantize(colors=64, method=Image.Quantize.MEDIANCUT).save(png, "PNG", optimize=True)
    svg = BytesIO()
    with rc_context({"svg.fonttype": "none", "svg.hashsalt": "reach-status"}):
        figure.savefig(svg, format="svg", dpi=dpi, metadata={"Date": None})
    return {
        "image/png": (png.getvalue(), len(png.getvalue())),
        "image/svg+xml": (svg.getvalue(), len(gzip.compress(svg.getvalue(), 6))),
    }


class _Handler(BaseHTTPRequestHandler):
    """GET and HEAD only; the page, one figure, or the status as JSON."""

    page: StatusPage  # set on the subclass the server is made with
    server_version = "reachd-status"
    protocol_version = "HTTP/1.1"  # keep-alive: one TCP (and tunnel) setup per reload

    def do_GET(self) -> None:  # the name http.server dispatches to
        path = self.path.split("?", 1)[0]
        if path in ("/", "/index.html"):
            self._answer(Body.of("text/html; charset=utf-8", self.page.html().encode()))
        elif path == "/status.json":
            self._answer(Body.of("application/json", json.dumps(self.page.status()).encode()))
        elif path.startswith("/figure/"):
            name = path.removeprefix("/figure/")
            figures = self.page.figures
            try:
                if self._fresh(figures.etag(name), None):
                    return
                body = figures.get(name)
            except KeyError:
                self._send(404, Body.of("text/plain", b"no such figure\n"))
                return
            except Exception:  # a figure that cannot be drawn is logged, the page lives on
                log.exception("status page: figure %s could not be drawn", name)
                self._send(500, Body.of("text/plain",
                                        b"the figure could not be drawn (see the log)\n"))
                return
            self._answer(body)
        else:
            self._send(404, Body.of("text/plain", b"not found\n"))

    def do_HEAD(self) -> None:
        self.do_GET()

    def _fresh(self, etag: str, modified: float | None) -> bool:
        """Answer ``304 Not Modified`` if the client holds this version already."""
        match = self.headers.get("If-None-Match")
        if match is not None:
            fresh = etag in [t.strip().removeprefix("W/") for t in match.split(",")]
        elif modified is not None and self.headers.get("If-Modified-Since"):
            try:
                since = email.utils.parsedate_to_datetime(self.headers["If-Modified-Since"])
                fresh = int(modified) <= since.timestamp()
            except (TypeError, ValueError):
                fresh = False
        else:
            fresh = False
        if fresh:
            self.send_response(304)
            self.send_header("ETag", etag)
            self.send_header("Cache-Control", "no-cache")
            self.send_header("Content-Length", "0")
            self.end_headers()
        return fresh

    def _answer(self, body: Body) -> None:
        if not self._fresh(body.etag, body.modified):
            self._send(200, body)

    def _send(self, code: int, body: Body) -> None:
        accepts = self.headers.get("Accept-Encoding", "")
        zipped = body.gzipped is not None and "gzip" in accepts
        data = body.gzipped if zipped and body.gzipped is not None else body.data
        self.send_response(code)
        self.send_header("Content-Type", body.kind)
        self.send_header("Content-Length", str(len(data)))
        if code == 200:
            self.send_header("ETag", body.etag)
            self.send_header("Last-Modified", email.utils.formatdate(body.modified, usegmt=True))
            self.send_header("Cache-Control", "no-cache")  # kept, revalidated at each use
        if body.gzipped is not None:
            self.send_header("Vary", "Accept-Encoding")
        if zipped:
            self.send_header("Content-Encoding", "gzip")
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(data)

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
    jobs
        The daemon's jobs, oldest first, as the protocol shows them with their
        ``result`` lines (for the recent jobs and the last calibration).
    rules
        The site's alarm rules, whose thresholds the temperature panels draw.
    """

    def __init__(
        self,
        port: int,
        status: Status,
        runs: Path,
        database: Callable[[], MetricsDatabase | None],
        now: Callable[[], float] = time.time,
        jobs: Callable[[], Sequence[Mapping[str, Any]]] = list,
        rules: Sequence[AlarmRule] = (),
    ) -> None:
        from . import status_figures  # matplotlib: only for a daemon that serves the page

        self.port, self.status, self.runs, self.database, self.now, self.jobs = (
            port, status, runs, database, now, jobs
        )
        self.rules = tuple(rules)
        self._figures = status_figures
        self._builders = status_figures.FIGURES
        self.figures = FigureCache(self._render, self._version, tuple(self._builders))
        self._spectrum: tuple[str, float | None] = ("", None)
        self._shown: dict[str, tuple[str, bool]] = {}
        self._server: ThreadingHTTPServer | None = None
        self._thread: threading.Thread | None = None

    def _version(self, name: str) -> str:
        return self._figures.data_version(name, self.runs, self.database())

    def _render(self, name: str) -> tuple[str, bytes]:
        from calibration.report.figures.style import DPI

        fig = self._builders[name](self.runs, self.database(), self.now(), self.rules)
        return smallest_image(fig, DPI)

    def last_spectrum(self) -> float | None:
        """The newest stored spectrum's time, read again only when the runs change."""
        version = self._version("spectra")
        if version != self._spectrum[0]:
            self._spectrum = (version, self._figures.last_spectrum(self.runs))
        return self._spectrum[1]

    def shown(self, name: str) -> bool:
        """Whether figure ``name`` is on the page (some only once they have data)."""
        when = self._figures.SHOWN_WHEN.get(name)
        if when is None:
            return True
        version = self._version(name)
        if self._shown.get(name, ("", False))[0] != version:
            self._shown[name] = (version, when(self.runs))
        return self._shown[name][1]

    def html(self) -> str:
        """The page as it is now."""
        captions = self._figures.CAPTIONS
        names = [n for n in self.figures.names if self.shown(n)]
        return render_page(
            self.status(), [(n, captions.get(n, n)) for n in names], time.time(),
            jobs=self.jobs(), last_spectrum=self.last_spectrum(), clock_now=self.now(),
        )

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
