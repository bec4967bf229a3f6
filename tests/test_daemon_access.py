"""Who may talk to reachd, and when it stops feeding systemd's watchdog.

The control socket's access is the kernel's (the socket file's mode and group) and then
the server's own check of the peer's credentials: a client of another user and group is
refused by both, each tested with a real process under another uid. The watchdog tests
run a whole daemon on the simulated receiver with a fake ``NOTIFY_SOCKET``: a main loop
that hangs, or a daemon that is no longer healthy, must stop the WATCHDOG messages so
that systemd restarts the service.
"""

import dataclasses
import json
import logging
import os
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest

from reach_receiver.config.daemon import DaemonSettings
from reach_receiver.daemon.control import SOCKET_FILE, ControlServer
from reach_receiver.daemon.notify import Notifier
from reach_receiver.daemon.service import Daemon, Directories
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings, spectrum_period_for

NOBODY = 65534
SERVICE_GROUP = 4242  # a group the test's other users are not members of

# Runs as root, then becomes another user (Python is loaded first: its files may be in a
# directory only root can read) and asks the socket for its status.
CLIENT = """\
import json, os, socket, sys
path, uid, gid = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
os.setgroups([])
os.setgid(gid)
os.setuid(uid)
client = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
client.settimeout(10)
try:
    client.connect(path)
except PermissionError:
    print(json.dumps({"connect": "EACCES"}))
    sys.exit(0)
try:
    client.sendall(b'{"v": 1, "op": "status"}\\n')
except BrokenPipeError:  # a refusing server may answer and close before reading
    pass
print(json.dumps({"connect": "ok", "reply": json.loads(client.makefile().readline())}))
"""


def ask_as(path: Path, uid: int, gid: int) -> dict:
    """What a client running as ``uid:gid`` (no other groups) gets from the socket."""
    done = subprocess.run(
        [sys.executable, "-c", CLIENT, str(path), str(uid), str(gid)],
        capture_output=True, text=True, timeout=60, check=True,
    )
    return json.loads(done.stdout)


@pytest.fixture
def control_server():
    assert os.geteuid() == 0, "clients of other users need root to be made: run as root"
    # Not under pytest's tmp_path: that is private to root, and the kernel must refuse
    # on the socket's own mode, not on a directory above it.
    directory = Path(tempfile.mkdtemp(prefix="reachd-access-"))
    directory.chmod(0o755)
    server = ControlServer(
        directory / SOCKET_FILE, lambda request, peer: {"v": 1, "ok": True, "uid": peer.uid},
        group=SERVICE_GROUP,
    )
    server.start()
    yield server
    server.close()
    directory.rmdir()


def test_the_socket_admits_only_the_service_s_group(control_server):
    mode = control_server.path.stat()
    assert stat.S_ISSOCK(mode.st_mode)
    assert stat.S_IMODE(mode.st_mode) == 0o660
    assert mode.st_gid == SERVICE_GROUP
    assert ask_as(control_server.path, NOBODY, NOBODY) == {"connect": "EACCES"}


def test_a_member_of_the_group_is_answered_and_logged_with_its_uid(control_server, caplog):
    with caplog.at_level(logging.DEBUG, logger="reach_receiver.daemon.control"):
        answer = ask_as(control_server.path, NOBODY, SERVICE_GROUP)
    assert answer == {"connect": "ok", "reply": {"v": 1, "ok": True, "uid": NOBODY}}
    assert f"status from uid {NOBODY}" in caplog.text


def test_the_server_refuses_a_stranger_the_kernel_let_through(control_server, caplog):
    control_server.path.chmod(0o666)  # a mistake in the socket's mode
    with caplog.at_level(logging.WARNING, logger="reach_receiver.daemon.control"):
        answer = ask_as(control_server.path, NOBODY, NOBODY)
    assert answer["connect"] == "ok"
    assert answer["reply"]["ok"] is False
    assert "not a member of the service's group" in answer["reply"]["error"]
    assert f"refused uid {NOBODY}" in caplog.text


class Systemd:
    """A fake ``NOTIFY_SOCKET``: the times at which each kind of message came."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(str(path))
        self.sock.settimeout(0.05)
        self.received: list[tuple[float, str]] = []
        self._thread = threading.Thread(target=self._listen, daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        while True:
            try:
                data = self.sock.recv(4096).decode()
            except TimeoutError:
                continue
            except OSError:
                return
            self.received.append((time.monotonic(), data))

    def watchdogs(self, start: float, end: float) -> int:
        return sum(1 for t, m in self.received if start <= t < end and "WATCHDOG=1" in m)

    def close(self) -> None:
        self.sock.close()
        self._thread.join(timeout=5)


WATCHDOG_S = 0.4  # fed every 0.2 s while healthy


@pytest.fixture
def daemon(tmp_path):
    systemd = Systemd(tmp_path / "notify.sock")
    notifier = Notifier({"NOTIFY_SOCKET": str(systemd.path),
                         "WATCHDOG_USEC": str(int(WATCHDOG_S * 1e6))})
    settings = SimulationSettings(compression=3000.0, spectrum_period_s=spectrum_period_for(3000.0))
    with SimulatedReceiver(settings) as sim:
        directories = Directories(tmp_path / "run", tmp_path / "state")
        site = dataclasses.replace(sim.site(), daemon=DaemonSettings(
            runtime_dir=directories.runtime, state_dir=directories.state))
        reachd = Daemon(site, sim.clock, directories, notifier=notifier, tick_s=0.05)
        reachd.start()
        serving = threading.Thread(target=reachd.serve)
        serving.start()
        yield reachd, systemd
        reachd.halt("test over")
        serving.join(timeout=60)
        reachd.close()
    systemd.close()


def test_a_hung_main_loop_starves_the_watchdog_and_a_free_one_feeds_it(daemon):
    reachd, systemd = daemon
    time.sleep(1.0)
    fed = time.monotonic()
    time.sleep(1.0)
    assert systemd.watchdogs(fed, time.monotonic()) >= 3
    with reachd._loop:  # the main loop's turn cannot run: as if stuck in a device call
        hung = time.monotonic()
        time.sleep(1.5)
        assert systemd.watchdogs(hung + 0.1, time.monotonic()) == 0  # systemd would restart
    free = time.monotonic()
    time.sleep(1.0)
    assert systemd.watchdogs(free, time.monotonic()) >= 3


def test_a_daemon_whose_socket_died_stops_feeding_the_watchdog(daemon):
    reachd, systemd = daemon
    time.sleep(0.5)
    reachd.server.close()  # the control socket's thread is gone: not healthy
    dead = time.monotonic()
    time.sleep(1.5)
    assert not reachd.healthy()
    assert systemd.watchdogs(dead + 0.1, time.monotonic()) == 0
    assert any("STATUS=" in m for _, m in systemd.received)
