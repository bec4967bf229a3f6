"""Whether the iTPM is sending, seen from a run without touching its socket.

The iTPM streams a spectrum every integration period whether or not anyone integrates;
the run's driver reads its socket only inside an integration, so between integrations
(a VNA sweep, a ``wait`` for a sidereal time) the datagrams queue in the kernel. The
spectrometer answers when, since the last look, its driver counted new datagrams, or
its socket's receive queue or drop count (``/proc/net/udp``: ``rx_queue``, ``drops``)
moved. It is silent when none of these moved for longer than two integration periods
(at least one cadence): a stalled firmware or a pulled fibre. Where ``/proc/net/udp``
cannot be read, only the driver's counters are looked at, and a spectrometer between
integrations is then not judged at all (unknown), rather than called silent.
"""

from __future__ import annotations

import math
from pathlib import Path

from reach_receiver.devices.spectra import SpectrometerStatistics

from .access import Links

#: The kernel's tables of UDP sockets (IPv4, IPv6).
UDP_TABLES = (Path("/proc/net/udp"), Path("/proc/net/udp6"))
DEVICE = "spectrometer"


def _sockets(port: int) -> tuple[bool, tuple[int, int] | None]:
    """Whether a table was read; bytes queued and datagrams dropped at ``port``'s socket."""
    readable = False
    for table in UDP_TABLES:
        try:
            lines = table.read_text().splitlines()[1:]
        except OSError:
            continue
        readable = True
        for line in lines:
            fields = line.split()
            if len(fields) < 13 or int(fields[1].rsplit(":", 1)[1], 16) != port:
                continue
            return True, (int(fields[4].split(":")[1], 16), int(fields[-1]))
    return readable, None


def socket_queue(port: int) -> tuple[int, int] | None:
    """Bytes queued and datagrams dropped at the UDP socket bound to ``port``, if found."""
    return _sockets(port)[1]


def port_bound(port: int) -> bool | None:
    """Whether a UDP socket of this machine is bound to ``port`` (``None``: cannot tell)."""
    readable, found = _sockets(port)
    return found is not None if readable else None


class Arrivals:
    """The spectrometer's link in :class:`~.access.Links`, judged once a sample."""

    def __init__(self, links: Links) -> None:
        self.links = links
        self._seen: tuple[int, ...] | None = None
        self._since = math.nan  # when something last moved

    def observe(self, stats: SpectrometerStatistics, port: int | None, period_s: float,
                cadence_s: float, now: float) -> None:
        """Mark the spectrometer up, down or unknown from its counters and queue."""
        counters = (stats.packets_received, stats.packets_foreign, stats.packets_malformed)
        queue = socket_queue(port) if port is not None else None
        seen = counters + (queue if queue is not None else (-1, -1))
        if port is None:
            self.links.unknown(DEVICE)
            self._seen = None
            return
        if self._seen is None:  # a first look: nothing to compare with yet
            self._seen, self._since = seen, now
            return
        if seen != self._seen:
            self._seen, self._since = seen, now
            self.links.good(DEVICE, now)
            return
        if queue is None:
            self.links.unknown(DEVICE)
        elif now - self._since > max(2.0 * period_s, cadence_s):
            self.links.failed(DEVICE, f"{DEVICE}: no datagram for {now - self._since:.0f} s")

    def reset(self) -> None:
        """The run is over: its socket is closed, the spectrometer no longer watched."""
        self._seen = None
        if DEVICE in self.links.states:
            self.links.unknown(DEVICE)
