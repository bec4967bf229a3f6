"""The control socket: a Unix stream server for the service's group, one thread a client.

The socket ``<runtime_dir>/control.sock`` is created ``0660`` in the runtime directory's
group (the service's group under systemd), so the kernel refuses anyone else at
``connect``; the server also checks each peer's credentials (``SO_PEERCRED``: pid, uid,
gid) and refuses a peer that is neither root, nor the daemon's own user, nor a member of
that group. Every request is logged with the peer's uid. Requests are handled by the
daemon's dispatcher (:mod:`.protocol` for the messages): a reply, or for ``follow`` an
iterator of messages streamed until it ends or the client goes away.
"""

from __future__ import annotations

import contextlib
import grp
import logging
import os
import pwd
import socket
import stat
import struct
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .protocol import MAX_LINE, ControlError, decode, encode, refusal

log = logging.getLogger(__name__)

SOCKET_FILE = "control.sock"
SOCKET_MODE = 0o660


@dataclass(frozen=True)
class Peer:
    """Who is on the other end of a connection (from the kernel, not from the client)."""

    pid: int
    uid: int
    gid: int

    @property
    def user(self) -> str:
        """The peer's user name, or its uid."""
        try:
            return pwd.getpwuid(self.uid).pw_name
        except KeyError:
            return str(self.uid)


Dispatcher = Callable[[dict[str, Any], Peer], "dict[str, Any] | Iterator[dict[str, Any]]"]


def peer_of(connection: socket.socket) -> Peer:
    """The connected process's pid, uid and gid (``SO_PEERCRED``)."""
    raw = connection.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
    pid, uid, gid = struct.unpack("3i", raw)
    return Peer(pid, uid, gid)


def in_group(peer: Peer, group: int) -> bool:
    """Whether the peer is root, this process's user, or a member of ``group``."""
    if peer.uid in (0, os.getuid()) or peer.gid == group:
        return True
    try:
        entry = pwd.getpwuid(peer.uid)
    except KeyError:
        return False
    return group in os.getgrouplist(entry.pw_name, entry.pw_gid)


class ControlServer:
    """Serves the control socket until :meth:`close`.

    Parameters
    ----------
    path
        The socket file (its directory must exist).
    dispatch
        The daemon's request handler.
    group
        The group admitted; the socket directory's group by default.
    """

    def __init__(self, path: Path, dispatch: Dispatcher, group: int | None = None) -> None:
        self.path = Path(path)
        self.dispatch = dispatch
        self.group = group
        self._listener: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._closing = threading.Event()
        self._clients: set[socket.socket] = set()
        self._lock = threading.Lock()

    def start(self) -> None:
        """Bind (replacing a stale socket file), set its mode and group, start accepting."""
        if self.group is None:
            self.group = os.stat(self.path.parent).st_gid
        _remove_stale(self.path)
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
        listener.bind(str(self.path))
        os.chmod(self.path, SOCKET_MODE)
        with contextlib.suppress(PermissionError):
            os.chown(self.path, -1, self.group)
        listener.listen(16)
        listener.settimeout(0.5)
        self._listener = listener
        self._thread = threading.Thread(target=self._accept, name="control-accept", daemon=True)
        self._thread.start()
        log.info("control socket %s (group %s)", self.path, _group_name(self.group))

    @property
    def serving(self) -> bool:
        """Whether the server accepts connections."""
        return self._thread is not None and self._thread.is_alive() and not self._closing.is_set()

    def close(self) -> None:
        """Stop accepting, close every client, remove the socket file."""
        self._closing.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self._listener is not None:
            self._listener.close()
        with self._lock:
            for client in list(self._clients):
                with contextlib.suppress(OSError):
                    client.shutdown(socket.SHUT_RDWR)
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()

    def _accept(self) -> None:
        assert self._listener is not None
        while not self._closing.is_set():
            try:
                connection, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                if self._closing.is_set():
                    return
                raise
            threading.Thread(
                target=self._serve, args=(connection,), name="control-client", daemon=True
            ).start()

    def _serve(self, connection: socket.socket) -> None:
        with self._lock:
            self._clients.add(connection)
        try:
            peer = peer_of(connection)
            if self.group is None or not in_group(peer, self.group):
                uid, pid = peer.uid, peer.pid
                log.warning("control: refused uid %d (pid %d): not in the group", uid, pid)
                connection.sendall(encode(refusal("not a member of the service's group")))
                return
            with connection.makefile("rb") as stream:
                for line in stream:
                    if self._closing.is_set():
                        return
                    if not self._answer(connection, line, peer):
                        return
        except OSError as err:  # the client went away
            log.debug("control client: %s", err)
        finally:
            with self._lock:
                self._clients.discard(connection)
            with contextlib.suppress(OSError):
                connection.close()

    def _answer(self, connection: socket.socket, line: bytes, peer: Peer) -> bool:
        """Handle one request; whether the connection stays open."""
        try:
            request = decode(line)
        except ControlError as err:
            connection.sendall(encode(refusal(str(err))))
            return len(line) <= MAX_LINE
        op = str(request.get("op"))
        log.info("control: %s from uid %d (%s, pid %d)", op, peer.uid, peer.user, peer.pid)
        try:
            answer = self.dispatch(request, peer)
        except ControlError as err:
            answer = refusal(str(err), err.problems)
        except Exception as err:  # a bug must not take the daemon down with it
            log.exception("control: %s failed", op)
            answer = refusal(f"internal error: {type(err).__name__}: {err}")
        if isinstance(answer, dict):
            connection.sendall(encode(answer))
            return True
        for message in answer:  # a stream (follow): until it ends or the client leaves
            if self._closing.is_set():
                return False
            connection.sendall(encode(message))
        return True


def _remove_stale(path: Path) -> None:
    """Remove a socket file left by a daemon that died; refuse to replace a live one."""
    if not path.exists():
        return
    if not stat.S_ISSOCK(path.stat().st_mode):
        raise ControlError(f"{path} exists and is not a socket")
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        probe.connect(str(path))
    except OSError:
        path.unlink()  # nobody listens: stale
        return
    finally:
        probe.close()
    raise ControlError(f"another daemon answers on {path}")


def _group_name(gid: int) -> str:
    try:
        return grp.getgrgid(gid).gr_name
    except KeyError:
        return str(gid)
