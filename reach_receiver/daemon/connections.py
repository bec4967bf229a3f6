"""The control socket's connections: one I/O thread reads them all, within bounds.

A connection waiting for a request costs a file descriptor and its partial line, not a
thread: the :class:`Reactor`'s one thread accepts clients, reads their lines (never
more than the longest line allowed plus its newline, so a longer line is refused as
soon as it is seen) and times them out: a client that sends nothing for
``Limits.idle_s``, or does not finish a line begun within ``Limits.request_s``, is told
so and closed. A complete line goes to a thread of its own (the server's), which
answers it, streams a ``follow`` for as long as it lasts, and gives the connection back.

At most ``Limits.clients`` connections are open at once. When full, a newcomer takes
the place of the connection idle the longest (an idle client loses nothing: it is told,
and ``DaemonClient`` reconnects), or is told "too many connections" when none is idle.
When ``accept`` finds no file descriptor left, the thread drops the longest idle client
to free one, or when none is idle rests a moment; it logs that once a minute at most.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import selectors
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .protocol import MAX_LINE, closing, encode

log = logging.getLogger(__name__)

#: How long accepting rests when it cannot (no file descriptor left).
ACCEPT_PAUSE_S = 0.1
#: At most one warning in this long while accepting fails.
ACCEPT_WARN_S = 60.0


@dataclass(frozen=True)
class Limits:
    """What clients may hold, and for how long."""

    clients: int = 64
    streams: int = 32
    idle_s: float = 60.0
    request_s: float = 10.0
    send_s: float = 60.0
    max_line: int = MAX_LINE


class Ended(Exception):
    """A connection ends without a line.

    ``why`` (:mod:`.protocol`) and the message are told to the client, but for ``gone``
    (it closed its end: nothing to tell).
    """

    def __init__(self, message: str, why: str) -> None:
        self.why = why
        super().__init__(message)


class Connection:
    """One client's socket, its partial line and its peer (set when it was admitted)."""

    def __init__(self, sock: socket.socket, limits: Limits) -> None:
        self.sock = sock
        self.limits = limits
        self.peer: Any = None
        self.since = time.monotonic()  # waiting for a request since
        self._begun = 0.0  # the first byte of the partial line
        self._buffer = bytearray()
        self._scanned = 0  # bytes of the buffer known to hold no newline

    def receive(self) -> None:
        """Take what the socket holds, up to the longest line (:class:`Ended` when it left)."""
        try:
            chunk = self.sock.recv(min(65536, self.limits.max_line + 1 - len(self._buffer)))
        except (BlockingIOError, InterruptedError):
            return
        except OSError as err:
            raise Ended(str(err), "gone") from None
        if not chunk:
            raise Ended("the client left", "gone")
        if not self._buffer:
            self._begun = time.monotonic()
        self._buffer += chunk

    def line(self) -> bytes | None:
        """The next complete line, if any; :class:`Ended` for one over the limit."""
        end = self._buffer.find(b"\n", self._scanned)
        if end < 0:
            self._scanned = len(self._buffer)
            if len(self._buffer) > self.limits.max_line:
                raise Ended(f"a line longer than {self.limits.max_line} bytes", "long")
            return None
        line = bytes(self._buffer[: end + 1])
        del self._buffer[: end + 1]
        self._scanned = 0
        self._begun = time.monotonic()
        return line

    @property
    def idle(self) -> bool:
        """Waiting for a request with nothing of it read."""
        return not self._buffer

    def expired(self, now: float) -> Ended | None:
        """Why the connection is closed now, if its time is up."""
        if self.idle and now >= self.since + self.limits.idle_s:
            return Ended(f"no request in {self.limits.idle_s:g} s", "idle")
        if not self.idle and now >= self._begun + self.limits.request_s:
            return Ended(f"a line not finished in {self.limits.request_s:g} s", "timeout")
        return None

    def deadline(self) -> float:
        """When :meth:`expired` says so."""
        if self.idle:
            return self.since + self.limits.idle_s
        return self._begun + self.limits.request_s

    def send(self, data: bytes) -> None:
        """Send a message whole within the send timeout (``OSError`` when it cannot)."""
        self.sock.settimeout(self.limits.send_s)
        self.sock.sendall(data)

    def tell(self, message: dict[str, Any]) -> None:
        """A last word, if the socket takes it at once (a stuck client is not waited for)."""
        with contextlib.suppress(OSError):
            self.sock.send(encode(message), socket.MSG_DONTWAIT | socket.MSG_NOSIGNAL)

    def close(self) -> None:
        """Close the socket."""
        with contextlib.suppress(OSError):
            self.sock.close()


