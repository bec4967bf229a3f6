"""A simulated serial instrument behind a pseudo-terminal.

:class:`PtyDevice` opens a pty pair (``os.openpty``), puts the slave in raw mode
(``tty.setraw``: no echo, no line editing, no CR/LF translation) and publishes the slave's
path as :attr:`PtyDevice.port`, which pyserial opens like any ``/dev/tty*``. A reader
thread waits on the master side, hands every chunk of bytes to a :class:`ByteHandler`
(the instrument's protocol and model) and writes back whatever it returns. Drivers thus
talk to simulators through the real serial stack, byte for byte.

The device keeps its own slave descriptor open for its whole life: on Linux, a read on
the master fails with ``EIO`` once no descriptor of the slave is open, so without it the
thread would spin whenever the driver closed and re-opened its port.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import select
import threading
import tty
from types import TracebackType
from typing import Protocol

logger = logging.getLogger(__name__)


class ByteHandler(Protocol):
    """The instrument behind the pty: bytes in from the host, reply bytes out."""

    def feed(self, data: bytes) -> bytes:
        """Consume bytes written by the host; return the bytes to send back (maybe none)."""
        ...


class PtyDevice:
    """A pty whose far end is served by ``handler`` on a background thread.

    Parameters
    ----------
    handler
        The simulated instrument.
    name
        Used for the thread's name and in log messages.
    poll_s
        How often the reader thread checks for a stop request while idle.
    """

    def __init__(
        self, handler: ByteHandler, name: str = "pty-device", poll_s: float = 0.02
    ) -> None:
        self.handler = handler
        self.name = name
        self.poll_s = poll_s
        self._master: int | None = None
        self._slave: int | None = None
        self._port: str | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    @property
    def port(self) -> str:
        """Path of the slave side (``/dev/pts/N``), for pyserial."""
        if self._port is None:
            raise RuntimeError(f"{self.name}: not started")
        return self._port

    @property
    def running(self) -> bool:
        """Whether the reader thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> None:
        """Open the pty pair and start serving."""
        if self._thread is not None:
            return
        master, slave = os.openpty()
        tty.setraw(slave)
        self._master, self._slave = master, slave
        self._port = os.ttyname(slave)
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name=self.name, daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop the thread, then close both descriptors.

        A client that still holds the slave open sees its next read or write fail (the
        line hangs up), as with an unplugged USB serial adapter.
        """
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            if self._thread.is_alive():
                logger.warning("%s: reader thread did not stop within %s s", self.name, timeout_s)
            self._thread = None
        for fd in (self._master, self._slave):
            if fd is not None:
                with contextlib.suppress(OSError):  # already gone: nothing to release
                    os.close(fd)
        self._master = self._slave = None

    close = stop

    def __enter__(self) -> PtyDevice:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    def _serve(self) -> None:
        master = self._master
        if master is None:
            return
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([master], [], [], self.poll_s)
                if not ready:
                    continue
                data = os.read(master, 4096)
            except OSError as err:
                if err.errno == errno.EIO:  # no slave descriptor open at this instant
                    self._stop.wait(self.poll_s)
                    continue
                if self._stop.is_set():
                    return
                logger.error("%s: pty read failed: %s", self.name, err)
                return
            if not data:
                continue
            try:
                reply = self.handler.feed(data)
            except Exception:  # a simulator bug must not kill the line silently
                logger.exception("%s: handler failed on %r", self.name, data[:80])
                continue
            self._write_all(master, reply)

    def _write_all(self, fd: int, data: bytes) -> None:
        view = memoryview(data)
        while view and not self._stop.is_set():
            try:
                written = os.write(fd, view)
            except BlockingIOError:
                self._stop.wait(0.001)
                continue
            except OSError as err:
                logger.error("%s: pty write failed: %s", self.name, err)
                return
            view = view[written:]
