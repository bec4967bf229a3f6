"""The control socket against clients that misbehave: no local client can stop it.

Real Unix sockets against a real :class:`ControlServer` (in this process, or in a child
with a low limit on file descriptors); the dispatcher is a small one answering
``status`` and streaming ``follow``, as the daemon's does.
"""

import json
import logging
import os
import socket
import stat
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from reach_receiver.daemon.client import DaemonClient, daemon_answers
from reach_receiver.daemon.connections import Connection, Ended, Limits
from reach_receiver.daemon.control import SOCKET_FILE, ControlServer
from reach_receiver.daemon.protocol import MAX_LINE, Closed, ControlError, reply

NOBODY = 65534
SERVICE_GROUP = 4242


def dispatch(request, peer):
    if request["op"] == "follow":
        return (reply(event={"n": n}, end=n == 3) for n in range(4) if not time.sleep(0.25))
    return reply(state="idle", uid=peer.uid)


def serve(path: Path, **limits) -> ControlServer:
    server = ControlServer(path, dispatch, limits=Limits(**limits))
    server.start()
    return server


@pytest.fixture
def socket_dir():
    with tempfile.TemporaryDirectory(prefix="reachd-limits-") as directory:
        yield Path(directory)


@pytest.fixture
def server(socket_dir):
    made = serve(socket_dir / SOCKET_FILE, idle_s=1.0, request_s=1.0, clients=8)
    yield made
    made.close()


OPENED: list[socket.socket] = []


@pytest.fixture(autouse=True)
def _close_raw_clients():
    yield
    while OPENED:
        OPENED.pop().close()


def raw(path: Path, timeout_s: float = 5.0) -> socket.socket:
    """A connection speaking bytes, closed after the test."""
    client = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    OPENED.append(client)
    client.settimeout(timeout_s)
    client.connect(str(path))
    return client


def last_word(client: socket.socket) -> tuple[dict, bool]:
    """The message the server sent, and whether it then closed the connection."""
    stream = client.makefile("rb")
    message = json.loads(stream.readline())
    try:
        closed = stream.readline() == b""
    except (ConnectionResetError, TimeoutError):
        closed = True
    return message, closed


def status_works(path: Path) -> bool:
    with DaemonClient(path, timeout_s=5.0) as client:
        return client.request("status")["state"] == "idle"


# ----------------------------------------------------------------- reading lines
def test_a_line_is_read_no_further_than_the_limit_plus_one_byte():
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    theirs.sendall(b"x" * 10_000)
    ours.setblocking(False)
    connection = Connection(ours, Limits(max_line=100))
    why = ""
    try:
        while connection.line() is None:
            connection.receive()
    except Ended as ended:
        why = f"{ended.why}: {ended}"
    assert why == "long: a line longer than 100 bytes"
    unread = len(ours.recv(20_000))
    assert 10_000 - unread == 101  # the rest was never taken from the kernel
    ours.close()
    theirs.close()


def test_an_over_long_line_is_refused_before_it_ends_and_the_connection_closed(server):
    client = raw(server.path)
    sent = 0
    try:  # the server stops reading and closes: a send fails
        while sent < 64 * 2**20:
            client.sendall(b"7" * 2**20)
            sent += 2**20
    except (BrokenPipeError, ConnectionResetError):
        pass
    assert sent <= MAX_LINE + 2**21
    message, closed = last_word(client)
    assert message["closed"] == "long"
    assert f"longer than {MAX_LINE} bytes" in message["error"]
    assert closed
    assert status_works(server.path)


BAD_LINES = {
    "deep nesting": b'{"v": 1, "op": ' + b"[" * 200_000 + b"]" * 200_000 + b"}",
    "5000-digit integer": b'{"v": 1, "op": "status", "n": ' + b"9" * 5000 + b"}",
    "invalid UTF-8": b'{"v": 1, "op": "st\xff\xfeatus"}',
    "not an object": b"[1, 2, 3]",
    "not JSON": b"GET / HTTP/1.1",
    "NaN": b'{"v": 1, "op": "status", "x": NaN}',
    "wrong version": b'{"v": 2, "op": "status"}',
    "binary": bytes(range(256)).replace(b"\n", b""),
}


@pytest.mark.parametrize("line", BAD_LINES.values(), ids=BAD_LINES.keys())
def test_every_line_that_is_not_a_request_is_answered_without_an_error_logged(
    server, line, caplog
):
    with caplog.at_level(logging.INFO, logger="reach_receiver.daemon"):
        client = raw(server.path)
        client.sendall(line + b"\n")
        message, closed = last_word(client)
    assert message["ok"] is False
    assert message["closed"] == "protocol", message
    assert closed
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert "not a request" in caplog.text
    assert status_works(server.path)


