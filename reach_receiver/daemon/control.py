"""The control socket: a Unix stream server for the service's group.

The socket ``<runtime_dir>/control.sock`` is created ``0660`` in the runtime directory's
group (the service's group under systemd), so the kernel refuses anyone else at
``connect``; the server also checks each peer's credentials (``SO_PEERCRED``: pid, uid,
gid) and tells a peer that is neither root, nor the daemon's own user, nor a member of
that group that it is refused. Every request is logged with the peer's uid. Requests
are handled by the daemon's dispatcher (:mod:`.protocol` for the messages): a reply, or
for ``follow`` an iterator of messages streamed until it ends or the client goes away.

No local client can stop the server: one I/O thread (:mod:`.connections`) holds every
connection waiting for a request, reads lines within bounds, times out idle and
half-finished clients, limits connections, and when no file descriptor is left rests
and tries again (dropping an idle client to free one) instead of ending; each complete
line is answered in a thread of its own; every line that is not a request is answered;
a burst of connects waits in a long backlog. The socket file is removed on close
only if this server made it: a second daemon refused on its way in leaves the first
one's socket alone.
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

from .connections import Connection, Limits, Reactor
from .protocol import ControlError, check_request, closing, decode, encode, refusal

log = logging.getLogger(__name__)

#: Requests that change nothing, logged at DEBUG (a script may poll them); the others at INFO.
READS = frozenset({"status", "queue", "follow", "solutions"})

SOCKET_FILE = "control.sock"
SOCKET_MODE = 0o660
#: The listen backlog at least (the kernel's own maximum when larger).
BACKLOG = 128


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
    limits
        Connections at once, streams, timeouts, the longest line (:mod:`.connections`).
    """

    def __init__(
        self, path: Path, dispatch: Dispatcher, group: int | None = None,
        limits: Limits | None = None,
    ) -> None:
        self.path = Path(path)
        self.dispatch = dispatch
        self.group = group
        self.limits = limits or Limits()
        self.connections: Reactor | None = None
        self._listener: socket.socket | None = None
        self._bound: tuple[int, int] | None = None  # (st_dev, st_ino) of the file it made
        self._closing = threading.Event()
        self._streams = 0
        self._lock = threading.Lock()

    def start(self) -> None:
        """Bind (replacing a stale socket file), set its mode and group, start accepting."""
        if self.group is None:
            self.group = os.stat(self.path.parent).st_gid
        _remove_stale(self.path)
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
        try:
            listener.bind(str(self.path))
        except OSError:
            listener.close()
            raise
        made = os.stat(self.path)
        self._bound = (made.st_dev, made.st_ino)
        os.chmod(self.path, SOCKET_MODE)
        with contextlib.suppress(PermissionError):
            os.chown(self.path, -1, self.group)
        listener.listen(max(socket.SOMAXCONN, BACKLOG))  # a burst of clients waits its turn
        self._listener = listener
        self.connections = Reactor(listener, self.limits, self._admit, self._handle)
        self.connections.start()
        log.info("control socket %s (group %s)", self.path, _group_name(self.group))

    @property
    def serving(self) -> bool:
        """Whether the server accepts connections."""
        reactor = self.connections
        return reactor is not None and reactor.thread.is_alive() and not self._closing.is_set()

    def close(self) -> None:
        """Stop accepting, close every client, remove the socket file if this server made it.

        A server that never bound (another daemon answers on the path) leaves the file
        alone, and so does one whose file was since replaced by another daemon's.
        """
        self._closing.set()
        if self.connections is not None:
            self.connections.stop()
        if self._listener is not None:
            self._listener.close()
        if self._bound is None:
            return
        with contextlib.suppress(FileNotFoundError):
            found = os.lstat(self.path)
            if (found.st_dev, found.st_ino) == self._bound:
                self.path.unlink()
        self._bound = None

    # ----------------------------------------------------------------- from the I/O thread
    def _admit(self, connection: Connection) -> str | None:
        """Why a new client is refused (not in the group), or None."""
        peer = connection.peer = peer_of(connection.sock)
        if self.group is not None and in_group(peer, self.group):
            return None
        log.warning("control: refused uid %d (pid %d): not in the group", peer.uid, peer.pid)
        return f"refused: not a member of the service's group (uid {peer.uid})"

    def _handle(self, connection: Connection, line: bytes) -> None:
        threading.Thread(
            target=self._work, args=(connection, line), name="control-client", daemon=True
        ).start()

    # ----------------------------------------------------------------- a request's thread
    def _work(self, connection: Connection, line: bytes) -> None:
        keep = False
        try:
            keep = self._answer(connection, line, connection.peer)
        except OSError as err:  # the client went away, or stopped reading
            log.debug("control client: %s", err)
        except Exception:  # a bug must not take the daemon down with it
            log.exception("control: a client's thread failed")
        finally:
            assert self.connections is not None
            self.connections.give_back(connection, keep and not self._closing.is_set())

    def _answer(self, connection: Connection, line: bytes, peer: Peer) -> bool:
        """Handle one request; whether the connection stays open."""
        try:
            request = decode(line)
        except ControlError as err:  # not a request: the two sides no longer agree
            log.info("control: uid %d sent a line that is not a request: %s", peer.uid, err)
            connection.send(encode(closing(str(err), "protocol")))
            return False
        op = str(request.get("op"))[:40]
        level = logging.DEBUG if op in READS else logging.INFO  # polling floods no journal
        log.log(level, "control: %s from uid %d (%s, pid %d)", op, peer.uid, peer.user, peer.pid)
        try:
            answer = self.dispatch(check_request(request), peer)
        except ControlError as err:
            log.log(level, "control: %s from uid %d refused: %s", op, peer.uid, err)
            answer = refusal(str(err), err.problems)
        except Exception as err:
            log.exception("control: %s failed", op)
            answer = refusal(f"internal error: {type(err).__name__}: {err}")
        if isinstance(answer, dict):
            connection.send(_encoded(answer, op))
            return True
        return self._stream(connection, answer, op)

    def _stream(self, connection: Connection, messages: Iterator[dict[str, Any]], op: str) -> bool:
        """Send a stream (follow) until it ends or the client leaves; whether to go on."""
        with self._lock:
            free = self._streams < self.limits.streams
            self._streams += free
        if not free:
            connection.send(encode(refusal(
                f"too many streams (at most {self.limits.streams}): try again")))
            return True
        try:
            for message in messages:
                if self._closing.is_set():
                    return False
                connection.send(_encoded(message, op))
        finally:
            with self._lock:
                self._streams -= 1
        return True


def _encoded(message: dict[str, Any], op: str) -> bytes:
    """A message as a line; one that JSON cannot carry is an internal error, said so."""
    try:
        return encode(message)
    except (TypeError, ValueError) as err:
        log.exception("control: the reply to %s cannot be sent", op)
        return encode(refusal(f"internal error: {type(err).__name__}: {err}"))


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
