"""Simulated iTPM spectrometer: encodes spectra as SPEAD packets and streams them over UDP.

The wire format is the one :mod:`reach_receiver.devices.spead` decodes (its module doc
lists what was confirmed against REACH's and SKA's code and what was assumed). Every
``period_s`` of the clock's time the simulator asks its spectrum source for the power
spectrum integrated over the period just ended, stamps it with the period's start, and
sends its packets to the receiver's address, as the iTPM does once per integration.
It sends from one fixed address and port (:attr:`ItpmSimulator.sender`, loopback by
default), which the simulated site names as the spectra's only source.

While no socket of this machine is bound to the receiver's port (no run has its
spectrometer connected), a spectrum would go nowhere: the simulator then neither
computes nor sends it (:attr:`ItpmSimulatorStats.spectra_unheard`), so an idle
``reachd --sim`` at high compression does not spend a core on spectra nobody reads. A
receiver that binds the port gets the next period's spectrum, as from the real iTPM,
which streams all the time. Where the kernel's socket table cannot be read, every
spectrum is sent.

A simulator starved of CPU skips spectra to keep up with the clock
(:data:`MAX_LAG_PERIODS`). No measurement changes because of it: an integration
averages the number of whole spectra it asks for, each a full period of the source it
looked at, from those that arrive; a skipped spectrum only makes that position end
later in simulated time (and the timestamps stored with it show the gap).

Faults can be switched at run time (:meth:`ItpmSimulator.set_faults`): lost, duplicated
or reordered packets, garbage datagrams, and a stall (nothing sent). They are drawn from
one seeded generator, so a test's packet losses are reproducible.
"""

from __future__ import annotations

import dataclasses
import ipaddress
import logging
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from reach_receiver.clock import Clock
from reach_receiver.devices import spead
from reach_receiver.monitor.arrivals import port_bound

logger = logging.getLogger(__name__)

SpectrumSource = Callable[[float, float], np.ndarray]
"""``source(t_start, duration_s) -> (n_inputs, n_channels)`` power integrated over the span."""

#: Spectra the simulator may fall behind the clock before it skips ahead. The iTPM runs in
#: real time whatever its host does; a simulator starved of CPU (high time compression on
#: a busy machine) would otherwise send ever older spectra, which the receiver skips as
#: stale, and fall behind without bound.
MAX_LAG_PERIODS = 4
#: Real seconds between two looks at whether a receiver listens: a receiver that binds
#: its port gets spectra this much later at most.
LISTENER_CHECK_S = 0.05

_PACKET = np.dtype([("header", ">u8", (1 + spead.N_ITEMS,)), ("payload", "V1024")])


