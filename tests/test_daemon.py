"""``reachd --sim`` as a subprocess: the control socket, the queue, reach-run as its client."""

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from reach_receiver.cli import run_main
from reach_receiver.daemon.client import DaemonClient
from reach_receiver.daemon.protocol import ControlError
from reach_receiver.store import read_run_file

ENTRY = "from reach_receiver.cli import {main}; import sys; sys.exit({main}(sys.argv[1:]))"
SHORT = """\
schedule: {name}
steps:
  - initialise: {{rails: [12v, 24v, 6v]}}
  - dicke: {{sources: [{sources}], seconds: 600}}
  - safe
"""


def python(main: str, *args: str, **options) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", ENTRY.format(main=main), *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **options,
    )


class Reachd:
    """A ``reachd --sim`` in its own process, with a fake systemd notification socket."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.site = root / "site.yaml"
        self.notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.notify.bind(str(root / "notify.sock"))
        self.notify.settimeout(0.2)
        self.received: list[str] = []
        self.listening = threading.Thread(target=self._listen, daemon=True)
        self.listening.start()
        env = {**os.environ, "NOTIFY_SOCKET": str(root / "notify.sock"), "WATCHDOG_USEC": "2000000"}
        self.process = python(
            "reachd_main", "--sim", "--state-dir", str(root / "state"), "--runtime-dir",
            str(root / "run"), "--site-out", str(self.site), env=env,
        )
        deadline = time.monotonic() + 60
        while not (root / "run" / "control.sock").exists():
            assert self.process.poll() is None, self.process.communicate()
            assert time.monotonic() < deadline, "reachd did not start"
            time.sleep(0.05)

    def client(self) -> DaemonClient:
        return DaemonClient(self.root / "run" / "control.sock")

    def _listen(self) -> None:
        while True:  # as systemd does: read every notification as it comes
            try:
                self.received.append(self.notify.recv(4096).decode())
            except TimeoutError:
                continue
            except OSError:
                return

    def messages(self) -> list[str]:
        return list(self.received)

    def stop(self, sig=signal.SIGTERM) -> int:
        if self.process.poll() is None:
            self.process.send_signal(sig)
        try:
            code = self.process.wait(timeout=60)
        finally:
            self.process.communicate()
            time.sleep(0.3)
            self.notify.close()
        return code


@pytest.fixture
def reachd(tmp_path):
    daemon = Reachd(tmp_path)
    yield daemon
    if daemon.process.poll() is None:
        daemon.stop()


def write(tmp_path: Path, name: str, sources: str) -> Path:
    path = tmp_path / f"{name}.yaml"
    path.write_text(SHORT.format(name=name, sources=sources))
    return path


def wait_for(client: DaemonClient, job: int, *states: str, timeout_s: float = 60.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = [j for j in client.request("queue")["jobs"] if j["id"] == job]
        if found and found[0]["state"] in states:
            return found[0]
        time.sleep(0.05)
    raise AssertionError(f"job {job} never reached {states}")


def test_jobs_queue_run_and_can_be_cancelled_and_aborted(reachd, tmp_path, capsys):
    long = write(tmp_path, "long", "cold, hot, r25, r100, c2r27, c2r36")
    short = write(tmp_path, "short", "cold")
    site = str(reachd.site)
    assert run_main(["--site", site, str(long), "--detach"]) == 0
    assert run_main(["--site", site, str(short), "--detach"]) == 0
    assert run_main(["--site", site, str(short), "--detach"]) == 0
    with reachd.client() as client:
        wait_for(client, 1, "running")
        queued = client.request("status")["queue"]
        assert queued == [2, 3]  # the second submission queues behind the first
        assert client.request("cancel", job=3)["job"]["state"] == "cancelled"
        end = [m for m in client.follow(1)][-1]["event"]
        assert end["state"] == "completed", end  # its error, if it failed
        assert read_run_file(Path(end["run"]) / "run.h5").status == "completed"
        wait_for(client, 2, "running", "completed")
        client.request("abort")  # job 2 stops now, the front-end goes safe
        aborted = wait_for(client, 2, "interrupted")
        assert "aborted by uid" in aborted["reason"]
        contents = read_run_file(Path(aborted["run"]) / "run.h5")
        assert contents.status == "interrupted"
        (event,) = [m for m in contents.of_kind("event") if m.name == "interrupted"]
        for pin in ("ns=0", "6v=0", "12v=0", "ms1=0", "mts=lna"):
            assert pin in event.attrs["message"]
        status = client.request("status")
        assert status["paused"] is True
        assert status["state"] == "idle"
        with pytest.raises(ControlError, match="nothing to cancel"):
            client.request("cancel", job=1)
        client.request("resume")
        assert client.request("status")["paused"] is False
    assert reachd.stop() == 0
    messages = reachd.messages()
    assert any("READY=1" in m for m in messages)
    assert any("STATUS=running: job 1 long" in m for m in messages)
    assert any("WATCHDOG=1" in m for m in messages)
    assert any("STOPPING=1" in m for m in messages)


def test_a_bad_schedule_comes_back_with_its_lines_and_nothing_is_queued(reachd, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        "schedule: bad\nsteps:\n  - initialise\n  - dicke: {sources: [sky], seconds: 60}\n"
    )
    with reachd.client() as client:
        with pytest.raises(ControlError) as refused:
            client.request("submit", schedule=str(bad), files={str(bad): bad.read_text()})
        assert any(f"{bad}:4: dicke.sources[0]" in p for p in refused.value.problems)
        assert client.request("queue")["jobs"] == []


def test_reach_run_follows_detaches_and_attaches_again(reachd, tmp_path):
    schedule = write(tmp_path, "follow", "cold, hot, r25, r100")
    # Six hours of waiting after the Dicke cycle (7 s real at the simulator's 3000x): the
    # run is still going when the detaching Ctrl-C arrives, however loaded the machine.
    schedule.write_text(schedule.read_text().replace(
        "  - safe\n", "  - wait: {seconds: 21600}\n  - safe\n"))
    follower = python("run_main", "--site", str(reachd.site), str(schedule))
    deadline = time.monotonic() + 60
    lines = []
    while not any("Dicke" in line for line in lines):
        assert time.monotonic() < deadline, lines
        lines.append(follower.stderr.readline())
    follower.send_signal(signal.SIGINT)  # detach: the run goes on
    out, err = follower.communicate(timeout=30)
    assert follower.returncode == 0
    assert "detached from job 1" in out, (lines, out, err)
    with reachd.client() as client:
        assert wait_for(client, 1, "running", "completed")["state"] in ("running", "completed")
    again = python("run_main", "--site", str(reachd.site), "--attach", "1")
    out, err = again.communicate(timeout=120)
    assert again.returncode == 0, err
    assert "job 1 completed" in out


def test_sigterm_stops_the_run_safely_and_the_daemon_cleanly(reachd, tmp_path):
    schedule = write(tmp_path, "stopped", "cold, hot, r25, r100, c2r27, c2r36")
    assert run_main(["--site", str(reachd.site), str(schedule), "--detach"]) == 0
    with reachd.client() as client:
        job = wait_for(client, 1, "running")
        deadline = time.monotonic() + 60
        while not job.get("run") and time.monotonic() < deadline:
            time.sleep(0.05)
            job = wait_for(client, 1, "running")
    time.sleep(0.5)
    assert reachd.stop(signal.SIGTERM) == 0
    runs = list((tmp_path / "state" / "runs").iterdir())
    (run,) = runs
    contents = read_run_file(run / "run.h5")
    assert contents.status == "interrupted"
    assert "signal SIGTERM" in contents.reason
    assert "front-end in its safe state" in contents.reason
