"""``python -m benchmarks.firmware_flood``: the firmware's host build under a flood of commands.

Starts the firmware's host build on a pseudo-terminal as the simulated receiver does
(:class:`~reach_receiver.sim.teensy_firmware.FirmwareTeensy`), opens the terminal raw,
and writes N tagged commands (``#<tag> ping``, ``state`` or a mix with switch moves)
from one thread while another reads the replies concurrently. It reports how many
replies came back, how many are missing once none has come for ``--grace-s`` (so a slow
reply is not counted as lost), replies cut short (two on one line), unknown or repeated
tags, the latency from a command's write to its reply (percentiles), and how many replies
the program said it dropped (``TXDROP``).

The pace is set by ``--rate`` (commands per second, 0: as fast as the terminal takes
them) and ``--depth`` (commands written but not yet answered, at most; 0: no limit).
``--reader-stall-ms`` makes the reader sleep that long after every read, standing in for
a host that lags. Replies are lost only when the unread ones overflow the board's
transmit buffering for 70 ms (firmware/PROTOCOL.md, "Flow control", where the measured
bound is tabled). Exit status 1 when any reply was missing or cut.
"""

from __future__ import annotations

import argparse
import os
import select
import sys
import termios
import threading
import time
import tty
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from reach_receiver.sim.teensy_firmware import FIRMWARE_DIR, FirmwareTeensy

COMMANDS = {
    "ping": ("ping",),
    "state": ("state",),
    # A realistic mix: queries, and switch moves that the interlocks allow (rails on first).
    "mix": ("ping", "state", "select ms1 3", "select ms1 4", "rail 12v", "deadman"),
}
_SETUP = ("rail 12v on", "rail 24v on")


@dataclass
class FloodResult:
    """What one flood saw."""

    sent: int
    received: int
    missing: int
    unknown: int
    repeated: int
    garbled: int
    errors: int
    elapsed_s: float
    latencies_s: np.ndarray = field(repr=False)
    dropped_by_firmware: str = ""  # what the program itself reported

    def percentile_ms(self, q: float) -> float:
        """Latency percentile ``q`` (0-100), in milliseconds; NaN when nothing came back."""
        if not self.latencies_s.size:
            return float("nan")
        return float(np.percentile(self.latencies_s, q) * 1e3)

    def summary(self) -> str:
        """One paragraph for the terminal."""
        rate = self.received / self.elapsed_s if self.elapsed_s > 0 else 0.0
        return (
            f"sent {self.sent}, replies {self.received}, missing {self.missing}, "
            f"unknown tags {self.unknown}, repeated {self.repeated}, garbled {self.garbled}, "
            f"ERR replies {self.errors}\n"
            f"{rate:.0f} replies/s over {self.elapsed_s:.2f} s; latency ms p50 "
            f"{self.percentile_ms(50):.2f} p90 {self.percentile_ms(90):.2f} "
            f"p99 {self.percentile_ms(99):.2f} max {self.percentile_ms(100):.2f}"
            + (f"\nfirmware state: {self.dropped_by_firmware}" if self.dropped_by_firmware else "")
        )


def _tag(i: int) -> str:
    digits = "0123456789abcdefghijklmnopqrstuvwxyz"
    out = ""
    while True:
        i, r = divmod(i, 36)
        out = digits[r] + out
        if not i:
            return out


def _open_raw(path: str) -> int:
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    termios.tcflush(fd, termios.TCIOFLUSH)
    return fd


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


