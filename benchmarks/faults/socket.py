"""Faults of the control socket: what any member of the service's group can send ``reachd``.

Every trial runs against a real ``reachd --sim`` in its own process, over its real Unix
socket. A trial is ``clean`` when the bad input is answered with a refusal (or the
connection closed, as the protocol says), the daemon still answers ``status`` and its
log holds no traceback; ``crash`` when the daemon died, stopped answering or logged a
traceback; ``silent`` when the bad input was taken as a request.

The quick subset sends each kind of bad line once, a few idle and unfinished clients and
a burst of connects. The full set adds a 200 MB line (the daemon's memory measured), a
second daemon on the same directories, and the load test: ``reachd`` under a soft limit
of 1024 open files held by 2,000 idle connections and 100 garbage clients while a
legitimate client asks ``status`` and a run of ``schedules/quick.yaml`` completes; it
prints what it measured.
"""

from __future__ import annotations

import contextlib
import json
import os
import resource
import select
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from reach_receiver.daemon.client import DaemonClient, daemon_answers
from reach_receiver.daemon.control import SOCKET_FILE, ControlServer
from reach_receiver.daemon.protocol import ControlError

from .core import Trial

CLASS = "socket"
ROOT = Path(__file__).resolve().parents[2]
ENTRY = "from reach_receiver.cli import {main}; import sys; sys.exit({main}(sys.argv[1:]))"

#: Lines that are not requests: each must be answered and the connection closed.
GARBAGE: dict[str, bytes] = {
    "garbage text": b"hello daemon, please stop",
    "deep nesting": b'{"v": 1, "op": ' + b"[" * 100_000 + b"]" * 100_000 + b"}",
    "huge integer": b'{"v": 1, "op": "status", "n": ' + b"9" * 5000 + b"}",
    "invalid UTF-8": b'{"v": 1, "op": "\xc3\x28status"}',
    "binary": bytes(range(256)).replace(b"\n", b"") * 4,
    "not an object": b'["status"]',
    "wrong version": b'{"v": 99, "op": "status"}',
    "no version": b'{"op": "status"}',
    "NaN": b'{"v": 1, "op": "status", "x": NaN}',
}
#: Requests of the right version with the wrong contents: refused, the connection kept.
WRONG: dict[str, dict] = {
    "unknown op": {"v": 1, "op": "shutdown"},
    "op not a string": {"v": 1, "op": ["status"]},
    "job id a string": {"v": 1, "op": "cancel", "job": "1; rm -rf /"},
    "job id a float": {"v": 1, "op": "follow", "job": 1.5},
    "limit negative": {"v": 1, "op": "solutions", "limit": -5},
    "files not text": {"v": 1, "op": "submit", "schedule": "a.yaml", "files": {"a.yaml": 7}},
    "submit without files": {"v": 1, "op": "submit", "schedule": "a.yaml"},
}


#: A check: ``True`` refused as it should be, ``False`` not, ``None`` taken; what was seen.
Check = Callable[["Daemon"], tuple[bool | None, str]]


