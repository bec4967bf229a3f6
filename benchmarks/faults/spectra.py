"""Faults of the spectra stream: datagrams the spectrometer must drop, count and never use.

Each trial binds a real :class:`~reach_receiver.devices.spectrometer.Spectrometer` on
loopback that takes spectra only from its iTPM's address and port (the site's
``devices.spectrometer.source``), sends the fault over real UDP sockets together with
(or before) one true spectrum from that source, and judges:

* ``clean``: the spectrum read is the true one, bit for bit, and the bad datagrams are
  counted where they belong (foreign, malformed, duplicated, late);
* ``silent``: a wrong value entered a spectrum, or bad datagrams went uncounted;
* ``lost``: the true spectrum was not delivered although its packets arrived;
* ``crash``: the driver raised anything else, or overran its deadline under a flood.

Spoofed senders use other loopback addresses (127.0.0.2, 127.0.0.3), which Linux binds
without any set-up, or the source's own address with another port.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from reach_receiver.clock import SystemClock
from reach_receiver.devices import spead
from reach_receiver.devices.spectra import SpectrometerStatistics
from reach_receiver.devices.spectrometer import Spectrometer
from reach_receiver.errors import DeviceTimeout
from reach_receiver.sim.itpm import encode_spectrum

from .core import Trial, Verdict

CLASS = "spectra"

N_CHANNELS = 1024  # 16 packets a spectrum: real sockets, small enough to be quick
SYNC = 1_700_000_000
LOOPBACK = "127.0.0.1"


@dataclass
class Stream:
    """A spectrometer that takes its source's datagrams only, the source and two spoofers."""

    device: Spectrometer
    itpm: socket.socket
    spoofer: socket.socket  # another address
    same_host: socket.socket  # the source's address, another port
    truth: np.ndarray
    fake: np.ndarray

    def packets(self, stamp: int, data: np.ndarray | None = None) -> list[bytes]:
        """One spectrum's datagrams (the true one by default) at timestamp ``stamp``."""
        return encode_spectrum(self.truth if data is None else data, stamp, stamp, SYNC)

    def send(self, sock: socket.socket, datagrams: list[bytes]) -> None:
        """Send each datagram from ``sock`` to the spectrometer."""
        for datagram in datagrams:
            sock.sendto(datagram, self.device.address)


@contextlib.contextmanager
def stream() -> Iterator[Stream]:
    """A fresh spectrometer and senders on loopback, closed afterwards."""
    rng = np.random.default_rng(7)
    socks = []
    try:
        for host in (LOOPBACK, "127.0.0.2", LOOPBACK):
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            socks.append(sock)
            sock.bind((host, 0))
        itpm, spoofer, same_host = socks
        device = Spectrometer(
            (LOOPBACK, 0), source=LOOPBACK, source_port=itpm.getsockname()[1],
            n_channels=N_CHANNELS, timeout_s=1.0, clock=SystemClock(),
        )
        with device:
            yield Stream(
                device, itpm, spoofer, same_host,
                truth=rng.uniform(1.0, 2.0, (2, N_CHANNELS)),
                fake=rng.uniform(100.0, 200.0, (2, N_CHANNELS)),
            )
    finally:
        for sock in socks:
            sock.close()


# -------------------------------------------------------------- the faults
# Each sends its bad datagrams and the true spectrum, and returns the counter that must
# have grown and by how much (None: at least one).
Fault = Callable[[Stream], tuple[str, int | None]]


def spoofed_first(s: Stream) -> tuple[str, int | None]:
    """A spoofer sends a whole spectrum of the same timestamp just before the iTPM."""
    s.send(s.spoofer, s.packets(10, s.fake))
    s.send(s.itpm, s.packets(10))
    return "packets_foreign", 16


def spoofed_interleaved(s: Stream) -> tuple[str, int | None]:
    """Spoofed packets between the true ones, same timestamp, every slot."""
    for fake, true in zip(s.packets(10, s.fake), s.packets(10), strict=True):
        s.send(s.spoofer, [fake])
        s.send(s.itpm, [true])
    return "packets_foreign", 16


def spoofed_newer(s: Stream) -> tuple[str, int | None]:
    """A spoofer sends newer timestamps and another sync time (to retire true heaps)."""
    for k in range(3):
        fake = encode_spectrum(s.fake, 100 + k, 0, SYNC + 99)
        s.send(s.spoofer, fake)
    s.send(s.itpm, s.packets(10))
    return "packets_foreign", 48


def same_host_other_port(s: Stream) -> tuple[str, int | None]:
    """The iTPM's own address, another port (another process of the same host)."""
    s.send(s.same_host, s.packets(10, s.fake))
    s.send(s.itpm, s.packets(10))
    return "packets_foreign", 16