def encode_spectrum(
    spectrum: np.ndarray,
    timestamp: int,
    heap_counter: int,
    sync_time: int,
    *,
    floating_point: bool = True,
    buffer_id: int = 0,
) -> list[bytes]:
    """Encode one (n_inputs, n_channels) spectrum as the iTPM's SPEAD datagrams.

    Values are placed in the heap in the firmware's order (the inverse of the
    receiver's :func:`~reach_receiver.devices.spead.physical_index` map), written as
    little-endian float64 (or int64 in integer mode), 128 per 1024-byte packet. Packet
    ``p`` of ``2 x k`` carries FPGA row ``p // k``: start signal ``(p // k) x s`` and
    start channel ``(p % k) x 128 / s`` with ``s = n_inputs // 2`` signals per FPGA.

    Parameters
    ----------
    spectrum
        Power per input and channel, physical channel order.
    timestamp
        Spectrum time in 32768 x 2.5 ns counts after ``sync_time`` (48 bits).
    heap_counter
        Per-spectrum counter; its low 24 bits go in bits 0-23 of item 0x0001 and the
        packet's index in the heap in bits 24-39 (an assumption: see the spead module).
    sync_time
        Unix seconds of the firmware's time sync.
    floating_point
        Float64 payload and mode bit 7, else int64 payload (values rounded).
    buffer_id
        Value of bits 16-31 of item 0x2001.

    Returns
    -------
    list of bytes
        One 1096-byte datagram per packet, in sending order.
    """
    n_inputs, n_channels = spectrum.shape
    per_fpga = spead.signals_per_fpga(n_inputs)
    per_packet = spead.PAYLOAD_BYTES // spead.VALUE_BYTES
    if (n_inputs * n_channels) % (2 * per_packet):
        raise ValueError(f"{n_inputs} x {n_channels} values do not fill whole packets")
    index = spead.physical_index(n_inputs, n_channels, floating_point)
    heap = np.asarray(spectrum).reshape(-1)[index]
    wire = heap.astype("<f8") if floating_point else np.rint(heap).astype("<i8")
    n_packets = wire.size // per_packet
    per_row = n_packets // 2
    p = np.arange(n_packets, dtype=np.uint64)
    start_signal = (p // per_row) * per_fpga
    start_channel = (p % per_row) * (per_packet // per_fpga)
    info = (
        (start_channel << 24)
        | ((per_packet // per_fpga) << 16)
        | (start_signal << 8)
        | np.uint64(per_fpga)
    )
    mode = spead.SIMULATED_MODE | (spead.MODE_FLOATING_POINT if floating_point else 0)
    packets = np.zeros(n_packets, dtype=_PACKET)
    header = packets["header"]
    header[:, 0] = spead.HEADER_WORD
    header[:, 1] = (
        (int(spead.IMMEDIATE | spead.HEAP_COUNTER) << 48) | (p << 24) | (heap_counter & 0xFFFFFF)
    )
    header[:, 2] = (int(spead.IMMEDIATE | spead.PAYLOAD_LENGTH) << 48) | spead.PAYLOAD_BYTES
    header[:, 3] = (int(spead.IMMEDIATE | spead.SYNC_TIME) << 48) | (sync_time & spead.VALUE_MASK)
    header[:, 4] = (int(spead.IMMEDIATE | spead.TIMESTAMP) << 48) | (timestamp & spead.VALUE_MASK)
    header[:, 5] = (int(spead.IMMEDIATE | spead.MODE) << 48) | mode
    header[:, 6] = (int(spead.IMMEDIATE | spead.CHANNEL_INFO) << 48) | info
    header[:, 7] = (int(spead.IMMEDIATE | spead.BUFFER_ID) << 48) | ((buffer_id & 0xFFFF) << 16)
    header[:, 8] = int(spead.PAYLOAD_OFFSET) << 48
    packets["payload"] = wire.view("V1024")
    blob = packets.tobytes()
    size = spead.PACKET_BYTES
    return [blob[k * size : (k + 1) * size] for k in range(n_packets)]


@dataclass(frozen=True)
class ItpmFaults:
    """Faults the simulator injects, per spectrum sent.

    Parameters
    ----------
    drop_fraction
        Probability that each packet is not sent.
    duplicate_fraction
        Probability that each sent packet is sent twice (the copy right after it).
    reorder
        Shuffle the packets of each spectrum (they stay within their heap).
    garbage_fraction
        Expected garbage datagrams per packet: random bytes or truncated packets.
    stall
        Send nothing at all (a hung firmware or a pulled cable).
    """

    drop_fraction: float = 0.0
    duplicate_fraction: float = 0.0
    reorder: bool = False
    garbage_fraction: float = 0.0
    stall: bool = False


@dataclass
class ItpmSimulatorStats:
    """What the simulator did: spectra and packets sent, and faults injected.

    ``spectra_skipped`` counts spectra skipped to catch up with the clock while a
    receiver listened; ``spectra_unheard`` those not made because nobody listened.
    """

    spectra_sent: int = 0
    packets_sent: int = 0
    packets_dropped: int = 0
    packets_duplicated: int = 0
    garbage_sent: int = 0
    spectra_skipped: int = 0
    spectra_unheard: int = 0


class ItpmSimulator:
    """A thread that streams one spectrum every ``period_s`` of clock time over UDP.

    Parameters
    ----------
    spectrum_source
        ``source(t_start, duration_s)`` -> (n_inputs, n_channels) power spectrum
        integrated over ``[t_start, t_start + duration_s)`` of the clock's time.
    clock
        Shared with the receiver; a :class:`~reach_receiver.clock.CompressedClock`
        makes a 1 s integration take ``1 / factor`` real seconds.
    address
        The receiver's (host, port).
    sender
        The (host, port) it sends from; port 0 lets the kernel choose one at the first
        :meth:`bind`, kept for later starts (read it from :attr:`sender`).
    period_s
        Integration time of one spectrum, clock seconds.
    faults
        Initial faults (none by default); change them with :meth:`set_faults`.
    seed
        Seed of the generator the faults are drawn from.
    floating_point
        Float64 payload (REACH's firmware setting) or int64.
    """

    def __init__(
        self,
        spectrum_source: SpectrumSource,
        clock: Clock,
        address: tuple[str, int],
        period_s: float = 1.0,
        faults: ItpmFaults | None = None,
        *,
        sender: tuple[str, int] = ("127.0.0.1", 0),
        seed: int = 0,
        floating_point: bool = True,
    ) -> None:
        if not period_s > 0:
            raise ValueError(f"period_s must be positive, got {period_s}")
        self.source = spectrum_source
        self.clock = clock
        self.address = address
        self.sender = sender
        self.period_s = float(period_s)
        self.floating_point = floating_point
        self.stats = ItpmSimulatorStats()
        self._faults = faults or ItpmFaults()
        self._rng = np.random.default_rng(seed)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._sock: socket.socket | None = None
        self._listener = True
        self._listener_checked = -float("inf")
        self.error: BaseException | None = None

    @property
    def faults(self) -> ItpmFaults:
        """The faults in force."""
        return self._faults

    def set_faults(self, **changes: float | bool) -> ItpmFaults:
        """Change some faults (fields of :class:`ItpmFaults`), from the next spectrum on."""
        self._faults = dataclasses.replace(self._faults, **changes)  # type: ignore[arg-type]
        return self._faults

    def start(self) -> None:
        """Bind the sending socket to :attr:`sender` and start streaming."""
        if self._thread is not None:
            return
        self.bind()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="itpm-simulator", daemon=True)
        self._thread.start()

    def bind(self) -> tuple[str, int]:
        """Open the sending socket at :attr:`sender` (once); return the address it sends from.

        Called by :meth:`start`; call it before to learn the port the kernel chose.
        """
        if self._sock is None:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4 * 1024 * 1024)
                sock.bind(self.sender)
            except OSError:
                sock.close()
                raise
            self._sock = sock
            host, port = sock.getsockname()[:2]
            self.sender = (str(host), int(port))
        return self.sender

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop streaming, join the thread and close the socket."""
        self._stop.set()
        if self.stats.spectra_skipped:
            logger.warning(
                "iTPM simulator fell behind the clock and skipped %d of %d spectra; no "
                "measurement changed: each integration averaged as many whole spectra as it "
                "asked for, and a skip made its position end later in simulated time",
                self.stats.spectra_skipped,
                self.stats.spectra_skipped + self.stats.spectra_sent,
            )
        if self._thread is not None:
            self._thread.join(timeout_s)
            if self._thread.is_alive():
                logger.error("iTPM simulator thread did not stop within %g s", timeout_s)
            self._thread = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> ItpmSimulator:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    def _wait_until(self, t: float) -> bool:
        """Wait in clock time until ``t``; False when asked to stop first.

        One wait on the stop event, not a poll: at high compression a period is a few
        real milliseconds, and waking eight times in each cost an idle core a tenth.
        """
        while not self._stop.is_set():
            remaining = t - self.clock.now()
            if remaining <= 0:
                return True
            if self.clock.wait(self._stop, remaining):
                return False
        return False

    def _listened(self) -> bool:
        """Whether a receiver may be listening: its local port bound, or not local.

        The kernel's table is read at most every :data:`LISTENER_CHECK_S` real seconds
        (a read costs a third of a millisecond, a period at 3000x a few milliseconds).
        """
        now = time.monotonic()
        if now < self._listener_checked + LISTENER_CHECK_S:
            return self._listener
        host, port = self.address
        try:
            local = ipaddress.ip_address(host).is_loopback
        except ValueError:
            local = host == "localhost"
        self._listener = not local or port_bound(port) is not False
        self._listener_checked = now
        return self._listener

    def _run(self) -> None:
        now = self.clock.now()
        sync_time = int(now)
        t_start = now
        heap_counter = 0
        try:
            while self._wait_until(t_start + self.period_s):
                behind = int((self.clock.now() - t_start) // self.period_s) - MAX_LAG_PERIODS
                listened = self._listened()
                if behind > 0:  # a starved simulator skips, as a real iTPM never lags
                    if listened:
                        self.stats.spectra_skipped += behind
                    else:
                        self.stats.spectra_unheard += behind
                    heap_counter += behind
                    t_start += behind * self.period_s
                    continue
                if not listened:  # look again in a while, then skip what passed meanwhile
                    self.stats.spectra_unheard += 1
                    heap_counter += 1
                    t_start += self.period_s
                    self._stop.wait(LISTENER_CHECK_S)
                    continue
                spectrum = np.asarray(self.source(t_start, self.period_s), dtype=float)
                timestamp = round((t_start - sync_time) / spead.TIMESTAMP_UNIT_S)
                faults = self._faults
                if not faults.stall:
                    packets = encode_spectrum(
                        spectrum,
                        timestamp,
                        heap_counter,
                        sync_time,
                        floating_point=self.floating_point,
                    )
                    self._send(packets, faults)
                    self.stats.spectra_sent += 1
                heap_counter += 1
                t_start += self.period_s
        except Exception as err:  # the thread must not die silently
            logger.exception("iTPM simulator stopped")
            self.error = err

    def _send(self, packets: list[bytes], faults: ItpmFaults) -> None:
        rng = self._rng
        n = len(packets)
        order = rng.permutation(n) if faults.reorder else np.arange(n)
        keep = rng.random(n) >= faults.drop_fraction
        twice = rng.random(n) < faults.duplicate_fraction
        garbage = rng.poisson(faults.garbage_fraction, n) if faults.garbage_fraction else None
        sock = self._sock
        if sock is None:
            return
        for k in order:
            if garbage is not None:
                for _ in range(garbage[k]):
                    sock.sendto(self._garbage(packets[k]), self.address)
                    self.stats.garbage_sent += 1
            if not keep[k]:
                self.stats.packets_dropped += 1
                continue
            sock.sendto(packets[k], self.address)
            self.stats.packets_sent += 1
            if twice[k]:
                sock.sendto(packets[k], self.address)
                self.stats.packets_duplicated += 1

    def _garbage(self, packet: bytes) -> bytes:
        """Random bytes, or a real packet cut short (a truncated or foreign datagram)."""
        rng = self._rng
        if rng.random() < 0.5:
            return bytes(packet[: int(rng.integers(1, len(packet)))])
        return rng.bytes(int(rng.integers(1, 2 * len(packet))))
