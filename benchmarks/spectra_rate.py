"""Spectra receive rate: how many iTPM packets per second the driver assembles with no loss.

Usage (from the repository root)::

    python -m benchmarks.spectra_rate

A sender process (``multiprocessing``) replays one pre-encoded 2 x 16384 spectrum (256
SPEAD packets, ``reach_receiver.sim.itpm.encode_spectrum``), patching only the
timestamp item of each burst, to a :class:`~reach_receiver.devices.spectrometer.Spectrometer`
in this process over loopback UDP. It sends one burst of 256 packets per spectrum, as
the iTPM does, either paced at a target rate or as fast as it can.

Measured, all in one run:

* for each paced rate: packets/s and spectra/s received, whether every spectrum arrived
  complete (zero loss: no packet lost, dropped by the kernel or malformed), and the
  receiving process's CPU time per wall second (``time.process_time``; the sender runs in
  another process). The issue asks for >= 100 x the iTPM's real rate (one spectrum of 256
  packets per second, so 25,600 packets/s) with zero loss on < 1 core;
* the same with the sender unpaced (its own maximum);
* a baseline in the same run: a bare ``recv_into`` loop that decodes nothing, fed by the
  same unpaced sender; our CPU cost per packet is printed as a ratio of its cost, since
  machines and loads differ.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import socket
import time
from dataclasses import dataclass
from multiprocessing.queues import Queue
from multiprocessing.synchronize import Event

import numpy as np

from reach_receiver.devices import spead
from reach_receiver.devices.spectrometer import Spectrometer
from reach_receiver.errors import DeviceTimeout
from reach_receiver.sim.itpm import encode_spectrum
from reach_receiver.transports.udp import UdpReceiver

PACKETS_PER_SPECTRUM = 256
REAL_PACKETS_PER_S = 256.0  # the iTPM: one 2 x 16384 float64 spectrum per second
TARGET_RATIO = 100.0
STAMPS_PER_SECOND = round(1.0 / spead.TIMESTAMP_UNIT_S)
_TIMESTAMP_WORD = 1 + spead.ITEM_ORDER.index(spead.TIMESTAMP)


@dataclass(frozen=True)
class RateResult:
    """One receive run: what was sent, what arrived complete, and the CPU it cost."""

    label: str
    target_spectra_per_s: float  # 0 = sender unpaced
    spectra_sent: int
    packets_sent: int
    spectra_received: int
    packets_received: int
    packets_lost: int
    kernel_drops: int
    wall_s: float
    cpu_s: float

    @property
    def packets_per_s(self) -> float:
        """Packets received per wall second."""
        return self.packets_received / self.wall_s if self.wall_s > 0 else 0.0

    @property
    def spectra_per_s(self) -> float:
        """Complete spectra per wall second."""
        return self.spectra_received / self.wall_s if self.wall_s > 0 else 0.0

    @property
    def cpu_fraction(self) -> float:
        """Receiving process CPU seconds per wall second (1.0 = one core)."""
        return self.cpu_s / self.wall_s if self.wall_s > 0 else 0.0

    @property
    def cpu_us_per_packet(self) -> float:
        """Receiving CPU time per packet received, microseconds."""
        return 1e6 * self.cpu_s / max(self.packets_received, 1)

    @property
    def zero_loss(self) -> bool:
        """Every spectrum sent arrived complete."""
        return (
            self.spectra_received == self.spectra_sent
            and self.packets_lost == 0
            and self.kernel_drops == 0
        )


def _kernel_udp_drops() -> int:
    """Linux's count of datagrams dropped for a full receive buffer (0 where unknown)."""
    try:
        with open("/proc/net/snmp") as handle:
            lines = [line.split() for line in handle if line.startswith("Udp:")]
        return int(lines[1][lines[0].index("RcvbufErrors")])
    except (OSError, ValueError, IndexError):
        return 0