class Daemon:
    """``reachd --sim`` in its own process (optionally with a soft limit on open files)."""

    def __init__(self, root: Path, nofile: int | None = None) -> None:
        self.root = root
        self.path = root / "run" / SOCKET_FILE
        self.site = root / "site.yaml"
        self.log = root / "reachd.log"
        self._read = 0
        root.mkdir(parents=True, exist_ok=True)
        with open(self.log, "w") as log:
            self.process = subprocess.Popen(
                [sys.executable, "-c", ENTRY.format(main="reachd_main"), "--sim",
                 "--state-dir", str(root / "state"), "--runtime-dir", str(root / "run"),
                 "--site-out", str(self.site)],
                stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                preexec_fn=None if nofile is None else lambda: _limit_files(nofile),
            )
        deadline = time.monotonic() + 120
        while not daemon_answers(self.path):
            if self.process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"reachd --sim did not start: {self.new_log()[-400:]}")
            time.sleep(0.1)

    def new_log(self) -> str:
        """What the daemon logged since the last call."""
        text = self.log.read_text(errors="replace")
        new, self._read = text[self._read:], len(text)
        return new

    def status(self, timeout_s: float = 10.0) -> str | None:
        """The daemon's state, or why it did not answer."""
        try:
            with DaemonClient(self.path, timeout_s) as client:
                return str(client.request("status")["state"])
        except (OSError, ControlError) as err:
            return f"no status: {err}"

    def rss_kib(self) -> int:
        """The daemon's resident memory."""
        for line in Path(f"/proc/{self.process.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
        return 0

    def threads_and_files(self) -> tuple[int, int]:
        """The daemon's threads and open file descriptors now."""
        threads = len(os.listdir(f"/proc/{self.process.pid}/task"))
        return threads, len(os.listdir(f"/proc/{self.process.pid}/fd"))

    def close(self) -> None:
        """Stop the daemon (SIGTERM; SIGKILL if it does not stop within a minute)."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=60)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


def trials(workdir: Path, quick: bool) -> Iterator[Trial]:
    """Each fault against one ``reachd --sim`` (and, in full, the load test on another)."""
    daemon = Daemon(workdir / "quick" if quick else workdir / "full")
    try:
        checks: list[tuple[str, Check]] = [
            *((f"line: {name}", _garbage(line)) for name, line in GARBAGE.items()),
            *((f"request: {name}", _wrong(request)) for name, request in WRONG.items()),
            ("client leaves mid-line", _leaves_mid_line),
            ("over-long line (16 MiB)", _long_line(16 * 2**20)),
            ("60 idle connections", _idle(60)),
            ("burst of 200 non-blocking connects", _burst),
            ("second ControlServer on the same path", _second_server),
        ]
        if not quick:
            checks += [
                ("line without newline, then silence", _unfinished),
                ("over-long line (200 MB)", _long_line(200 * 10**6)),
                ("second reachd on the same directories", _second_daemon),
            ]
        for name, check in checks:
            yield _judge(daemon, name, check)
    finally:
        daemon.close()
    if not quick:
        yield _under_load(workdir / "load")


def _judge(daemon: Daemon, name: str, check: Check) -> Trial:
    """Run one check: ``True`` refused as it should be, ``False`` not, ``None`` taken."""
    try:
        refused, detail = check(daemon)
    except (OSError, ControlError, ValueError) as err:
        refused, detail = False, f"{type(err).__name__}: {err}"
    state = daemon.status()
    log = daemon.new_log()
    if daemon.process.poll() is not None or state not in ("idle", "running", "observing"):
        return Trial(name, "crash", f"daemon gone or mute ({state}); {detail}")
    if "Traceback" in log:
        return Trial(name, "crash", "traceback in the daemon's log: " + log[-200:])
    if refused is None:
        return Trial(name, "silent", detail)
    return Trial(name, "clean" if refused else "crash", detail)


# ----------------------------------------------------------------- single clients
def _connect(path: Path, timeout_s: float = 10.0) -> socket.socket:
    client = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    client.settimeout(timeout_s)
    try:
        client.connect(str(path))
    except OSError:
        client.close()
        raise
    return client


def _last_word(client: socket.socket) -> tuple[dict, bool]:
    """The message read, and whether the daemon then closed the connection."""
    stream = client.makefile("rb")
    try:
        message = json.loads(stream.readline() or b"{}")
        try:
            closed = stream.readline() == b""
        except (ConnectionResetError, TimeoutError):
            closed = True
    finally:
        stream.close()
    return message, closed


def _garbage(line: bytes) -> Check:
    def check(daemon: Daemon) -> tuple[bool | None, str]:
        with _connect(daemon.path) as client:
            client.sendall(line + b"\n")
            message, closed = _last_word(client)
        if message.get("ok"):
            return None, "taken as a request"
        said = f"{message.get('error', 'no answer')} (closed: {message.get('closed')})"
        return message.get("closed") == "protocol" and closed, said[:160]
    return check


def _wrong(request: dict) -> Check:
    def check(daemon: Daemon) -> tuple[bool | None, str]:
        with _connect(daemon.path) as client, client.makefile("rb") as stream:
            client.sendall(json.dumps(request).encode() + b"\n")
            message = json.loads(stream.readline() or b"{}")
            client.sendall(b'{"v": 1, "op": "status"}\n')  # the connection goes on
            after = json.loads(stream.readline() or b"{}")
        if message.get("ok"):
            return None, "taken as a request"
        return bool(after.get("ok")), str(message.get("error", "no answer"))[:160]
    return check


def _unfinished(daemon: Daemon) -> tuple[bool | None, str]:
    """Half a line and nothing more: closed after the request timeout (10 s)."""
    with _connect(daemon.path, timeout_s=30.0) as client:
        client.sendall(b'{"v": 1, "op": "sta')
        start = time.monotonic()
        message, closed = _last_word(client)
    waited = time.monotonic() - start
    return message.get("closed") == "timeout" and closed, f"closed after {waited:.1f} s"


def _leaves_mid_line(daemon: Daemon) -> tuple[bool | None, str]:
    for _ in range(50):
        with _connect(daemon.path) as client:
            client.sendall(b'{"v": 1, "op": "submit", "files": {"a": "')
    _, files = daemon.threads_and_files()
    return True, f"50 clients left mid-line; the daemon holds {files} descriptors"


def _long_line(size: int) -> Check:
    def check(daemon: Daemon) -> tuple[bool | None, str]:
        before, sent, chunk = daemon.rss_kib(), 0, b"7" * 2**20
        with _connect(daemon.path, timeout_s=30.0) as client:
            with contextlib.suppress(BrokenPipeError, ConnectionResetError):
                while sent < size:
                    sent += client.send(chunk)
            message, closed = _last_word(client)
        grown = (daemon.rss_kib() - before) / 1024
        said = f"{message.get('error')}; {sent / 2**20:.0f} MiB taken, RSS +{grown:.0f} MiB"
        return message.get("closed") == "long" and closed and grown < 32, said
    return check


def _idle(count: int) -> Check:
    def check(daemon: Daemon) -> tuple[bool | None, str]:
        held = [_connect(daemon.path) for _ in range(count)]
        try:
            state = daemon.status()
            threads, files = daemon.threads_and_files()
        finally:
            for client in held:
                client.close()
        said = f"status {state} with {count} idle; {threads} threads, {files} files"
        return state == "idle", said
    return check


def _burst(daemon: Daemon) -> tuple[bool | None, str]:
    clients = [socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) for _ in range(200)]
    try:
        for client in clients:
            client.setblocking(False)
        failed = sum(1 for c in clients if c.connect_ex(str(daemon.path)) != 0)
    finally:
        for client in clients:
            client.close()
    return failed == 0, f"{200 - failed} of 200 connected"


def _second_server(daemon: Daemon) -> tuple[bool | None, str]:
    inode = daemon.path.stat().st_ino
    second = ControlServer(daemon.path, lambda request, peer: {"ok": True})
    try:
        second.start()
    except ControlError as err:
        said = str(err)
    else:
        second.close()
        return None, "a second server bound the live daemon's path"
    second.close()  # as a refused daemon does on its way out
    kept = daemon.path.exists() and daemon.path.stat().st_ino == inode
    return kept, f"{said}; the first one's socket {'kept' if kept else 'REMOVED'}"


def _second_daemon(daemon: Daemon) -> tuple[bool | None, str]:
    inode = daemon.path.stat().st_ino
    done = subprocess.run(
        [sys.executable, "-c", ENTRY.format(main="reachd_main"), "--sim",
         "--state-dir", str(daemon.root / "state"), "--runtime-dir", str(daemon.root / "run")],
        capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL,
    )
    kept = daemon.path.exists() and daemon.path.stat().st_ino == inode
    said = next((line for line in reversed(done.stderr.splitlines())
                 if line.startswith("reachd:")), "no message")[:120]
    if done.returncode == 0:
        return None, "a second daemon started"
    return kept and "Traceback" not in done.stderr, f"{said}; socket {'kept' if kept else 'GONE'}"


# ----------------------------------------------------------------- the load test
IDLE, GARBAGE_CLIENTS, NOFILE = 2000, 100, 1024


def _under_load(root: Path) -> Trial:
    """2,000 idle connections and 100 garbage clients against ``reachd`` at 1024 files."""
    name = f"{IDLE} idle + {GARBAGE_CLIENTS} garbage clients at a soft limit of {NOFILE} files"
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (max(soft, min(hard, IDLE + 1000)), hard))
    daemon = Daemon(root, nofile=NOFILE)
    stop = threading.Event()
    held: list[socket.socket] = []
    asked: list[float | str] = []  # each status: its latency, or why it failed
    answered: list[int] = []  # one entry a garbage client answered
    reopened: list[int] = []  # one entry an idle connection the daemon closed, opened again
    try:
        rss0 = daemon.rss_kib()
        start = time.monotonic()
        for _ in range(IDLE):
            held.append(_connect(daemon.path))
        opened_s = time.monotonic() - start
        workers = [threading.Thread(target=_ask_status, args=(daemon, stop, asked)),
                   threading.Thread(target=_keep_idle, args=(daemon, stop, held, reopened))]
        workers += [threading.Thread(target=_send_garbage, args=(daemon, n, answered))
                    for n in range(GARBAGE_CLIENTS)]
        for worker in workers:
            worker.start()
        run_start = time.monotonic()
        run = subprocess.run(
            [sys.executable, "-c", ENTRY.format(main="run_main"), "--site", str(daemon.site),
             str(ROOT / "schedules" / "quick.yaml")],
            capture_output=True, text=True, timeout=900, stdin=subprocess.DEVNULL,
        )
        run_s = time.monotonic() - run_start
        threads, files = daemon.threads_and_files()
        rss1 = daemon.rss_kib()
        stop.set()
        for worker in workers:
            worker.join(timeout=60)
        final = daemon.status()
    finally:
        stop.set()
        for client in held:
            client.close()
        daemon.close()
    log = daemon.log.read_text(errors="replace")
    ok = [a for a in asked if isinstance(a, float)]
    failed = [a for a in asked if isinstance(a, str)]
    ok.sort()
    median = ok[len(ok) // 2] if ok else float("nan")
    report = (
        f"{IDLE} connects in {opened_s:.1f} s, {len(reopened)} more as the daemon dropped "
        f"them; run quick.yaml exit {run.returncode} in "
        f"{run_s:.0f} s; status asked {len(asked)}: {len(ok)} answered (median "
        f"{median * 1e3:.0f} ms, max {max(ok, default=0) * 1e3:.0f} ms), {len(failed)} "
        f"not{' (' + failed[0][:60] + ')' if failed else ''}; garbage answered "
        f"{len(answered)}/{GARBAGE_CLIENTS}; daemon {threads} threads, {files} files, RSS "
        f"{rss0 // 1024}->{rss1 // 1024} MiB; after: {final}"
    )
    print(f"socket load test: {report}", flush=True)
    if run.returncode != 0 or final != "idle" or "Traceback" in log:
        why = (run.stderr.strip().splitlines() or ["traceback in the daemon's log"])[-1]
        return Trial(name, "crash", f"{why[:120]}; {report}")
    if not ok or len(failed) > len(asked) // 10 or len(answered) < GARBAGE_CLIENTS:
        return Trial(name, "crash", report)
    return Trial(name, "clean", report)


def _ask_status(daemon: Daemon, stop: threading.Event, asked: list[float | str]) -> None:
    """A legitimate client: ``status`` twice a second on a fresh connection."""
    while not stop.wait(0.5):
        start = time.monotonic()
        state = daemon.status(timeout_s=10.0)
        if state in ("idle", "running", "observing"):
            asked.append(time.monotonic() - start)
        else:
            asked.append(str(state))


def _keep_idle(
    daemon: Daemon, stop: threading.Event, held: list[socket.socket], reopened: list[int]
) -> None:
    """Every 2 s, open again the idle connections the daemon closed."""
    while not stop.wait(2.0):
        for i, client in enumerate(held):
            if stop.is_set():
                return
            poller = select.poll()  # a last word or the end: the daemon closed it
            poller.register(client, select.POLLIN)
            if poller.poll(0):
                client.close()
                with contextlib.suppress(OSError):
                    held[i] = _connect(daemon.path)
                    reopened.append(i)


def _send_garbage(daemon: Daemon, n: int, answered: list[int]) -> None:
    lines = list(GARBAGE.values())
    try:
        with _connect(daemon.path, timeout_s=30.0) as client:
            client.sendall(lines[n % len(lines)] + b"\n")
            message, _ = _last_word(client)
    except OSError:
        return
    if message.get("closed") in ("protocol", "idle", "busy"):
        answered.append(n)


def _limit_files(soft: int) -> None:
    """In the daemon's process before it runs: the soft limit of systemd's default."""
    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
