"""iTPM spectrometer driver: assembles SPEAD packets into spectra and integrates them.

The iTPM sends each integrated spectrum (2 inputs x 16384 channels, float64) as 256 UDP
packets sharing one timestamp (packet layout and channel order:
:mod:`reach_receiver.devices.spead`). This driver

* groups packets into heaps by timestamp, as REACH's ``spectra.py`` does, and places
  each packet's 1024 payload bytes by its start signal and start channel, so packets may
  arrive in any order within their heap;
* delivers a spectrum only when every one of its packets arrived. A heap still
  incomplete when ``max_open_heaps`` newer heaps have started is dropped and its missing
  packets counted as lost; its data are never mixed with another heap's;
* counts and ignores duplicates (also of a heap already delivered), packets of heaps
  already dropped or flushed, and malformed datagrams; none of these raises;
* takes datagrams only from the iTPM's address when given one (``source``): those of
  any other sender are dropped by the transport and counted as ``packets_foreign``,
  so a spoofed or stray stream is never mixed into a spectrum;
* returns float64 spectra in physical channel order, shape (n_inputs, n_channels), as
  the records of :mod:`reach_receiver.devices.spectra`.

:meth:`Spectrometer.integrate` flushes what was queued before the request, skips
spectra whose integration ended before the request (their packets may still be on their
way when the flush runs), drops the first ``discard`` complete spectra (one may straddle
a switch change) and averages the next ``n_spectra``. Timeouts are real (monotonic)
seconds: they guard against a silent device, and a socket waits in real time whatever
the clock.
"""

from __future__ import annotations

import ipaddress
import logging
import time
from collections import OrderedDict
from collections.abc import Callable

import numpy as np

from reach_receiver.clock import Clock, SystemClock
from reach_receiver.devices import spead
from reach_receiver.devices.spectra import AccumulatedSpectrum, SpectrometerStatistics, Spectrum
from reach_receiver.errors import DeviceTimeout, ProtocolError
from reach_receiver.transports.udp import UdpReceiver

logger = logging.getLogger(__name__)

_RETIRED_MEMORY = 64
_POLL_S = 0.05
_COMPLETE, _DROPPED, _FLUSHED = 0, 1, 2



class _Heap:
    """Packets of one timestamp being assembled."""

    __slots__ = ("count", "heap_counter", "raw", "seen", "sync_time")

    def __init__(self, n_packets: int, raw: bytearray, sync_time: int, heap_counter: int) -> None:
        self.raw = raw
        self.seen = bytearray(n_packets)
        self.count = 0
        self.sync_time = sync_time
        self.heap_counter = heap_counter


