"""The control socket: a Unix stream server for the service's group, one thread a client.

The socket ``<runtime_dir>/control.sock`` is created ``0660`` in the runtime directory's
group (the service's group under systemd), so the kernel refuses anyone else at
``connect``; the server also checks each peer's credentials (``SO_PEERCRED``: pid, uid,
gid) and tells a peer that is neither root, nor the daemon's own user, nor a member of
that group that it is refused. Every request is logged with the peer's uid. Requests
are handled by the daemon's dispatcher (:mod:`.protocol` for the messages): a reply, or
for ``follow`` an iterator of messages streamed until it ends or the client goes away.

No local client can stop the server: lines are bounded while they are read, idle and
half-finished clients are timed out, connections are limited (:mod:`.connections`), every
line that is not a request is answered, a burst of connects waits in a long backlog, and
when no file descriptor is left ``accept`` rests and tries again (dropping an idle
client to free one) instead of ending the thread. The socket file is removed on close
only if this server made it: a second daemon refused on its way in leaves the first
one's socket alone.
"""

from __future__ import annotations

import contextlib
import errno
import grp
import logging
import os
import pwd
import socket
import stat
import struct
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .connections import Connection, ConnectionTable, Ended, Limits
from .protocol import ControlError, check_request, closing, decode, encode, refusal

log = logging.getLogger(__name__)

SOCKET_FILE = "control.sock"
SOCKET_MODE = 0o660
#: The listen backlog at least (the kernel's own maximum when larger).
BACKLOG = 128
#: How long accepting rests when it cannot (no file descriptor left).
ACCEPT_PAUSE_S = 0.1
#: At most one warning in this long while accepting fails.
ACCEPT_WARN_S = 60.0


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
        self.connections = ConnectionTable(self.limits)
        self._listener: socket.socket | None = None
        self._bound: tuple[int, int] | None = None  # (st_dev, st_ino) of the file it made
        self._thread: threading.Thread | None = None
        self._closing = threading.Event()

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
        """Stop accepting, close every client, remove the socket file if this server made it.

        A server that never bound (another daemon answers on the path) leaves the file
        alone, and so does one whose file was since replaced by another daemon's.
        """
        self._closing.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self._listener is not None:
            self._listener.close()
        self.connections.drop_all()
        if self._bound is None:
            return
        with contextlib.suppress(FileNotFoundError):
            found = os.lstat(self.path)
            if (found.st_dev, found.st_ino) == self._bound:
                self.path.unlink()
        self._bound = None

    # ----------------------------------------------------------------- accepting
    def _accept(self) -> None:
        """Accept until closed; no error of ``accept`` ends the thread (module's text)."""
        assert self._listener is not None
        failed, warn_at = 0, 0.0
        while not self._closing.is_set():
            try:
                connection, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError as err:
                if self._closing.is_set():
                    return
                failed += 1
                if time.monotonic() >= warn_at:  # once, then once a minute while it lasts
                    log.warning("control: cannot accept a client (%s; %d time(s)); they wait",
                                err, failed)
                    failed, warn_at = 0, time.monotonic() + ACCEPT_WARN_S
                if err.errno in (errno.EMFILE, errno.ENFILE):  # an idle client's descriptor
                    self.connections.drop_idle("closed: the daemon is out of file descriptors")
                time.sleep(ACCEPT_PAUSE_S)
                continue
            self._admit(connection)

    def _admit(self, sock: socket.socket) -> None:
        connection = Connection(sock, self.limits)
        if self.connections.admit(connection):
            try:
                threading.Thread(
                    target=self._serve, args=(connection,), name="control-client", daemon=True
                ).start()
                return
            except RuntimeError:  # no thread to be had
                self.connections.leave(connection)
        connection.tell(encode(closing(
            f"too many connections (at most {self.limits.clients}): try again", "busy")))
        sock.close()

    # ----------------------------------------------------------------- one client
    def _serve(self, connection: Connection) -> None:
        try:
            peer = peer_of(connection.sock)
            if self.group is None or not in_group(peer, self.group):
                uid, pid = peer.uid, peer.pid
                log.warning("control: refused uid %d (pid %d): not in the group", uid, pid)
                connection.send(encode(closing(
                    f"refused: not a member of the service's group (uid {uid})", "refused")))
                return
            while not self._closing.is_set():
                try:
                    line = connection.read_line()
                except Ended as ended:
                    if ended.why != "gone":
                        _log_end(peer, ended)
                        connection.tell(encode(closing(f"closed: {ended}", ended.why)))
                    return
                if not self._answer(connection, line, peer):
                    return
        except OSError as err:  # the client went away, or stopped reading
            log.debug("control client: %s", err)
        except Ended:  # dropped while answering: the server closes
            pass
        except Exception:  # a bug must not take the daemon down with it
            log.exception("control: a client's thread failed")
        finally:
            with contextlib.suppress(OSError):
                connection.sock.close()
            self.connections.leave(connection)

    def _answer(self, connection: Connection, line: bytes, peer: Peer) -> bool:
        """Handle one request; whether the connection stays open."""
        try:
            request = decode(line)
        except ControlError as err:  # not a request: the two sides no longer agree
            log.info("control: uid %d sent a line that is not a request: %s", peer.uid, err)
            connection.send(encode(closing(str(err), "protocol")))
            return False
        op = str(request.get("op"))[:40]
        log.info("control: %s from uid %d (%s, pid %d)", op, peer.uid, peer.user, peer.pid)
        try:
            answer = self.dispatch(check_request(request), peer)
        except ControlError as err:
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
        if not self.connections.start_stream():
            connection.send(encode(refusal(
                f"too many streams (at most {self.limits.streams}): try again")))
            return True
        try:
            connection.streaming()
            for message in messages:
                if self._closing.is_set():
                    return False
                connection.send(_encoded(message, op))
        finally:
            self.connections.end_stream()
        return True


def _encoded(message: dict[str, Any], op: str) -> bytes:
    """A message as a line; one that JSON cannot carry is an internal error, said so."""
    try:
        return encode(message)
    except (TypeError, ValueError) as err:
        log.exception("control: the reply to %s cannot be sent", op)
        return encode(refusal(f"internal error: {type(err).__name__}: {err}"))


def _log_end(peer: Peer, ended: Ended) -> None:
    """An idle client closed is routine; a line too long or unfinished is worth a warning."""
    level = logging.DEBUG if ended.why == "idle" else logging.WARNING
    log.log(level, "control: closed uid %d (pid %d): %s", peer.uid, peer.pid, ended)


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
