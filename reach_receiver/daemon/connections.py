"""The control socket's connections: lines read within bounds, and a table of who is on.

Reading (:class:`Connection`): a line is read into a buffer that never holds more than
the longest line allowed plus its newline, so a longer line is refused as soon as it is
seen, not once it is whole. Waiting for a request is bounded by the idle timeout, and a
line begun must be finished within the request timeout: a client that says nothing, or
half a line, does not hold a thread for ever. Sending is bounded too (a client that
stops reading a stream is dropped).

The table (:class:`ConnectionTable`): at most ``Limits.clients`` connections at once,
each with its thread. When it is full, a new client takes the place of the connection
idle the longest (waiting for a request, nothing half-read): an idle client loses
nothing by being dropped (it is told, and ``DaemonClient`` reconnects), and a client that
connects means to ask something now. When none is idle (every connection in the middle
of a request or following a run), the newcomer is told "too many connections". Streams
(``follow``) hold at most ``Limits.streams`` places, so that requests always find one.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from dataclasses import dataclass

from .protocol import MAX_LINE, closing, encode


@dataclass(frozen=True)
class Limits:
    """What one client may hold, and for how long."""

    clients: int = 64
    streams: int = 32
    idle_s: float = 60.0
    request_s: float = 10.0
    send_s: float = 60.0
    max_line: int = MAX_LINE


class Ended(Exception):
    """Reading ended without a line; ``why`` and the message are told to the client.

    ``why`` is ``idle``, ``timeout`` or ``long`` (:mod:`.protocol`), or ``gone`` when the
    client closed its end (nothing to tell).
    """

    def __init__(self, message: str, why: str) -> None:
        self.why = why
        super().__init__(message)


class Connection:
    """One client's socket, its partial line, and what it is doing.

    ``state`` is ``idle`` (waiting for a request, nothing read of it), ``reading`` (a line
    begun), ``busy`` (a request being answered) or ``stream`` (a ``follow``).
    """

    def __init__(self, sock: socket.socket, limits: Limits) -> None:
        self.sock = sock
        self.limits = limits
        self.state = "idle"
        self.since = time.monotonic()  # of the state
        self.dropped = False  # to make room, or the server closing
        self.done = threading.Event()  # its descriptor is closed
        self._buffer = bytearray()
        self._scanned = 0  # bytes of the buffer known to hold no newline
        self._lock = threading.Lock()

    def read_line(self) -> bytes:
        """The next line with its newline; :class:`Ended` when there is none to answer."""
        limit = self.limits.max_line + 1
        begun = time.monotonic()
        while True:
            end = self._buffer.find(b"\n", self._scanned)
            if end >= 0:
                line = bytes(self._buffer[: end + 1])
                del self._buffer[: end + 1]
                self._scanned = 0
                self._set("busy")
                return line
            self._scanned = len(self._buffer)
            if len(self._buffer) >= limit:
                raise Ended(f"a line longer than {self.limits.max_line} bytes", "long")
            waiting = not self._buffer
            self._set("idle" if waiting else "reading")
            if waiting:
                begun = self.since
            left = begun + (self.limits.idle_s if waiting else self.limits.request_s)
            self.sock.settimeout(max(0.001, left - time.monotonic()))
            try:
                chunk = self.sock.recv(min(65536, limit - len(self._buffer)))
            except TimeoutError:
                if waiting:
                    raise Ended(f"no request in {self.limits.idle_s:g} s", "idle") from None
                raise Ended(
                    f"a line not finished in {self.limits.request_s:g} s", "timeout"
                ) from None
            with self._lock:
                if self.dropped or not chunk:
                    raise Ended("the client left" if not chunk else "dropped", "gone")
                if waiting:
                    begun = time.monotonic()
                self._buffer += chunk

    def send(self, data: bytes) -> None:
        """Send a message whole within the send timeout (``OSError`` when it cannot)."""
        self.sock.settimeout(self.limits.send_s)
        self.sock.sendall(data)

    def tell(self, message: bytes) -> None:
        """A last word, if the socket takes it at once (a stuck client is not waited for)."""
        with contextlib.suppress(OSError):
            self.sock.send(message, socket.MSG_DONTWAIT | socket.MSG_NOSIGNAL)

    def streaming(self) -> None:
        """The connection now carries a stream (never dropped to make room)."""
        self._set("stream")

    def drop_if_idle(self, why: str) -> bool:
        """Tell an idle client why it is closed and wake its thread; whether it was idle."""
        with self._lock:
            if self.state != "idle" or self.dropped:
                return False
            self.dropped = True
            self.tell(encode(closing(why, "idle")))
            with contextlib.suppress(OSError):
                self.sock.shutdown(socket.SHUT_RDWR)
            return True

    def drop(self) -> None:
        """Wake the connection's thread whatever it does (the server is closing)."""
        with self._lock:
            self.dropped = True
            with contextlib.suppress(OSError):
                self.sock.shutdown(socket.SHUT_RDWR)

    def _set(self, state: str) -> None:
        with self._lock:
            if self.dropped:
                raise Ended("dropped", "gone")
            if state != self.state:
                self.state, self.since = state, time.monotonic()


class ConnectionTable:
    """The connections open at once, within :class:`Limits`."""

    def __init__(self, limits: Limits) -> None:
        self.limits = limits
        self._open: set[Connection] = set()
        self._streams = 0
        self._lock = threading.Lock()

    def __len__(self) -> int:
        with self._lock:
            return sum(1 for c in self._open if not c.dropped)

    def admit(self, connection: Connection) -> bool:
        """Take a new connection, dropping the longest idle one when full; whether taken."""
        with self._lock:
            live = [c for c in self._open if not c.dropped]
            victim = None
            if len(live) >= self.limits.clients:
                victim = self._drop_idle(live, "closed: idle, and another client needed its place")
                if victim is None:
                    return False
            self._open.add(connection)
        if victim is not None:  # its descriptor is closed before another is used
            victim.done.wait(1.0)
        return True

    def drop_idle(self, why: str) -> bool:
        """Drop the longest idle connection (to free its descriptor); whether there was one."""
        with self._lock:
            victim = self._drop_idle([c for c in self._open if not c.dropped], why)
        if victim is not None:
            victim.done.wait(1.0)
        return victim is not None

    def leave(self, connection: Connection) -> None:
        """A connection's thread is done with it (its socket closed)."""
        with self._lock:
            self._open.discard(connection)
        connection.done.set()

    def start_stream(self) -> bool:
        """Take one of the streams' places; whether there was one free."""
        with self._lock:
            if self._streams >= self.limits.streams:
                return False
            self._streams += 1
            return True

    def end_stream(self) -> None:
        """Give a stream's place back."""
        with self._lock:
            self._streams -= 1

    def drop_all(self) -> None:
        """Wake every connection's thread (the server closes)."""
        with self._lock:
            connections = list(self._open)
        for connection in connections:
            connection.drop()

    @staticmethod
    def _drop_idle(live: list[Connection], why: str) -> Connection | None:
        for connection in sorted(live, key=lambda c: c.since):
            if connection.drop_if_idle(why):
                return connection
        return None
