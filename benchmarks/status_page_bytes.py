"""Status page bytes over a satellite link: a conditional client against a no-cache one.

``reachd --sim`` serves the page (``status_port: 0``) after the quick calibration has
run (so every figure has data: Dicke spectra, S11s, a solution, temperatures) while a
long wait runs. Two clients each load the page :data:`RELOADS` times, fetching every
image the HTML references:

* **conditional**: what a browser does with the page's headers: ``Accept-Encoding:
  gzip`` and ``If-None-Match`` with the ``ETag`` it holds for each address;
* **no cache**: neither (what a browser did when the page sent ``no-store`` and
  cache-busting query strings: every reload fetched everything).

Bytes counted are the bodies received (headers add ~300 bytes an answer). Printed: the
first load and the mean and largest steady-state reload of each, against the targets
(first load under 400 kB, a reload under 60 kB), and the figures' sizes and types.

Run: ``python -m benchmarks.status_page_bytes [--reloads 10] [--interval 15]`` (about a
minute with the default interval of 1 s; ``--interval 15`` reloads as the page does).
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from html.parser import HTMLParser
from pathlib import Path

from reach_receiver.cli import run_main
from reach_receiver.daemon.client import DaemonClient
from reach_receiver.sim.receiver import SimulationSettings, simulated_site

RELOADS = 10
FIRST_TARGET = 400_000
RELOAD_TARGET = 60_000
SCHEDULES = Path(__file__).resolve().parents[1] / "schedules"
ENTRY = "import sys; from reach_receiver.cli import reachd_main as m; sys.exit(m(sys.argv[1:]))"
LONG = "schedule: long look\nsteps:\n  - wait: {seconds: 300000}\n"


class _Images(HTMLParser):
    def __init__(self, text: str) -> None:
        super().__init__()
        self.images: list[str] = []
        self.feed(text)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag == "img":
            self.images.append(str(dict(attrs)["src"]))


class Client:
    """A page reader: conditional (ETags, gzip) or not; counts the body bytes it gets."""

    def __init__(self, base: str, conditional: bool) -> None:
        self.base, self.conditional = base, conditional
        self.etags: dict[str, str] = {}
        self.kinds: dict[str, tuple[str, int]] = {}

    def get(self, path: str) -> tuple[bytes, int]:
        """(body as received, status) of ``path``."""
        headers = {}
        if self.conditional:
            headers["Accept-Encoding"] = "gzip"
            if path in self.etags:
                headers["If-None-Match"] = self.etags[path]
        request = urllib.request.Request(self.base + path.lstrip("/"), headers=headers)
        try:
            with urllib.request.urlopen(request, timeout=120) as answer:
                body = answer.read()
                if answer.headers.get("ETag"):
                    self.etags[path] = answer.headers["ETag"]
                self.kinds[path] = (answer.headers.get("Content-Type", ""), len(body))
                return body, answer.status
        except urllib.error.HTTPError as err:
            if err.code == 304:
                return b"", 304
            raise

    def reload(self) -> int:
        """Bytes of one load: the page, then every image it references."""
        page, _ = self.get("/")
        text = page
        if page[:2] == b"\x1f\x8b":
            import gzip

            text = gzip.decompress(page)
        total = len(page)
        for src in _Images(text.decode()).images:
            total += len(self.get(src)[0])
        return total


def _serve(tmp: Path) -> tuple[subprocess.Popen[str], str]:
    site = tmp / "base-site.yaml"
    site.write_text(simulated_site(SimulationSettings()).to_yaml()
                    + "daemon:\n  status_port: 0\n")
    process = subprocess.Popen(
        [sys.executable, "-c", ENTRY, "--sim", "--site", str(site), "--state-dir",
         str(tmp / "state"), "--runtime-dir", str(tmp / "run"), "--site-out",
         str(tmp / "site.yaml")],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
        env={**os.environ, "NOTIFY_SOCKET": ""},
    )
    assert process.stdout is not None
    url = None
    for line in process.stdout:
        found = re.search(r"status page (http://\S+)", line)
        url = found.group(1) if found else url
        if "serving" in line:
            break
    if url is None:
        process.kill()
        raise SystemExit("status_page_bytes: reachd printed no status page")
    return process, url


def _prepare(tmp: Path) -> None:
    """The quick calibration done, then a long wait running."""
    site = str(tmp / "site.yaml")
    (tmp / "long.yaml").write_text(LONG)
    for schedule in (SCHEDULES / "quick.yaml", tmp / "long.yaml"):
        if run_main(["--site", site, str(schedule), "--detach"]) != 0:
            raise SystemExit(f"status_page_bytes: {schedule} was not accepted")
    deadline = time.monotonic() + 600
    with DaemonClient(tmp / "run" / "control.sock") as client:
        while time.monotonic() < deadline:
            status = client.request("status")
            if (status.get("job") or {}).get("id") == 2 and status.get("step"):
                return
            time.sleep(0.2)
    raise SystemExit("status_page_bytes: the quick calibration did not end in 10 min")


def measure(url: str, reloads: int, interval_s: float) -> dict[str, list[int]]:
    """Bytes of each load by each client, loads interleaved so both see the same data."""
    clients = {"conditional": Client(url, True), "no cache": Client(url, False)}
    loads: dict[str, list[int]] = {name: [] for name in clients}
    for i in range(reloads):
        for name, client in clients.items():
            loads[name].append(client.reload())
        if i < reloads - 1:
            time.sleep(interval_s)
    for path, (kind, size) in sorted(clients["conditional"].kinds.items()):
        if path.startswith("/figure/"):
            plain = clients["no cache"].kinds.get(path, ("", 0))[1]
            print(f"  {path:22s} {kind:15s} {size / 1e3:7.1f} kB sent ({plain / 1e3:.1f} kB "
                  "uncompressed)")
    return loads


def formats(state: Path) -> None:
    """Each figure of the run just made drawn both ways: the palette PNG and the SVG."""
    from calibration.report.figures.style import DPI
    from reach_receiver.daemon.status_figures import FIGURES
    from reach_receiver.daemon.status_page import image_formats
    from reach_receiver.monitor.database import MetricsDatabase

    path = state / "metrics.sqlite"
    database = MetricsDatabase(path) if path.exists() else None
    print("each figure both ways (as sent: PNG as is, SVG gzipped; the page sends the smaller):")
    try:
        keys = database.keys() if database is not None else []
        last = [p.t for k in keys for p in database.series(k, 0, 4e9)[-1:]] if database else []
        now = max(last, default=time.time())  # the daemon's clock (a simulator's runs fast)
        for name, build in FIGURES.items():
            sizes = image_formats(build(state / "runs", database, now, ()), DPI)
            print(f"  {name:13s} PNG {sizes['image/png'][1] / 1e3:6.1f} kB, "
                  f"SVG {sizes['image/svg+xml'][1] / 1e3:6.1f} kB "
                  f"({len(sizes['image/svg+xml'][0]) / 1e3:.0f} kB before gzip)")
    finally:
        if database is not None:
            database.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.status_page_bytes")
    parser.add_argument("--reloads", type=int, default=RELOADS)
    parser.add_argument("--interval", type=float, default=1.0,
                        help="seconds between reloads (the page's own: 15)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="status-bytes-") as workdir:
        tmp = Path(workdir)
        process, url = _serve(tmp)
        try:
            _prepare(tmp)
            print(f"status page of reachd --sim ({url}), {args.reloads} loads each:")
            loads = measure(url, args.reloads, args.interval)
        finally:
            process.send_signal(signal.SIGTERM)
            process.wait(timeout=60)
        formats(tmp / "state")
    ok = True
    for name, sizes in loads.items():
        steady = sizes[1:] or [0]
        mean, worst = sum(steady) / len(steady), max(steady)
        print(f"{name:12s} first load {sizes[0] / 1e3:7.1f} kB (target < {FIRST_TARGET / 1e3:.0f})"
              f"  reload mean {mean / 1e3:6.1f} kB, max {worst / 1e3:6.1f} kB "
              f"(target < {RELOAD_TARGET / 1e3:.0f})")
        if name == "conditional":
            ok = sizes[0] < FIRST_TARGET and worst < RELOAD_TARGET
    print("conditional client within both targets" if ok else "TARGET MISSED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