def _send(
    port: int, n_spectra: int, spectra_per_s: float, ready: Event, go: Event, done: Queue
) -> None:
    """Sender process: replay one encoded spectrum ``n_spectra`` times with new timestamps."""
    spectrum = np.random.default_rng(0).uniform(1e3, 1e7, (2, 16384))
    packets = encode_spectrum(spectrum, 0, 0, 1_700_000_000)
    frames = np.frombuffer(b"".join(packets), dtype=np.uint8).reshape(len(packets), -1).copy()
    words = frames.view(">u8")
    timestamp_id = int(spead.IMMEDIATE | spead.TIMESTAMP) << 48
    rows = [frame.data for frame in frames]
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4 * 1024 * 1024)
    sock.connect(("127.0.0.1", port))
    send = sock.send
    ready.set()
    go.wait(10.0)
    start = time.perf_counter()
    for i in range(n_spectra):
        if spectra_per_s > 0:
            delay = start + i / spectra_per_s - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        words[:, _TIMESTAMP_WORD] = timestamp_id | ((i + 1) * STAMPS_PER_SECOND)
        for row in rows:
            send(row)
    done.put((n_spectra, n_spectra * len(rows), time.perf_counter() - start))
    sock.close()


def _run(label: str, n_spectra: int, spectra_per_s: float, bare: bool = False) -> RateResult:
    """Start a sender, receive until it is done, and measure the receiving side."""
    ctx = mp.get_context("spawn")
    receiver = UdpReceiver("127.0.0.1", 0, device="itpm", timeout_s=1.0)
    device = Spectrometer(receiver, timeout_s=1.0)
    device.connect()
    ready, go, done = ctx.Event(), ctx.Event(), ctx.Queue()
    sender = ctx.Process(
        target=_send, args=(device.address[1], n_spectra, spectra_per_s, ready, go, done)
    )
    sender.start()
    try:
        if not ready.wait(30.0):
            raise RuntimeError("sender process did not start")
        drops0 = _kernel_udp_drops()
        wall0, cpu0 = time.perf_counter(), time.process_time()
        go.set()
        received = _receive_bare(receiver, n_spectra) if bare else _receive(device, n_spectra)
        cpu = time.process_time() - cpu0
        spectra, packets, end = received
        wall = end - wall0
        spectra_sent, packets_sent, _ = done.get(timeout=30.0)
        sender.join(10.0)
        stats = device.statistics
        return RateResult(
            label=label,
            target_spectra_per_s=spectra_per_s,
            spectra_sent=spectra_sent,
            packets_sent=packets_sent,
            spectra_received=spectra,
            packets_received=packets,
            packets_lost=0 if bare else packets_sent - stats.packets_received,
            kernel_drops=_kernel_udp_drops() - drops0,
            wall_s=wall,
            cpu_s=cpu,
        )
    finally:
        if sender.is_alive():
            sender.terminate()
            sender.join(5.0)
        done.close()
        done.join_thread()
        device.close()


def _receive(device: Spectrometer, n_spectra: int) -> tuple[int, int, float]:
    """Read spectra until ``n_spectra`` or a 1 s silence; the time is the last one's."""
    spectra = 0
    end = time.perf_counter()
    while spectra < n_spectra:
        try:
            device.read_spectrum()
        except DeviceTimeout:
            break
        spectra += 1
        end = time.perf_counter()
    return spectra, device.statistics.packets_received, end


def _receive_bare(receiver: UdpReceiver, n_spectra: int) -> tuple[int, int, float]:
    """Baseline: count datagrams with a bare recv_into loop, decoding nothing."""
    buffer = bytearray(spead.PACKET_BYTES + 1)
    recv = receiver.recv_into
    expected = n_spectra * PACKETS_PER_SPECTRUM
    packets = 0
    end = time.perf_counter()
    while packets < expected:
        try:
            recv(buffer, 0.5)
        except DeviceTimeout:
            break
        packets += 1
        end = time.perf_counter()
    return packets // PACKETS_PER_SPECTRUM, packets, end


