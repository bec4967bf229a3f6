"""Operator entry points of the receiver side: ``reach-sim`` (and, later, ``reach-run``).

``reach-sim`` starts the simulated receiver as its own process, prints the site file that
reaches its instruments (and writes it with ``--site-out``), and serves until Ctrl-C or
SIGTERM. Failures print one line, without a traceback, and exit non-zero.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from types import FrameType

from reach_receiver.errors import ReceiverError
from reach_receiver.sim.receiver import DEFAULT_COMPRESSION, SimulatedReceiver, SimulationSettings


def _sim_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="reach-sim",
        description="Run the simulated REACH receiver (Teensy firmware, TEC, VNA, iTPM, TC-08) "
        "on real transports, for dry runs of reach-run.",
    )
    parser.add_argument(
        "--compression",
        type=float,
        default=DEFAULT_COMPRESSION,
        help=f"simulated seconds per real second (default {DEFAULT_COMPRESSION:g})",
    )
    parser.add_argument(
        "--spectrum-period",
        type=float,
        default=30.0,
        help="simulated seconds integrated into each iTPM spectrum (default 30)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of every simulated noise")
    parser.add_argument(
        "--spectrometer-port", type=int, default=None, help="UDP port to send spectra to"
    )
    parser.add_argument("--site-out", type=Path, help="also write the site file here")
    parser.add_argument(
        "--run-for", type=float, default=None, help="stop after this many real seconds"
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log what the sims do")
    return parser


def sim_main(argv: Sequence[str] | None = None) -> int:
    """``reach-sim``: serve the simulated receiver until interrupted."""
    args = _sim_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(asctime)s %(name)s: %(message)s",
    )
    settings = SimulationSettings(
        compression=args.compression, spectrum_period_s=args.spectrum_period, seed=args.seed
    )
    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        del signum, frame
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    try:
        with SimulatedReceiver(settings, spectrometer_port=args.spectrometer_port) as sim:
            text = sim.site().to_yaml()
            if args.site_out is not None:
                args.site_out.write_text(text)
            print("# site file of the simulated receiver (reach-run --site <file>)")
            print(text, flush=True)
            print(f"# serving at {settings.compression:g}x real time; Ctrl-C stops", flush=True)
            stop.wait(args.run_for)
    except (ReceiverError, OSError) as err:
        print(f"reach-sim: {err}", file=sys.stderr)
        return 1
    return 0


# ------------------------------------------------------------------------------- reach-run
def _run_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="reach-run",
        description="Check and run a YAML schedule against the receiver (a site file) or the "
        "simulated receiver (--sim).",
    )
    parser.add_argument("schedule", type=Path, help="the schedule, e.g. schedules/calibrate.yaml")
    target = parser.add_mutually_exclusive_group()
    target.add_argument("--site", type=Path, help="site file of the real instrument")
    target.add_argument(
        "--sim", action="store_true", help="run against the simulated receiver, in-process"
    )
    parser.add_argument(
        "--validate", action="store_true", help="check the schedule, print its duration, exit"
    )
    parser.add_argument(
        "--dry-run", action="store_true", help="print the step list and its timing, exit"
    )
    parser.add_argument("--out", type=Path, default=Path("runs"), help="directory of run files")
    parser.add_argument(
        "--compression",
        type=float,
        default=DEFAULT_COMPRESSION,
        help=f"--sim: simulated seconds per real second (default {DEFAULT_COMPRESSION:g})",
    )
    parser.add_argument("--seed", type=int, default=0, help="--sim: seed of the simulation")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    parser.add_argument("-v", "--verbose", action="store_true", help="log every action")
    return parser


def run_main(argv: Sequence[str] | None = None) -> int:
    """``reach-run``: validate, then run a schedule; exit 0 only if it completed."""
    from reach_receiver.runcli import run_command

    args = _run_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(asctime)s %(name)s: %(message)s",
    )
    return run_command(args)
