"""The status page of ``reachd --sim``, rendered by headless Chromium with live data.

Debian's ``chromium`` is installed by ``.ci/run``; this test does not skip without it.
The daemon runs the quick calibration (a solution, S11s, Dicke spectra, and the report
its run leaves), then a long wait that is still running while the page is read, with a
health alarm the site raises on purpose (any thermocouple above -100 degC).
"""

import gzip
import io
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from benchmarks.status_page_bytes import Client
from reach_receiver.cli import run_main
from reach_receiver.config.site import load_site
from reach_receiver.daemon.client import DaemonClient
from reach_receiver.daemon.status_page import StatusPage
from reach_receiver.errors import ReceiverError
from reach_receiver.sim.receiver import SimulationSettings, simulated_site

SCHEDULES = Path(__file__).resolve().parents[1] / "schedules"
ENTRY = "import sys; from reach_receiver.cli import reachd_main as m; sys.exit(m(sys.argv[1:]))"
ALARM = "thermocouple warm"
SITE_EXTRA = f"""\
daemon:
  status_port: 0
monitoring:
  alarms:
    - {{name: {ALARM}, metric: reach_tc08_temperature_celsius, above: -100.0, severity: warn}}
"""
#: A second job that waits (light on the CPU the page's figures need) while it is read.
LONG = """\
schedule: long look
steps:
  - wait: {seconds: 300000}
"""
FIGURES = ("spectra", "s11", "temperatures", "solution")


class Page(HTMLParser):
    """The page's text and image sources."""

    def __init__(self, text: str) -> None:
        super().__init__()
        self.images: list[str] = []
        self.words: list[str] = []
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        if tag == "img":
            self.images.append(dict(attrs)["src"])

    def handle_data(self, data):
        self.words.append(data)

    @property
    def text(self) -> str:
        return " ".join(" ".join(self.words).split())


def chromium(*args: str) -> subprocess.CompletedProcess:
    command = ["chromium", "--headless", "--no-sandbox", "--disable-gpu",
               "--disable-dev-shm-usage", "--hide-scrollbars", *args]
    return subprocess.run(command, capture_output=True, text=True, timeout=60, check=True)


@pytest.fixture
def reachd(tmp_path):
    site = tmp_path / "base-site.yaml"
    site.write_text(simulated_site(SimulationSettings()).to_yaml() + SITE_EXTRA)
    process = subprocess.Popen(
        [sys.executable, "-c", ENTRY, "--sim", "--site", str(site), "--state-dir",
         str(tmp_path / "state"), "--runtime-dir", str(tmp_path / "run"), "--site-out",
         str(tmp_path / "site.yaml")],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
        env={**os.environ, "NOTIFY_SOCKET": ""},
    )
    url = None
    for line in process.stdout:  # the page's line comes before "serving"
        found = re.search(r"status page (http://\S+)", line)
        url = found.group(1) if found else url
        if "serving" in line:
            break
    assert url is not None, "reachd printed no status page"
    yield url, tmp_path
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=60) == 0
    process.stdout.close()