def _print(result: RateResult) -> None:
    target = (
        f"{result.target_spectra_per_s * PACKETS_PER_SPECTRUM:8.0f}"
        if result.target_spectra_per_s
        else "  unpaced"
    )
    print(
        f"  {result.label:<22} target {target} pkt/s | received {result.packets_per_s:9.0f} "
        f"pkt/s = {result.spectra_per_s:7.1f} spectra/s | "
        f"{result.spectra_received}/{result.spectra_sent} spectra, "
        f"lost {result.packets_sent - result.packets_received} pkts, "
        f"kernel drops {result.kernel_drops} | CPU {result.cpu_fraction:5.2f} core, "
        f"{result.cpu_us_per_packet:5.2f} us/pkt | zero loss: {result.zero_loss}"
    )


def main(argv: list[str] | None = None) -> list[RateResult]:
    """Run the paced ladder, the unpaced run and the baseline; print the summary."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--seconds", type=float, default=2.0, help="length of each paced run")
    parser.add_argument(
        "--ratios",
        type=float,
        nargs="+",
        default=[100.0, 200.0, 400.0, 800.0],
        help="paced rates as multiples of the real iTPM rate",
    )
    args = parser.parse_args(argv)
    print("Spectra receive rate (loopback UDP, 2 x 16384 float64 spectra, 256 packets each)")
    results = []
    for ratio in args.ratios:
        spectra_per_s = ratio * REAL_PACKETS_PER_S / PACKETS_PER_SPECTRUM
        n = max(10, round(spectra_per_s * args.seconds))
        results.append(_run(f"paced {ratio:g} x", n, spectra_per_s))
        _print(results[-1])
    n_unpaced = max(10, round(max(args.ratios) * args.seconds))
    unpaced = _run("unpaced", n_unpaced, 0.0)
    _print(unpaced)
    baseline = _run("baseline bare recv", n_unpaced, 0.0, bare=True)
    _print(baseline)
    results += [unpaced, baseline]

    clean = [r for r in results[:-1] if r.zero_loss]
    best = max(clean, key=lambda r: r.packets_per_s) if clean else None
    at_target = next((r for r in results if r.target_spectra_per_s and r.zero_loss), None)
    print("=" * 100)
    print("SUMMARY (all measured in this run)")
    if best is None:
        print("  no run was loss-free")
    else:
        ratio = best.packets_per_s / REAL_PACKETS_PER_S
        print(
            f"  best zero-loss rate {best.packets_per_s:9.0f} packets/s = "
            f"{best.spectra_per_s:.1f} spectra/s ({best.label}), "
            f"CPU {best.cpu_fraction:.2f} core"
        )
        print(f"  ratio to real iTPM rate: {ratio:.0f} x")
    if at_target is not None:
        at_ratio = at_target.packets_per_s / REAL_PACKETS_PER_S
        passed = at_ratio >= 0.99 * TARGET_RATIO and at_target.cpu_fraction < 1.0
        print(
            f"  at {at_target.label}: zero loss, CPU {at_target.cpu_fraction:.3f} core "
            f"({at_target.cpu_us_per_packet:.2f} us/packet); target >= {TARGET_RATIO:g} x "
            f"with zero loss on < 1 core: {'PASS' if passed else 'FAIL'}"
        )
    else:
        print(f"  no paced run was loss-free; target >= {TARGET_RATIO:g} x: FAIL")
    rate_ratio = unpaced.packets_per_s / max(baseline.packets_per_s, 1.0)
    print(
        f"  unpaced: ours {unpaced.packets_per_s:9.0f} pkt/s, bare recv loop "
        f"{baseline.packets_per_s:9.0f} pkt/s: ratio {rate_ratio:.2f}"
    )
    print(
        f"  CPU per packet: ours {unpaced.cpu_us_per_packet:.2f} us, bare recv loop "
        f"{baseline.cpu_us_per_packet:.2f} us: ours / bare = "
        f"{unpaced.cpu_us_per_packet / max(baseline.cpu_us_per_packet, 1e-9):.2f} x"
    )
    return results


if __name__ == "__main__":
    main()