class Reactor:
    """The I/O thread of a listening socket (module's text).

    ``admit(connection)`` checks a new client (its credentials) and returns why it is
    refused, or None; ``handle(connection, line)`` answers a line in a thread of its own,
    which then calls :meth:`give_back`.
    """

    def __init__(
        self,
        listener: socket.socket,
        limits: Limits,
        admit: Callable[[Connection], str | None],
        handle: Callable[[Connection, bytes], None],
    ) -> None:
        self.listener = listener
        self.limits = limits
        self.admit = admit
        self.handle = handle
        self._selector = selectors.DefaultSelector()
        self._held: dict[Connection, None] = {}  # waiting for a line, oldest first
        self._out: set[Connection] = set()  # with a thread answering it
        self._back: queue.SimpleQueue[tuple[Connection, bool]] = queue.SimpleQueue()
        self._wake_r, self._wake_w = socket.socketpair()
        self._closing = threading.Event()
        self._stopped = False  # no connection is given back any more: closed instead
        self._lock = threading.Lock()
        self._failed, self._warn_at, self._resume_at = 0, 0.0, 0.0
        self.thread = threading.Thread(target=self._run, name="control-io", daemon=True)

    def __len__(self) -> int:
        return len(self._held) + len(self._out)

    def start(self) -> None:
        """Start the thread."""
        self.listener.setblocking(False)
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._selector.register(self.listener, selectors.EVENT_READ, "listener")
        self._selector.register(self._wake_r, selectors.EVENT_READ, "wake")
        self.thread.start()

    def stop(self) -> None:
        """End the thread; close every connection it holds, wake those answered."""
        self._closing.set()
        self._wake()
        if self.thread.is_alive():
            self.thread.join(timeout=5.0)

    def give_back(self, connection: Connection, keep: bool) -> None:
        """From an answering thread: the connection waits for its next line, or closes."""
        with self._lock:
            if not self._stopped:
                self._back.put((connection, keep))
                self._wake()
                return
        connection.close()

    # ----------------------------------------------------------------- the thread
    def _run(self) -> None:
        try:
            while not self._closing.is_set():
                now = time.monotonic()
                if self._resume_at and now >= self._resume_at:
                    self._resume_at = 0.0
                    self._selector.register(self.listener, selectors.EVENT_READ, "listener")
                wait = min([0.5, *(c.deadline() - now for c in self._held)])
                if self._resume_at:
                    wait = min(wait, self._resume_at - now)
                for key, _ in self._selector.select(max(0.0, wait)):
                    if key.data == "listener":
                        self._accept()
                    elif key.data == "wake":
                        self._taken_back()
                    else:
                        self._readable(key.data)
                self._expire(time.monotonic())
        except Exception:  # a bug: logged, and the server is then not serving
            log.exception("control: the socket's thread failed")
        finally:
            with self._lock:
                self._stopped = True
            while not self._back.empty():
                connection, _ = self._back.get_nowait()
                self._out.discard(connection)
                connection.close()
            for connection in [*self._held, *self._out]:
                with contextlib.suppress(OSError):
                    connection.sock.shutdown(socket.SHUT_RDWR)
            for connection in self._held:
                connection.close()
            self._selector.close()
            self._wake_r.close()
            self._wake_w.close()

    def _accept(self) -> None:
        for _ in range(64):  # then the others' turn
            try:
                sock, _ = self.listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as err:
                self._starved(err)
                return
            sock.setblocking(False)
            self._admit(Connection(sock, self.limits))

    def _starved(self, err: OSError) -> None:
        """No descriptor (or memory) for a client: free an idle one's, rest, go on."""
        self._failed += 1
        if time.monotonic() >= self._warn_at:
            log.warning("control: cannot accept a client (%s; %d time(s)); they wait",
                        err, self._failed)
            self._failed, self._warn_at = 0, time.monotonic() + ACCEPT_WARN_S
        if self._drop_idle("closed: the daemon is out of file descriptors"):
            return  # its descriptor is free for the next one waiting
        self._selector.unregister(self.listener)
        self._resume_at = time.monotonic() + ACCEPT_PAUSE_S

    def _admit(self, connection: Connection) -> None:
        try:
            refused = self.admit(connection)
        except OSError:  # gone before it could be asked who it is
            connection.close()
            return
        if refused is not None:
            connection.tell(closing(refused, "refused"))
            connection.close()
            return
        if len(self) >= self.limits.clients and not self._drop_idle(
            "closed: idle, and another client needed its place"
        ):
            connection.tell(closing(
                f"too many connections (at most {self.limits.clients}): try again", "busy"))
            connection.close()
            return
        self._hold(connection)

    def _drop_idle(self, why: str) -> bool:
        victim = next((c for c in self._held if c.idle), None)
        if victim is None:
            return False
        victim.tell(closing(why, "idle"))
        self._close(victim)
        return True

    def _hold(self, connection: Connection) -> None:
        self._held[connection] = None
        self._selector.register(connection.sock, selectors.EVENT_READ, connection)

    def _close(self, connection: Connection) -> None:
        if connection in self._held:
            del self._held[connection]
            self._selector.unregister(connection.sock)
        connection.close()

    def _readable(self, connection: Connection) -> None:
        try:
            connection.receive()
            line = connection.line()
        except Ended as ended:
            self._end(connection, ended)
            return
        if line is not None:
            del self._held[connection]
            self._selector.unregister(connection.sock)
            self._answer(connection, line)

    def _answer(self, connection: Connection, line: bytes) -> None:
        self._out.add(connection)
        try:
            self.handle(connection, line)
        except RuntimeError:  # no thread to be had
            self._out.discard(connection)
            connection.tell(closing("too many requests at once: try again", "busy"))
            connection.close()

    def _taken_back(self) -> None:
        with contextlib.suppress(OSError):
            while self._wake_r.recv(4096):
                pass
        while not self._back.empty():
            connection, keep = self._back.get_nowait()
            self._out.discard(connection)
            if not keep:
                connection.close()
                continue
            connection.sock.setblocking(False)
            connection.since = time.monotonic()
            try:
                line = connection.line()  # sent ahead of its turn
            except Ended as ended:
                self._end(connection, ended)
                continue
            if line is not None:
                self._answer(connection, line)
            else:
                self._hold(connection)

    def _expire(self, now: float) -> None:
        for connection in list(self._held):
            ended = connection.expired(now)
            if ended is not None:
                self._end(connection, ended)

    def _end(self, connection: Connection, ended: Ended) -> None:
        if ended.why != "gone":
            peer = connection.peer
            level = logging.DEBUG if ended.why == "idle" else logging.WARNING
            log.log(level, "control: closed uid %s (pid %s): %s",
                    getattr(peer, "uid", "?"), getattr(peer, "pid", "?"), ended)
            connection.tell(closing(f"closed: {ended}", ended.why))
        self._close(connection)

    def _wake(self) -> None:
        with contextlib.suppress(OSError):
            self._wake_w.send(b"x")