def flood(
    port: str,
    n: int,
    *,
    command: str = "ping",
    rate: float = 0.0,
    depth: int = 0,
    reader_stall_ms: float = 0.0,
    grace_s: float = 5.0,
    batch: int = 1,
) -> FloodResult:
    """Write ``n`` tagged commands to ``port`` while a thread reads replies; count them."""
    fd = _open_raw(port)
    try:
        for k, line in enumerate(_SETUP):
            _write_all(fd, f"#s{k} {line}\n".encode())
        time.sleep(0.2)
        termios.tcflush(fd, termios.TCIFLUSH)
        commands = COMMANDS[command]
        sent_at = np.full(n, np.nan)
        got_at = np.full(n, np.nan)
        counts = {"unknown": 0, "repeated": 0, "garbled": 0, "errors": 0}
        answered = threading.Semaphore(depth) if depth > 0 else None
        done = threading.Event()
        stall = reader_stall_ms / 1e3

        def read_replies() -> None:
            pending = b""
            poller = select.poll()
            poller.register(fd, select.POLLIN)
            while not done.is_set():
                if not poller.poll(50):
                    continue
                try:
                    chunk = os.read(fd, 65536)
                except BlockingIOError:
                    continue
                now = time.perf_counter()
                pending += chunk
                *lines, pending = pending.split(b"\n")
                for raw in lines:
                    # Two replies on one line: the first was cut short (its tail dropped).
                    if raw.count(b"OK 00") + raw.count(b"ERR ") != 1:
                        counts["garbled"] += 1
                    parts = raw.split()
                    if len(parts) < 3 or not parts[2].startswith(b"#"):
                        counts["unknown"] += 1
                        continue
                    try:
                        i = int(parts[2][1:], 36)
                    except ValueError:
                        counts["unknown"] += 1
                        continue
                    if not 0 <= i < n:
                        counts["unknown"] += 1
                    elif not np.isnan(got_at[i]):
                        counts["repeated"] += 1
                    else:
                        got_at[i] = now
                        counts["errors"] += parts[0] == b"ERR"
                        if answered is not None:
                            answered.release()
                if stall:
                    time.sleep(stall)

        os.set_blocking(fd, False)
        reader = threading.Thread(target=read_replies, daemon=True)
        reader.start()
        start = time.perf_counter()
        i = 0
        while i < n:
            if rate > 0:
                due = start + i / rate
                wait = due - time.perf_counter()
                if wait > 0:
                    time.sleep(wait)
            stop = min(n, i + batch)
            chunk = []
            for j in range(i, stop):
                if answered is not None:
                    answered.acquire()
                chunk.append(f"#{_tag(j)} {commands[j % len(commands)]}\n")
            now = time.perf_counter()
            sent_at[i:stop] = now
            _write_blocking(fd, "".join(chunk).encode())
            i = stop
        # Replies still coming are slow, not lost: wait until none came for grace_s.
        while np.isnan(got_at).any():
            newest = np.nanmax(got_at) if not np.isnan(got_at).all() else start
            if time.perf_counter() - max(newest, sent_at[-1]) > grace_s:
                break
            time.sleep(0.02)
        done.set()
        reader.join(2.0)
        received = ~np.isnan(got_at)
        last = np.nanmax(got_at) if received.any() else time.perf_counter()
        return FloodResult(
            sent=n,
            received=int(received.sum()),
            missing=int(n - received.sum()),
            unknown=counts["unknown"],
            repeated=counts["repeated"],
            garbled=counts["garbled"],
            errors=counts["errors"],
            elapsed_s=float(last - start),
            latencies_s=(got_at - sent_at)[received],
        )
    finally:
        os.close(fd)


def _write_blocking(fd: int, data: bytes) -> None:
    """Write all of ``data`` to a non-blocking descriptor, waiting while the terminal is full."""
    view = memoryview(data)
    while view:
        try:
            view = view[os.write(fd, view) :]
        except BlockingIOError:
            select.select([], [fd], [], 0.05)


def main(argv: list[str] | None = None) -> int:
    """Run one flood and print what came back."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.firmware_flood", description=__doc__)
    p.add_argument("-n", type=int, default=20000, help="commands to send (20000)")
    p.add_argument("--command", choices=sorted(COMMANDS), default="mix")
    p.add_argument("--rate", type=float, default=0.0, help="commands/s (0: unpaced)")
    p.add_argument("--depth", type=int, default=0, help="most unanswered commands (0: no limit)")
    p.add_argument("--batch", type=int, default=1, help="commands per write()")
    p.add_argument("--reader-stall-ms", type=float, default=0.0,
                   help="the reader sleeps this long after each read (a host that lags)")
    p.add_argument("--firmware-dir", type=Path, default=FIRMWARE_DIR,
                   help="the firmware tree to build and run (another checkout's, to compare)")
    p.add_argument("--grace-s", type=float, default=5.0,
                   help="a reply missing after this long without any reply is lost")
    args = p.parse_args(argv)
    if args.n < 1 or args.rate < 0 or args.depth < 0 or args.batch < 1:
        print("firmware_flood: -n, --batch must be >= 1; --rate, --depth >= 0", file=sys.stderr)
        return 2
    with FirmwareTeensy(firmware_dir=args.firmware_dir) as teensy:
        result = flood(
            teensy.port, args.n, command=args.command, rate=args.rate, depth=args.depth,
            reader_stall_ms=args.reader_stall_ms, grace_s=args.grace_s, batch=args.batch,
        )
        time.sleep(0.1)  # the program's last TXDROP lines
        teensy.sync()
        state = teensy.state
        result.dropped_by_firmware = (
            f"boot={state.get('boot')} changes={state.get('changes')} "
            f"replies dropped (TXDROP)={teensy.replies_dropped}"
        )
    print(result.summary())
    return 1 if result.missing or result.garbled else 0


if __name__ == "__main__":
    sys.exit(main())