def truncated(s: Stream) -> tuple[str, int | None]:
    """The source's packets cut short at lengths from 1 byte to one byte short."""
    cut = [p[:n] for p, n in zip(s.packets(10, s.fake), (1, 8, 40, 71, 72, 73, 500, 1095),
                                 strict=False)]
    s.send(s.itpm, cut)
    s.send(s.itpm, s.packets(10))
    return "packets_malformed", len(cut)


def garbage(s: Stream) -> tuple[str, int | None]:
    """Random bytes of random lengths from the source."""
    rng = np.random.default_rng(3)
    junk = [rng.bytes(int(n)) for n in rng.integers(1, 2 * spead.PACKET_BYTES, 20)]
    s.send(s.itpm, junk)
    s.send(s.itpm, s.packets(10))
    return "packets_malformed", 20


def oversized(s: Stream) -> tuple[str, int | None]:
    """True packets with bytes appended (one, a hundred, up to 60 kB)."""
    big = [p + b"\0" * n for p, n in zip(s.packets(10, s.fake), (1, 100, 60000), strict=False)]
    s.send(s.itpm, big)
    s.send(s.itpm, s.packets(10))
    return "packets_malformed", 3


def _patched(packet: bytes, word: int, value: int) -> bytes:
    """A packet with its header word ``word`` replaced."""
    out = bytearray(packet)
    out[8 * word : 8 * word + 8] = value.to_bytes(8, "big")
    return bytes(out)


def wrong_item_ids(s: Stream) -> tuple[str, int | None]:
    """Unknown item ids, a repeated id, and a wrong header word, from the source."""
    fake = s.packets(10, s.fake)
    bad = [
        _patched(fake[0], 6, (0x9234 << 48) | 1),  # an item nobody defined
        _patched(fake[1], 6, int.from_bytes(fake[1][8:16], "big")),  # heap counter twice
        _patched(fake[2], 0, spead.HEADER_WORD ^ (1 << 48)),  # SPEAD version 5
        _patched(fake[3], 0, spead.HEADER_WORD + 1),  # 9 items announced
    ]
    s.send(s.itpm, bad)
    s.send(s.itpm, s.packets(10))
    return "packets_malformed", len(bad)


def wrong_fields(s: Stream) -> tuple[str, int | None]:
    """Integer mode, a channel past the end, a lying payload length, from the source."""
    fake = s.packets(10, s.fake)
    mode = (int(spead.IMMEDIATE | spead.MODE) << 48) | spead.SIMULATED_MODE
    info = (int(spead.IMMEDIATE | spead.CHANNEL_INFO) << 48) | (N_CHANNELS << 24) | 1
    length = (int(spead.IMMEDIATE | spead.PAYLOAD_LENGTH) << 48) | 1016
    bad = [_patched(fake[0], 5, mode), _patched(fake[1], 6, info), _patched(fake[2], 2, length)]
    s.send(s.itpm, bad)
    s.send(s.itpm, s.packets(10))
    return "packets_malformed", len(bad)


def empty(s: Stream) -> tuple[str, int | None]:
    """Zero-length datagrams from the source."""
    s.send(s.itpm, [b""] * 5)
    s.send(s.itpm, s.packets(10))
    return "packets_malformed", 5


def out_of_order(s: Stream) -> tuple[str, int | None]:
    """The true spectrum's packets reversed, then shuffled: nothing to drop."""
    s.send(s.itpm, s.packets(10)[::-1])
    return "packets_received", 16


def duplicated(s: Stream) -> tuple[str, int | None]:
    """Every true packet sent twice."""
    for packet in s.packets(10):
        s.send(s.itpm, [packet, packet])
    return "packets_duplicated", 16  # the last copy: a duplicate of a delivered spectrum


def late(s: Stream) -> tuple[str, int | None]:
    """Packets of an older spectrum than one already started, from the source."""
    true = s.packets(10)
    s.send(s.itpm, true[:8])
    s.send(s.itpm, encode_spectrum(s.fake, 12, 12, SYNC)[:4])  # opens a newer heap
    s.send(s.itpm, encode_spectrum(s.fake, 11, 11, SYNC)[:4])  # and another: 10 dropped
    s.send(s.itpm, true[8:])  # too late: its heap was dropped
    s.send(s.itpm, s.packets(13))
    return "packets_late", 8


FAULTS: dict[str, Fault] = {
    "spoofed sender, whole spectrum first": spoofed_first,
    "spoofed sender, interleaved": spoofed_interleaved,
    "spoofed sender, newer timestamps and sync": spoofed_newer,
    "source address, other port": same_host_other_port,
    "truncated datagrams": truncated,
    "garbage datagrams": garbage,
    "oversized datagrams": oversized,
    "wrong item ids and header": wrong_item_ids,
    "wrong mode, channel, length": wrong_fields,
    "empty datagrams": empty,
    "out of order": out_of_order,
    "duplicated packets": duplicated,
    "late packets of a dropped heap": late,
}


