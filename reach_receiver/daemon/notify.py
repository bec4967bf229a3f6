"""systemd's notification protocol: readiness, status, watchdog, stopping.

The documented protocol (``sd_notify(3)``) is one datagram of newline-separated
``KEY=value`` assignments to the ``AF_UNIX`` socket named by ``$NOTIFY_SOCKET`` (a path,
or an abstract name when it starts with ``@``). It is a dozen lines, so it is written
here rather than taken from a library: ``READY=1`` once the daemon serves, ``STATUS=``
a line for ``systemctl status``, ``WATCHDOG=1`` at least every ``$WATCHDOG_USEC / 2``,
``STOPPING=1`` when it begins to stop. Without ``$NOTIFY_SOCKET`` (not under systemd)
every call does nothing. Sending never blocks: a notification that finds the socket's
queue full is dropped, since the daemon's main loop must not wait on its supervisor.

The watchdog is fed only by the daemon's main loop and only while the loop finds the
daemon healthy (:class:`Watchdog`): a hung loop, or one that finds a run's thread stuck,
stops feeding it and systemd restarts the service.
"""

from __future__ import annotations

import logging
import os
import socket
import time
from collections.abc import Mapping

log = logging.getLogger(__name__)


class Notifier:
    """Sends notifications to systemd, if it is listening.

    Parameters
    ----------
    environ
        Where ``NOTIFY_SOCKET`` and ``WATCHDOG_USEC`` are read (``os.environ``).
    """

    def __init__(self, environ: Mapping[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        self.address = _address(env.get("NOTIFY_SOCKET", ""))
        usec = env.get("WATCHDOG_USEC", "")
        pid = env.get("WATCHDOG_PID", "")
        mine = not pid or pid == str(os.getpid())
        self.watchdog_s = int(usec) / 1e6 if usec.isdigit() and int(usec) > 0 and mine else None
        self._socket: socket.socket | None = None

    @property
    def enabled(self) -> bool:
        """Whether systemd gave a notification socket."""
        return self.address is not None

    def send(self, **fields: str) -> bool:
        """Send ``KEY=value`` assignments (``send(READY="1", STATUS="idle")``); whether sent."""
        if self.address is None:
            return False
        text = "\n".join(f"{key}={value}" for key, value in fields.items())
        try:
            if self._socket is None:
                kind = socket.SOCK_DGRAM | socket.SOCK_CLOEXEC | socket.SOCK_NONBLOCK
                self._socket = socket.socket(socket.AF_UNIX, kind)
            self._socket.sendto(text.encode(), self.address)
        except BlockingIOError:  # systemd's queue is full: drop this one, never wait
            log.debug("notify %s: the queue is full; dropped", text.replace("\n", " "))
            return False
        except OSError as err:  # systemd gone: never fatal
            log.warning("notify %s: %s", text.replace("\n", " "), err)
            return False
        return True

    def ready(self, status: str) -> bool:
        """The daemon serves."""
        return self.send(READY="1", STATUS=status)

    def status(self, text: str) -> bool:
        """A one-line status for ``systemctl status``."""
        return self.send(STATUS=text)

    def stopping(self, status: str) -> bool:
        """The daemon begins to stop."""
        return self.send(STOPPING="1", STATUS=status)

    def close(self) -> None:
        """Close the socket."""
        if self._socket is not None:
            self._socket.close()
            self._socket = None


def _address(value: str) -> str | bytes | None:
    if not value:
        return None
    if value.startswith("@"):  # an abstract socket name
        return b"\0" + value[1:].encode()
    return value


class Watchdog:
    """Feeds systemd's watchdog from the main loop, at half its interval, while healthy.

    ``feed(healthy)`` is called on every turn of the main loop; it pings only when
    ``healthy`` is true and half the interval has passed since the last ping.
    """

    def __init__(self, notifier: Notifier) -> None:
        self.notifier = notifier
        self.interval_s = notifier.watchdog_s
        self._last = -float("inf")
        self.fed = 0

    def feed(self, healthy: bool) -> bool:
        """Ping the watchdog if it is due and the daemon is healthy; whether it pinged."""
        if self.interval_s is None or not healthy:
            return False
        now = time.monotonic()
        if now - self._last < self.interval_s / 2:
            return False
        self._last = now
        if self.notifier.send(WATCHDOG="1"):
            self.fed += 1
            return True
        return False