def wait_for(predicate, timeout_s: float = 60.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError("timed out")


def test_the_page_shows_the_daemon_with_live_data_in_chromium(reachd):
    url, tmp = reachd
    host, port = re.match(r"http://([\d.]+):(\d+)/$", url).groups()
    # Bound to 127.0.0.1 itself: the listening socket's address, and another loopback
    # address (which 0.0.0.0 would accept) is refused.
    assert host == "127.0.0.1"
    listening = Path("/proc/net/tcp").read_text()
    assert re.search(rf"^\s*\d+: 0100007F:{int(port):04X} 00000000:0000 0A", listening, re.M)
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection(("127.0.0.2", int(port)), timeout=5).close()

    site = str(tmp / "site.yaml")
    assert run_main(["--site", site, str(SCHEDULES / "quick.yaml"), "--detach"]) == 0
    (tmp / "long.yaml").write_text(LONG)
    assert run_main(["--site", site, str(tmp / "long.yaml"), "--detach"]) == 0
    with DaemonClient(tmp / "run" / "control.sock") as client:
        def long_running():
            status = client.request("status")
            job = status.get("job") or {}
            return status if job.get("id") == 2 and status.get("step") else None

        status = wait_for(long_running)
        jobs = client.request("queue")["jobs"]
        assert [j["state"] for j in jobs] == ["completed", "running"]
        # The calibrating job left its report beside its run file, and said where.
        report = Path(jobs[0]["run"]) / "report"
        assert jobs[0]["report"] == str(report)
        assert "## Solution" in (report / "summary.md").read_text()
        assert (report / "parameters.png").stat().st_size > 10_000
        events = [m["event"] for m in client.follow(1)]
        assert events[-1]["report"] == str(report)
        assert any(e["kind"] == "log" and e["message"].startswith("report: ") for e in events)

    dom = chromium("--dump-dom", url).stdout
    page = Page(dom)
    assert "running" in page.text
    assert "2 long look" in page.text
    assert status["step"].split(":")[0] in page.text
    assert ALARM in page.text
    assert "time left" in page.text
    assert "Last calibration" in page.text
    assert "job 1 quick" in page.text
    assert "completed" in page.text
    assert "last spectrum" in page.text
    assert len(page.images) == len(FIGURES)
    for name, src in zip(FIGURES, page.images, strict=True):
        assert src == f"/figure/{name}"  # one address per figure: revalidated, not refetched
        with urllib.request.urlopen(url + src.lstrip("/"), timeout=60) as answer:
            kind, body = answer.headers["Content-Type"], answer.read()
        assert kind in ("image/png", "image/svg+xml"), name
        if kind == "image/png":
            image = np.asarray(Image.open(io.BytesIO(body)).convert("L"), float)
            assert image.shape[1] == 1150, name
            assert image.shape[0] > 300, name  # a figure, not a one-line note
            assert image.std() > 10, name  # not blank
        else:
            assert b"<svg" in body, name
            assert body.count(b"<path") > 20, name  # a figure, not a one-line note

    # Over the link: a conditional, gzip-accepting client gets the page and its figures
    # once (under 400 kB), then each reload under 60 kB (the HTML and 304s).
    client = Client(url, conditional=True)
    first = client.reload()
    reloads = [client.reload() for _ in range(3)]
    assert first < 400_000, first
    assert max(reloads) < 60_000, reloads
    assert client.get("/")[0][:2] == b"\x1f\x8b"  # gzipped
    assert client.get(page.images[0]) == (b"", 304)

    shot = tmp / "status-page.png"
    chromium(f"--screenshot={shot}", "--window-size=1200,4200", url)
    assert shot.stat().st_size > 50_000
    # Images off, on a narrow screen: the words alone still say what is going on.
    narrow = tmp / "status-page-narrow.png"
    chromium(f"--screenshot={narrow}", "--window-size=420,2400",
             "--blink-settings=imagesEnabled=false", url)
    with Image.open(narrow) as image:
        assert image.size[0] == 420
    if os.environ.get("REACH_KEEP_SCREENSHOT"):
        keep = Path(os.environ["REACH_KEEP_SCREENSHOT"])
        shutil.copy(shot, keep)
        shutil.copy(narrow, keep.with_name(keep.stem + "-narrow.png"))


def test_a_bad_status_port_is_reported_at_its_line(tmp_path):
    site = tmp_path / "site.yaml"
    text = simulated_site(SimulationSettings()).to_yaml()
    site.write_text(text + "daemon:\n  status_port: 80800\n")
    line = text.count("\n") + 2
    expected = rf"site.yaml:{line}: daemon.status_port: must be a port number"
    with pytest.raises(ReceiverError, match=expected):
        load_site(site)
    site.write_text(text + "daemon:\n  runtime_dir: /tmp\n")
    assert load_site(site).daemon.status_port is None  # no page unless asked
    site.write_text(text + "daemon:\n  status_port: 8470\n")
    again = tmp_path / "again.yaml"
    again.write_text(load_site(site).to_yaml())  # as reachd --site-out writes it back
    assert load_site(again).daemon.status_port == 8470


def _get(url: str, **headers: str):
    request = urllib.request.Request(url, headers=headers)
    try:
        with urllib.request.urlopen(request, timeout=60) as answer:
            return answer.status, answer.headers, answer.read()
    except urllib.error.HTTPError as err:
        return err.code, err.headers, err.read()


def test_a_figure_is_revalidated_until_its_data_change(tmp_path):
    runs = tmp_path / "runs"
    runs.mkdir()
    page = StatusPage(0, lambda: {"state": "idle", "status": "idle"}, runs, lambda: None)
    page.start()
    try:
        figure = page.url + "figure/s11"
        code, headers, body = _get(figure)
        assert code == 200
        assert body
        assert headers["Cache-Control"] == "no-cache"
        etag = headers["ETag"]
        assert page.figures.drawn == 1
        # The same data: 304 with no body and nothing drawn again, by ETag or by date.
        code, _, body = _get(figure, **{"If-None-Match": etag})
        assert (code, body) == (304, b"")
        code, _, _ = _get(figure, **{"If-Modified-Since": headers["Last-Modified"]})
        assert code == 304
        assert page.figures.drawn == 1
        # A new run (even one that cannot be read) is new data: a new tag, drawn again.
        (runs / "20260101T000000").mkdir()
        (runs / "20260101T000000" / "run.h5").write_bytes(b"not hdf5")
        code, headers, _ = _get(figure, **{"If-None-Match": etag})
        assert code == 200
        assert headers["ETag"] != etag
        assert page.figures.drawn == 2
        # The HTML: gzipped when accepted, the same bytes when not.
        code, headers, zipped = _get(page.url, **{"Accept-Encoding": "gzip"})
        assert headers["Content-Encoding"] == "gzip"
        assert b"no job yet" in gzip.decompress(zipped)
        code, headers, plain = _get(page.url)
        assert "Content-Encoding" not in headers
        assert b"no job yet" in plain
        assert _get(page.url + "figure/nothing")[0] == 404
    finally:
        page.close()