@pytest.mark.parametrize(("request_", "says"), [
    ({"op": "launch"}, "unknown op 'launch'"),
    ({"op": 7}, "unknown op 7"),
    ({"op": "cancel", "job": "abc"}, "'job' must be int, not 'abc'"),
    ({"op": "cancel", "job": True}, "'job' must be int"),
    ({"op": "cancel"}, "cancel needs 'job'"),
    ({"op": "follow", "job": [1]}, "'job' must be int or null"),
    ({"op": "solutions", "limit": 10**30}, "'limit' is 1 to 1000"),
    ({"op": "submit", "schedule": "x.yaml", "files": {"x.yaml": 3}}, "each path to its text"),
    ({"op": "submit", "schedule": None, "files": {}}, "'schedule' must be str"),
])
def test_a_request_with_wrong_fields_is_refused_and_the_connection_goes_on(
    server, request_, says
):
    fields = dict(request_)
    op = fields.pop("op")
    with DaemonClient(server.path) as client:
        with pytest.raises(ControlError) as refused:
            client.request(op, **fields)
        assert says in str(refused.value)
        assert client.request("status")["state"] == "idle"


# ----------------------------------------------------------------- holding connections
def test_a_silent_client_and_an_unfinished_line_are_timed_out(socket_dir):
    server = serve(socket_dir / SOCKET_FILE, idle_s=0.3, request_s=0.3)
    try:
        silent, slow = raw(server.path), raw(server.path)
        slow.sendall(b'{"v": 1, "op": "sta')
        start = time.monotonic()
        assert last_word(silent) == ({"v": 1, "ok": False, "closed": "idle",
                                      "error": "closed: no request in 0.3 s"}, True)
        message, closed = last_word(slow)
        assert message["closed"] == "timeout"
        assert closed
        assert time.monotonic() - start < 2.0
        assert len(server.connections) == 0
    finally:
        server.close()


def test_a_client_reconnects_after_the_daemon_closed_its_idle_connection(socket_dir):
    server = serve(socket_dir / SOCKET_FILE, idle_s=0.2)
    try:
        with DaemonClient(server.path) as client:
            assert client.request("status")["state"] == "idle"
            time.sleep(0.6)  # closed by the daemon meanwhile
            assert client.request("status")["state"] == "idle"
    finally:
        server.close()


def test_a_stream_outlives_the_idle_timeout(socket_dir):
    server = serve(socket_dir / SOCKET_FILE, idle_s=0.3)
    try:
        with DaemonClient(server.path) as client:
            events = [m["event"]["n"] for m in client.follow()]  # 1 s, no request meanwhile
            assert events == [0, 1, 2, 3]
            assert client.request("status")["state"] == "idle"
    finally:
        server.close()


def test_a_new_client_takes_the_place_of_the_longest_idle_one(server):
    idle = [raw(server.path) for _ in range(8)]
    time.sleep(0.2)
    assert len(server.connections) == 8
    assert status_works(server.path)  # a ninth: the first idle one made room
    message, closed = last_word(idle[0])
    assert message["closed"] == "idle"
    assert "another client" in message["error"]
    assert closed
    assert len(server.connections) <= 8
    for client in idle:
        client.close()


def test_when_no_client_is_idle_a_newcomer_is_told_too_many_connections(socket_dir):
    server = serve(socket_dir / SOCKET_FILE, clients=8, request_s=4.0)
    try:
        for _ in range(8):
            raw(server.path).sendall(b'{"v": 1, "op": ')  # a line begun: not idle
        time.sleep(0.2)
        with pytest.raises(Closed, match="too many connections") as refused:
            status_works(server.path)  # after trying again for a second
        assert refused.value.why == "busy"
        assert daemon_answers(server.path)  # busy is not absent
    finally:
        server.close()


def test_a_client_tries_again_while_the_daemon_is_busy(socket_dir):
    server = serve(socket_dir / SOCKET_FILE, clients=8, request_s=0.5)
    try:
        for _ in range(8):
            raw(server.path).sendall(b'{"v": 1, "op": ')
        time.sleep(0.2)
        assert status_works(server.path)  # the unfinished lines timed out meanwhile
    finally:
        server.close()


def test_a_burst_of_200_non_blocking_connects_all_succeed(server):
    clients = []
    try:
        for _ in range(200):
            client = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            client.setblocking(False)
            clients.append(client)
        failed = [c.connect_ex(str(server.path)) for c in clients]
        assert failed == [0] * 200
    finally:
        for client in clients:
            client.close()
    time.sleep(0.2)
    assert status_works(server.path)


