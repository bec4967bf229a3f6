"""What an operator reads in an 80x24 terminal: no line wider than 80 columns.

The commands run inside a real tmux at 80x24; ``capture-pane -J`` joins the lines the
terminal wrapped, so a line that did not fit shows as one longer than 80. tmux is
Debian's package, which ``.ci/run`` installs where it is missing.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from reach_receiver.daemon.client import DaemonClient
from reach_receiver.daemon.protocol import Closed, ControlError

ROOT = Path(__file__).resolve().parents[1]
ENTRY = "import sys; from reach_receiver.cli import {main}; sys.exit({main}(sys.argv[1:]))"
#: A short calibration, as tests/test_follow_output.py follows it.
FOLLOWED = """\
schedule: follow
steps:
  - initialise: {}
  - temperatures: {period_s: 10}
  - vna_calibrate: {}
  - s11: {targets: [cold, hot, c10open, c10short, ant, lna]}
  - dicke: {sources: [cold, hot, c10open, c10short], seconds: 60}
  - calibrate: {}
  - safe: {}
"""


def in_tmux(
    tmp_path: Path, *args: str, main: str = "run_main", within_s: float = 60.0
) -> list[str]:
    """Run a command in a detached 80x24 tmux; its lines as the terminal showed them."""
    tmp_path = Path(tempfile.mkdtemp(dir=tmp_path))  # one per command
    socket = str(tmp_path / "tmux.sock")
    done = tmp_path / "done"
    command = shlex.join([sys.executable, "-c", ENTRY.format(main=main), *args])
    script = f"cd {shlex.quote(str(ROOT))}; {command}; touch {shlex.quote(str(done))}; sleep 600"
    tmux = ["tmux", "-S", socket, "-f", "/dev/null"]
    env = {**os.environ, "TERM": "xterm-256color", "COLUMNS": "", "LINES": ""}
    subprocess.run([*tmux, "new-session", "-d", "-x", "80", "-y", "24", "sh", "-c", script],
                   check=True, env=env, timeout=30)
    try:
        deadline = time.monotonic() + within_s
        while not done.exists():
            assert time.monotonic() < deadline, "the command did not end"
            time.sleep(0.1)
        shown = subprocess.run([*tmux, "capture-pane", "-p", "-J", "-S", "-2000"],
                               check=True, capture_output=True, text=True, timeout=30).stdout
    finally:
        subprocess.run([*tmux, "kill-server"], check=False, timeout=30)
    return [line.rstrip() for line in shown.splitlines() if line.strip()]


def test_the_dry_run_timeline_fits_80_columns(tmp_path):
    lines = in_tmux(tmp_path, "--sim", "--dry-run", "schedules/observe.yaml")
    assert any("total" in line for line in lines)
    assert max(map(len, lines)) <= 80, max(lines, key=len)


def _teensy_up(socket: Path) -> bool:
    """Whether the daemon's first health reading of the Teensy's link says up (a loaded
    machine answers on the socket before the simulated devices are brought up)."""
    try:
        with DaemonClient(socket) as client:
            readings = client.request("status")["health"].get("readings", [])
    except (OSError, ControlError, Closed):
        return False
    return any(r.get("key") == "reach_device_up{device=teensy}" and r.get("value") == 1
               for r in readings)


@pytest.fixture
def reachd(tmp_path: Path) -> Iterator[Path]:
    """A ``reachd --sim``; the site file that finds it."""
    site = tmp_path / "site.yaml"
    process = subprocess.Popen(
        [sys.executable, "-c", ENTRY.format(main="reachd_main"), "--sim", "--state-dir",
         str(tmp_path / "state"), "--runtime-dir", str(tmp_path / "run"), "--site-out",
         str(site)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 60
        while not ((tmp_path / "run" / "control.sock").exists() and site.exists()
                   and _teensy_up(tmp_path / "run" / "control.sock")):
            assert process.poll() is None, "reachd --sim exited"
            assert time.monotonic() < deadline, "reachd did not bring its devices up"
            time.sleep(0.2)
        yield site
    finally:
        process.terminate()
        process.wait(30)


def test_status_is_a_summary_within_80_columns(tmp_path, reachd):
    lines = in_tmux(tmp_path, "status", "--site", str(reachd))
    assert lines[0].startswith("state:     idle")
    assert any(line.startswith("devices:   ") and "teensy up" in line for line in lines)
    assert any(line.startswith("last calibration: ") for line in lines)
    assert len(lines) <= 24
    assert max(map(len, lines)) <= 80, max(lines, key=len)
    every = in_tmux(tmp_path, "status", "--all", "--site", str(reachd))
    assert len(every) > len(lines)
    assert max(map(len, every)) <= 80, max(every, key=len)


def test_a_followed_job_fits_80_columns(tmp_path, reachd):
    """``reach-run SCHEDULE`` against the daemon, followed to its end as an operator sees it.

    Every line within 80 columns, a path counted as the short one an operator's would be
    (this test's directory is pytest's, some 60 characters); the job's result and its
    end are on the screen.
    """
    schedule = tmp_path / "follow.yaml"
    schedule.write_text(FOLLOWED)
    lines = in_tmux(tmp_path, "--site", str(reachd), str(schedule), within_s=240.0)
    assert lines[-1] == "job 1 completed", lines
    assert any("noise scale s^2" in line for line in lines), lines
    shown = [line.replace(str(tmp_path), "/srv/reach") for line in lines]
    wide = [line for line in shown if len(line) > 80]
    assert not wide, wide
