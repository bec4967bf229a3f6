"""A client of the daemon's control socket (:mod:`.protocol`), as ``reach-run`` uses it.

A daemon that will not talk to this user (the socket's mode, or the daemon's own check
of the peer's group) is a :class:`~.protocol.Closed` refusal that says so, not a daemon
that is missing. A connection the daemon ended while it was idle is opened again before
the next request (the request had not been sent).
"""

from __future__ import annotations

import contextlib
import select
import socket
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO

from .control import SOCKET_FILE
from .protocol import MAX_LINE, Closed, ControlError, decode, encode

#: What a user outside the service's group is told.
NOT_A_MEMBER = "refused: not a member of the service's group"
#: The pauses before a request the daemon could not take is sent again (module's text).
RETRY_PAUSES_S = (0.1, 0.3, 0.6)


def socket_path(runtime_dir: Path) -> Path:
    """Where the daemon of a runtime directory listens."""
    return Path(runtime_dir) / SOCKET_FILE


def daemon_answers(path: Path, timeout_s: float = 2.0) -> bool:
    """Whether a daemon listens on ``path`` (a socket file alone is not enough).

    A daemon that refuses this user, or is busy, answers too: the request made next is
    refused in turn, and says why.
    """
    if not path.exists():
        return False
    try:
        with DaemonClient(path, timeout_s) as client:
            client.request("status")
    except Closed:
        return True
    except (OSError, ControlError):
        return False
    return True


class DaemonClient:
    """One connection to the daemon; requests in turn, replies as dicts.

    The connection is opened by the first request (or :meth:`connect`), so that a
    refusal to connect comes where requests' refusals are handled.

    Raises
    ------
    Closed
        The daemon ended the connection and said why (:mod:`.protocol`): ``why`` is
        ``refused`` for a user outside the service's group (told by the kernel or by
        the daemon), ``busy`` when it has too many connections, ...
    ControlError
        For a refusal (with its ``problems``), or a reply that breaks the protocol.
    OSError
        When the daemon cannot be reached.
    """

    def __init__(self, path: Path, timeout_s: float = 10.0) -> None:
        self.path = Path(path)
        self.timeout_s = timeout_s
        self._socket: socket.socket | None = None
        self._file: BinaryIO | None = None
        self._lines: Iterator[bytes] | None = None

    def __enter__(self) -> DaemonClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def connect(self) -> None:
        """Open the connection."""
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
        sock.settimeout(self.timeout_s)
        try:
            sock.connect(str(self.path))
        except PermissionError:  # the socket's mode: the kernel's refusal
            sock.close()
            raise Closed(f"{NOT_A_MEMBER} (no permission to open {self.path})", "refused") from None
        except OSError:
            sock.close()
            raise
        self._socket = sock
        self._file = sock.makefile("rb")
        self._lines = iter(self._file)

    def close(self) -> None:
        """Close the connection (a followed run goes on)."""
        if self._file is not None:
            self._file.close()
            self._file = None
        if self._socket is not None:
            self._socket.close()
            self._socket = None

    def _send(self, op: str, fields: dict[str, Any]) -> None:
        if self._socket is not None and self._ended_by_daemon():
            self.close()
        if self._socket is None:
            self.connect()
        assert self._socket is not None
        # A refusing daemon answers and closes before it reads the request (a uid not in
        # the service's group): the send fails, and its reason is waiting to be read.
        with contextlib.suppress(BrokenPipeError, ConnectionResetError):
            self._socket.sendall(encode({"op": op, **fields}))

    def _ended_by_daemon(self) -> bool:
        """Whether the daemon spoke unasked: only to close an idle connection (or EOF)."""
        assert self._socket is not None
        # poll, not select (no limit on descriptor numbers) nor a socket call (a timeout
        # set on the socket would make even a non-blocking recv wait for it).
        poller = select.poll()
        poller.register(self._socket, select.POLLIN)
        return bool(poller.poll(0))  # a last word, the end of the stream, or an error

    def _receive(self) -> dict[str, Any]:
        assert self._lines is not None
        try:
            line = next(self._lines)
        except StopIteration:
            raise ControlError("the daemon closed the connection") from None
        if len(line) > MAX_LINE + 1:
            raise ControlError("reply too long")
        message = decode(line)
        if not message.get("ok") and message.get("closed"):
            self.close()
            raise Closed(str(message.get("error", "closed")), str(message["closed"]))
        return message

    def request(self, op: str, **fields: Any) -> dict[str, Any]:
        """Send one request; its reply, or :class:`ControlError` for a refusal.

        A connection the daemon closed before it read the request (``idle``: dropped
        for another client; ``busy``: too many connections) is tried again a few times
        on a new one: the request was not taken, so sending it again is safe.
        """
        for pause_s in (*RETRY_PAUSES_S, None):
            self._send(op, fields)
            try:
                answer = self._receive()
                break
            except Closed as err:
                if err.why not in ("idle", "busy") or pause_s is None:
                    raise
                time.sleep(pause_s)
        if not answer.get("ok"):
            raise ControlError(str(answer.get("error", "refused")), answer.get("problems"))
        return answer

    def follow(
        self, job: int | None = None, timeout_s: float | None = None
    ) -> Iterator[dict[str, Any]]:
        """The events of a job as they come, up to and including its end.

        ``timeout_s`` bounds the wait for each event (``None``: wait as long as the run).
        """
        fields: dict[str, Any] = {} if job is None else {"job": job}
        self._send("follow", fields)
        assert self._socket is not None
        self._socket.settimeout(timeout_s)
        try:
            while True:
                message = self._receive()
                if not message.get("ok"):
                    raise ControlError(str(message.get("error", "refused")))
                yield message
                if message.get("end"):
                    return
        finally:
            if self._socket is not None:
                self._socket.settimeout(self.timeout_s)