def test_a_client_that_leaves_mid_line_frees_its_place(server):
    for _ in range(20):
        client = raw(server.path)
        client.sendall(b'{"v": 1, "op": "stat')
        client.close()
    deadline = time.monotonic() + 5
    while len(server.connections) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert len(server.connections) == 0
    assert status_works(server.path)


# ----------------------------------------------------------------- out of descriptors
CHILD = """\
import logging, resource, sys, time
from pathlib import Path
from reach_receiver.daemon.connections import Limits
from reach_receiver.daemon.control import ControlServer
from reach_receiver.daemon.protocol import reply
logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(message)s")
resource.setrlimit(resource.RLIMIT_NOFILE, (48, resource.getrlimit(resource.RLIMIT_NOFILE)[1]))
server = ControlServer(Path(sys.argv[1]), lambda r, p: reply(state="idle"),
                       limits=Limits(clients=200))
server.start()
print("serving", flush=True)
while server.serving:
    time.sleep(0.1)
"""


def test_out_of_descriptors_the_server_waits_drops_an_idle_client_and_goes_on(socket_dir):
    path = socket_dir / SOCKET_FILE
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(path)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline() == "serving\n"
        idle = [raw(path) for _ in range(60)]  # more than its 48 descriptors
        time.sleep(0.5)
        assert status_works(path)
        assert child.poll() is None
        for client in idle:
            client.close()
        time.sleep(0.3)
        assert all(status_works(path) for _ in range(5))
    finally:
        child.terminate()
        _, err = child.communicate(timeout=30)
    assert err.count("cannot accept a client") == 1, err  # once, not once a try
    assert "Too many open files" in err
    assert "Traceback" not in err


# ----------------------------------------------------------------- who may not, and a second one
# Imports first, as root (Python's files may be readable by root only), then another user.
CLIENT_AS = """\
import contextlib, io, json, os, sys
from pathlib import Path
from reach_receiver.cli import steer
from reach_receiver.daemon.client import DaemonClient, daemon_answers
uid, gid = int(sys.argv[1]), int(sys.argv[2])
os.setgroups([])
os.setgid(gid)
os.setuid(uid)
for path in map(Path, sys.argv[3:]):
    said = io.StringIO()
    with contextlib.redirect_stderr(said):
        code = steer.request(DaemonClient(path), "status", every=True)
    print(json.dumps({"answers": daemon_answers(path), "code": code, "said": said.getvalue()}))
"""


def test_a_user_outside_the_group_is_told_it_is_refused():
    assert os.geteuid() == 0, "a client of another user needs root to be made"
    servers = []
    for mode in (0o660, 0o666):  # 0666: a mistake in the mode, the daemon's check remains
        directory = Path(tempfile.mkdtemp(prefix="reachd-refused-"))
        directory.chmod(0o755)
        server = ControlServer(directory / SOCKET_FILE, dispatch, group=SERVICE_GROUP)
        server.start()
        server.path.chmod(mode)
        servers.append(server)
    try:
        done = subprocess.run(
            [sys.executable, "-c", CLIENT_AS, str(NOBODY), str(NOBODY),
             *(str(s.path) for s in servers)],
            capture_output=True, text=True, timeout=120,
        )
    finally:
        for server in servers:
            server.close()
            server.path.parent.rmdir()
    assert done.returncode == 0, done.stderr
    kernel, daemon = (json.loads(line) for line in done.stdout.splitlines())
    for answer, told_by in ((kernel, "no permission"), (daemon, f"uid {NOBODY}")):
        assert answer["answers"] is True  # a daemon is there, not "no daemon answers"
        assert answer["code"] == 1
        message = answer["said"].strip()
        assert message.startswith("reach-run status: refused: not a member of the service's group")
        assert told_by in message


def test_a_second_server_refused_on_the_path_leaves_the_first_one_s_socket(server):
    inode = server.path.stat().st_ino
    second = ControlServer(server.path, dispatch)
    with pytest.raises(ControlError, match="another daemon answers"):
        second.start()
    second.close()  # as a refused daemon does on its way out
    assert server.path.stat().st_ino == inode
    assert status_works(server.path)


def test_a_server_removes_only_the_socket_file_it_made(socket_dir):
    first = serve(socket_dir / SOCKET_FILE)
    first.path.unlink()  # replaced under it, as by another daemon
    other = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    other.bind(str(first.path))
    first.close()
    assert stat.S_ISSOCK(first.path.stat().st_mode)  # the other one's file stays
    other.close()
    again = serve(socket_dir / SOCKET_FILE)
    again.close()
    assert not again.path.exists()