class Spectrometer:
    """Driver of the iTPM spectrometer's UDP spectra stream.

    Parameters
    ----------
    transport
        A :class:`~reach_receiver.transports.udp.UdpReceiver`, or the (host, port) to
        bind one to.
    source, source_port
        With a (host, port) transport: the iTPM's IPv4 address, the only sender whose
        datagrams are taken, and its UDP port (0: any); None takes every sender's.
    n_channels, n_inputs
        Spectrum shape the firmware sends (16384 channels, 2 inputs for REACH).
    timeout_s
        Longest real wait for the next complete spectrum.
    clock
        Stamps integration requests (the system clock by default).
    floating_point
        Whether the firmware sends float64 spectra (REACH's setting); packets of the
        other mode are counted as malformed.
    max_open_heaps
        Heaps assembled at once; one more starting drops the oldest incomplete one.
    period_s
        Integration time of one spectrum as the firmware is configured, used to tell
        spectra that ended before a request; None estimates it from the spacing of
        consecutive timestamps (unknown until two consecutive spectra arrived).
    name
        Device name used in errors.
    """

    def __init__(
        self,
        transport: UdpReceiver | tuple[str, int] = ("0.0.0.0", spead.DEFAULT_PORT),
        *,
        source: str | None = None,
        source_port: int = 0,
        n_channels: int = 16384,
        n_inputs: int = 2,
        timeout_s: float = 5.0,
        clock: Clock | None = None,
        floating_point: bool = True,
        max_open_heaps: int = 2,
        period_s: float | None = None,
        name: str = "itpm",
    ) -> None:
        if isinstance(transport, UdpReceiver):
            if source is not None:
                raise ValueError("give the source address to the UdpReceiver passed")
            self.transport = transport
        else:
            host, port = transport
            self.transport = UdpReceiver(
                host, port, source=source, source_port=source_port, device=name
            )
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be positive, got {timeout_s}")
        self.name = name
        self.n_channels = n_channels
        self.n_inputs = n_inputs
        self.timeout_s = timeout_s
        self.clock: Clock = clock or SystemClock()
        self.floating_point = floating_point
        self.max_open_heaps = max(1, max_open_heaps)
        self.period_s = period_s
        self._period_estimate: float | None = None
        self._last_stamp: int | None = None
        self._per_fpga = spead.signals_per_fpga(n_inputs)
        self._per_packet = spead.PAYLOAD_BYTES // spead.VALUE_BYTES
        if (n_inputs * n_channels) % (2 * self._per_packet):
            raise ValueError(f"{n_inputs} x {n_channels} values do not fill whole packets")
        self.n_packets = n_inputs * n_channels // self._per_packet
        self._per_row = self.n_packets // 2
        self._gather = spead.heap_gather_index(n_inputs, n_channels, floating_point)
        self._dtype = "<f8" if floating_point else "<i8"
        self._buffer = bytearray(spead.PACKET_BYTES + 1)  # +1 reveals oversize datagrams
        self._view = memoryview(self._buffer)
        self._heaps: OrderedDict[int, _Heap] = OrderedDict()
        self._retired: OrderedDict[int, int] = OrderedDict()
        self._spare: list[bytearray] = []
        self._sync_time: int | None = None
        self._newest_retired: int | None = None
        self._reset_counters()

    def _reset_counters(self) -> None:
        self._received = 0
        self._malformed = 0
        self._duplicated = 0
        self._late = 0
        self._flushed = 0
        self._lost = 0
        self._completed = 0
        self._dropped = 0
        self._foreign_base = self.transport.foreign

    # -- connection -------------------------------------------------------------------

    def connect(self) -> None:
        """Bind the UDP socket; counters start from zero.

        Logs whose datagrams are taken: a warning when that is anyone's on an address
        other than loopback (where any host of the network could feed the spectra).
        """
        self.transport.open()
        self._log_sender()
        self._heaps.clear()
        self._retired.clear()
        self._sync_time = None
        self._newest_retired = None
        self._period_estimate = None
        self._last_stamp = None
        self._reset_counters()

    def _log_sender(self) -> None:
        transport = self.transport
        host, port = transport.address
        if transport.source is not None:
            logger.info("%s: spectra on UDP %s:%d from %s only", self.name, host, port,
                        transport.sender)
            return
        try:
            loopback = ipaddress.ip_address(host).is_loopback
        except ValueError:
            loopback = False
        log = logger.info if loopback else logger.warning
        log(
            "%s: spectra on UDP %s:%d are taken from any sender: set "
            "devices.spectrometer.source to the iTPM's address so that no other host's "
            "datagrams can enter a spectrum",
            self.name, host, port,
        )

    def close(self) -> None:
        """Close the socket."""
        self.transport.close()

    def __enter__(self) -> Spectrometer:
        self.connect()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port) packets should be sent to."""
        return self.transport.address

    @property
    def period(self) -> float | None:
        """Integration time of one spectrum: the configured one, else the estimate."""
        return self.period_s if self.period_s is not None else self._period_estimate

    @property
    def statistics(self) -> SpectrometerStatistics:
        """Packet and spectrum counters since :meth:`connect`."""
        return SpectrometerStatistics(
            packets_received=self._received,
            packets_malformed=self._malformed,
            packets_duplicated=self._duplicated,
            packets_late=self._late,
            packets_flushed=self._flushed,
            packets_lost=self._lost,
            spectra_completed=self._completed,
            heaps_dropped=self._dropped,
            packets_foreign=self.transport.foreign - self._foreign_base,
        )

    # -- reading ----------------------------------------------------------------------

    def read_spectrum(self, timeout_s: float | None = None) -> Spectrum:
        """Receive until one spectrum is complete and return it.

        Raises
        ------
        DeviceTimeout
            No spectrum completed within ``timeout_s`` (default: the driver's).
        """
        wait = self.timeout_s if timeout_s is None else timeout_s
        return self._next_spectrum(time.monotonic() + wait, "read_spectrum")

    def _next_spectrum(self, deadline: float, command: str) -> Spectrum:
        """The receive loop: kept to a few operations per packet (see the benchmark)."""
        recv = self.transport.recv_into
        parse = spead.parse_header
        buffer, view = self._buffer, self._view
        heaps = self._heaps
        per_fpga, per_row, per_packet = self._per_fpga, self._per_row, self._per_packet
        float_bit = spead.MODE_FLOATING_POINT if self.floating_point else 0
        monotonic = time.monotonic
        # A fixed poll interval: changing the socket's timeout costs system calls.
        poll = min(_POLL_S, self.timeout_s)
        while True:
            if monotonic() > deadline:
                raise DeviceTimeout(self.name, "no complete spectrum arrived in time", command)
            try:
                nbytes = recv(buffer, poll)
            except DeviceTimeout:
                continue
            self._received += 1
            try:
                heap_word, length, sync, stamp, mode, info, _, offset = parse(buffer, nbytes)
            except ProtocolError:
                self._malformed += 1
                continue
            row = ((info >> 8) & 0xFF) // per_fpga
            column = ((info >> 24) & 0xFFFF) * per_fpga
            if (
                (mode & spead.MODE_FLOATING_POINT) != float_bit
                or length - offset != spead.PAYLOAD_BYTES
                or row > 1
                or column % per_packet
                or column >= per_row * per_packet
            ):
                self._malformed += 1
                continue
            heap = heaps.get(stamp)
            if heap is None:
                heap = self._open_heap(stamp, sync, heap_word)
                if heap is None:
                    continue
            slot = row * per_row + column // per_packet
            if heap.seen[slot]:
                self._duplicated += 1
                continue
            heap.seen[slot] = 1
            start = slot * spead.PAYLOAD_BYTES
            data = spead.HEADER_BYTES + offset
            heap.raw[start : start + spead.PAYLOAD_BYTES] = view[data : data + spead.PAYLOAD_BYTES]
            heap.count += 1
            if heap.count == self.n_packets:
                return self._finish(stamp, heap)

    def _open_heap(self, stamp: int, sync: int, heap_word: int) -> _Heap | None:
        """Start assembling a new timestamp, or classify a packet of a closed heap."""
        if sync != self._sync_time:
            if self._sync_time is not None:
                logger.info("%s: sync time changed %s -> %s", self.name, self._sync_time, sync)
                self._retire_all(_DROPPED)
                self._retired.clear()
                self._newest_retired = None
                self._last_stamp = None
            self._sync_time = sync
        state = self._retired.get(stamp)
        newest = self._newest_retired
        if state is not None or (newest is not None and stamp < newest):
            if state == _COMPLETE:
                self._duplicated += 1
            elif state == _FLUSHED:
                self._flushed += 1
            else:
                self._late += 1
            return None
        while len(self._heaps) >= self.max_open_heaps:
            oldest = min(self._heaps)
            self._retire(oldest, _DROPPED)
        raw = self._spare.pop() if self._spare else bytearray(self.n_packets * spead.PAYLOAD_BYTES)
        heap = _Heap(self.n_packets, raw, sync, heap_word & 0xFFFFFF)
        self._heaps[stamp] = heap
        return heap

    def _retire(self, stamp: int, state: int) -> None:
        heap = self._heaps.pop(stamp, None)
        if heap is not None:
            if state == _DROPPED:
                self._dropped += 1
                self._lost += self.n_packets - heap.count
                logger.debug("%s: dropped heap %d with %d packets", self.name, stamp, heap.count)
            elif state == _FLUSHED:
                self._flushed += heap.count
            self._spare.append(heap.raw)
        self._retired[stamp] = state
        self._retired.move_to_end(stamp)
        if self._newest_retired is None or stamp > self._newest_retired:
            self._newest_retired = stamp
        while len(self._retired) > _RETIRED_MEMORY:
            self._retired.popitem(last=False)

    def _retire_all(self, state: int) -> None:
        for stamp in list(self._heaps):
            self._retire(stamp, state)

    def _finish(self, stamp: int, heap: _Heap) -> Spectrum:
        wire = np.frombuffer(heap.raw, dtype=self._dtype)
        data = wire[self._gather].astype(np.float64, copy=False)
        data = data.reshape(self.n_inputs, self.n_channels)
        self._retire(stamp, _COMPLETE)
        self._completed += 1
        if self._last_stamp is not None and stamp > self._last_stamp:
            spacing = (stamp - self._last_stamp) * spead.TIMESTAMP_UNIT_S
            if self._period_estimate is None or spacing < self._period_estimate:
                self._period_estimate = spacing
        self._last_stamp = stamp
        return Spectrum(
            timestamp=heap.sync_time + stamp * spead.TIMESTAMP_UNIT_S,
            data=data,
            raw_timestamp=stamp,
            sync_time=heap.sync_time,
            heap_counter=heap.heap_counter,
        )

    def flush(self) -> int:
        """Discard every datagram queued now and every partly assembled heap.

        Their timestamps are remembered, so the rest of a spectrum in flight at the
        request is ignored too rather than assembled into a partial heap. Reads at most
        as many datagrams as the receive buffer can hold, so a fast stream cannot keep
        it draining. Returns the number of datagrams discarded.
        """
        self._retire_all(_FLUSHED)
        limit = max(1, self.transport.rcvbuf_granted // spead.PACKET_BYTES)
        drained = 0
        while drained < limit:
            nbytes = self.transport.recv_into_nowait(self._buffer)
            if nbytes == 0:
                break
            drained += 1
            self._received += 1
            try:
                values = spead.parse_header(self._buffer, nbytes)
            except ProtocolError:
                self._malformed += 1
                continue
            self._flushed += 1
            stamp = values[3]
            if self._sync_time is None:
                self._sync_time = values[2]
            if values[2] == self._sync_time and stamp not in self._retired:
                self._retire(stamp, _FLUSHED)
        return drained

    def integrate(
        self,
        n_spectra: int,
        *,
        discard: int = 1,
        timeout_s: float | None = None,
        on_spectrum: Callable[[int, int], None] | None = None,
    ) -> AccumulatedSpectrum:
        """Average the next ``n_spectra`` complete spectra after dropping ``discard``.

        Spectra queued before the call are flushed first, and spectra whose integration
        ended before the request are skipped: their ``timestamp + period`` is not after
        the request time. This assumes the iTPM's time agrees with the clock to better
        than a period, and that a timestamp marks the start of its integration.

        Parameters
        ----------
        n_spectra
            Spectra to average (at least 1).
        discard
            Complete spectra to drop first; the first may straddle a switch change.
        timeout_s
            Real-time deadline of the whole integration; each spectrum must in any case
            arrive within the driver's ``timeout_s`` of the previous one.
        on_spectrum
            Called as ``on_spectrum(averaged, n_spectra)`` after each averaged spectrum:
            progress for the operator, and the place where a caller may stop a long
            integration by raising (the exception propagates unchanged).

        Raises
        ------
        DeviceTimeout
            A deadline passed; the message says how many spectra had arrived.
        """
        if n_spectra < 1 or discard < 0:
            raise ValueError(f"need n_spectra >= 1 and discard >= 0, got {n_spectra}, {discard}")
        requested_at = self.clock.now()
        before = self.statistics
        self.flush()
        overall = None if timeout_s is None else time.monotonic() + timeout_s
        total = np.zeros((self.n_inputs, self.n_channels))
        timestamps: list[float] = []
        skipped = stale = 0
        while len(timestamps) < n_spectra:
            deadline = time.monotonic() + self.timeout_s
            if overall is not None:
                deadline = min(deadline, overall)
            try:
                spectrum = self._next_spectrum(deadline, "integrate")
            except DeviceTimeout as err:
                message = (
                    f"integration timed out: {len(timestamps)} of {n_spectra} spectra arrived "
                    f"(after {skipped} of {discard} discarded)"
                )
                raise DeviceTimeout(self.name, message, "integrate") from err
            period = self.period
            if period is not None and spectrum.timestamp + period <= requested_at:
                stale += 1
                continue
            if skipped < discard:
                skipped += 1
                continue
            total += spectrum.data
            timestamps.append(spectrum.timestamp)
            if on_spectrum is not None:
                on_spectrum(len(timestamps), n_spectra)
        after = self.statistics
        return AccumulatedSpectrum(
            mean=total / n_spectra,
            n_spectra=n_spectra,
            n_discarded=skipped,
            n_stale=stale,
            start_time=timestamps[0],
            stop_time=timestamps[-1],
            timestamps=tuple(timestamps),
            requested_at=requested_at,
            packets_lost=after.packets_lost - before.packets_lost,
            packets_duplicated=after.packets_duplicated - before.packets_duplicated,
            packets_malformed=after.packets_malformed - before.packets_malformed,
            heaps_dropped=after.heaps_dropped - before.heaps_dropped,
            packets_foreign=after.packets_foreign - before.packets_foreign,
        )