def try_fault(name: str, fault: Fault) -> Trial:
    """Send one fault and the true spectrum; judge what the spectrometer made of them."""
    try:
        with stream() as s:
            before = s.device.statistics
            counter, expected = fault(s)
            spectrum = s.device.read_spectrum(timeout_s=2.0)
            time.sleep(0.05)  # what was sent after the last true packet: read and count it
            with contextlib.suppress(DeviceTimeout):
                s.device.read_spectrum(timeout_s=0.1)
            grown = getattr(s.device.statistics, counter) - getattr(before, counter)
            truth = s.truth
    except DeviceTimeout as err:
        return Trial(name, "lost", f"the true spectrum never came: {err}")
    except Exception as err:  # anything else the driver raises is a crash of the reader
        return Trial(name, "crash", f"{type(err).__name__}: {err}")
    return _judge(name, spectrum.data, truth, counter, grown, expected)


def _judge(
    name: str, data: np.ndarray, truth: np.ndarray, counter: str, grown: int, expected: int | None
) -> Trial:
    if not np.array_equal(data, truth):
        wrong = int(np.sum(data != truth))
        return Trial(name, "silent", f"{wrong} values of the spectrum are not the source's")
    if (expected is None and grown < 1) or (expected is not None and grown != expected):
        return Trial(name, "silent", f"{counter} grew by {grown}, expected {expected}")
    return Trial(name, "clean", f"true spectrum taken; {counter} +{grown}")


def flood(quick: bool) -> Trial:
    """A spoofer floods the port while the iTPM streams: every spectrum taken is true."""
    name = f"flood of {2000 if quick else 50000} spoofed datagrams"
    count = 2000 if quick else 50000
    try:
        with stream() as s:
            fake = s.packets(0, s.fake)
            stop = threading.Event()

            def spoof() -> None:
                for k in range(count):
                    s.spoofer.sendto(fake[k % len(fake)], s.device.address)
                stop.set()

            sender = threading.Thread(target=spoof, daemon=True)
            sender.start()
            taken: list[np.ndarray] = []
            stamp = 10
            while not stop.is_set() or not taken:
                s.send(s.itpm, s.packets(stamp))
                stamp += 1
                with contextlib.suppress(DeviceTimeout):
                    taken.append(s.device.read_spectrum(timeout_s=0.2).data)
                if stamp > 10 + 10 * count:
                    break
            sender.join(5.0)
            foreign = s.device.statistics.packets_foreign
            truth = s.truth
    except Exception as err:
        return Trial(name, "crash", f"{type(err).__name__}: {err}")
    if not taken:
        return Trial(name, "lost", "no true spectrum delivered during the flood")
    wrong = sum(not np.array_equal(d, truth) for d in taken)
    if wrong or foreign < 1:
        return Trial(name, "silent", f"{wrong} wrong spectra taken, {foreign} foreign counted")
    return Trial(name, "clean", f"{len(taken)} true spectra taken; {foreign} foreign dropped")


def flood_without_source(quick: bool) -> Trial:
    """Only spoofed datagrams arrive: the read ends at its deadline, not later."""
    name = "flood with the source silent"
    count = 3000 if quick else 30000
    with stream() as s:
        fake = s.packets(0, s.fake)
        sender = threading.Thread(
            target=lambda: [s.spoofer.sendto(fake[k % 16], s.device.address) for k in range(count)],
            daemon=True,
        )
        sender.start()
        start = time.monotonic()
        try:
            s.device.read_spectrum(timeout_s=0.5)
        except DeviceTimeout:
            took = time.monotonic() - start
            verdict: Verdict = "clean" if took < 1.5 else "crash"
            stats: SpectrometerStatistics = s.device.statistics
            detail = f"timed out after {took:.2f} s; {stats.packets_foreign} foreign dropped"
            if stats.packets_received:
                verdict, detail = "silent", f"{stats.packets_received} spoofed taken in"
            return Trial(name, verdict, detail)
        except Exception as err:
            return Trial(name, "crash", f"{type(err).__name__}: {err}")
        finally:
            sender.join(10.0)
    return Trial(name, "silent", "a spectrum was assembled from spoofed datagrams")


def trials(workdir: Path, quick: bool) -> Iterator[Trial]:
    """Every fault of the stream, each against a fresh spectrometer."""
    del workdir  # nothing is written: sockets only
    for name, fault in FAULTS.items():
        yield try_fault(name, fault)
    yield flood(quick)
    yield flood_without_source(quick)
