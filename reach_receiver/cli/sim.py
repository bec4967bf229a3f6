"""``reach-sim``: the simulated receiver in its own process, for dry runs.

It starts the simulated receiver as its own process, prints the site file that
reaches its instruments (and writes it with ``--site-out``), and serves until Ctrl-C or
SIGTERM. Failures print one line, without a traceback, and exit non-zero.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from types import FrameType

from reach_receiver.errors import ReceiverError

from .logs import add_version, configure_logging
from .run import DEFAULT_COMPRESSION

# The simulator (numpy, h5py, the engine) is imported once the arguments are read: --help
# and --version answer without it.


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
        default=None,
        help="simulated seconds integrated into each iTPM spectrum "
        "(default: compression / 100, at least 1: 30 at the default compression)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of every simulated noise")
    parser.add_argument(
        "--spectrometer-port", type=int, default=None, help="UDP port to send spectra to"
    )
    parser.add_argument("--site-out", type=Path, help="also write the site file here")
    parser.add_argument(
        "--effects",
        action="store_true",
        help="an MTS two-port, cables warmer at one end, a cable-cooled hot load, RFI spikes "
        "(reach_receiver.sim.effects); the site file then describes their corrections",
    )
    parser.add_argument(
        "--run-for", type=float, default=None, help="stop after this many real seconds"
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log what the sims do")
    add_version(parser)
    return parser


def sim_main(argv: Sequence[str] | None = None) -> int:
    """``reach-sim``: serve the simulated receiver until interrupted."""
    args = _sim_parser().parse_args(argv)
    configure_logging(args.verbose)
    from reach_receiver.sim.effects import SimEffects
    from reach_receiver.sim.physics import PhysicsConfig
    from reach_receiver.sim.receiver import (
        SimulatedReceiver,
        SimulationSettings,
        spectrum_period_for,
    )

    period = args.spectrum_period or spectrum_period_for(args.compression)
    settings = SimulationSettings(
        compression=args.compression,
        spectrum_period_s=period,
        seed=args.seed,
        physics=PhysicsConfig(effects=SimEffects.all() if args.effects else SimEffects()),
    )
    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        del signum, frame
        stop.set()

    for handled in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
        signal.signal(handled, on_signal)
    try:
        with SimulatedReceiver(settings, spectrometer_port=args.spectrometer_port) as sim:
            text = sim.site().to_yaml()
            if args.site_out is not None:  # whole or not at all: a reader may be waiting
                partial = args.site_out.with_name(args.site_out.name + ".partial")
                partial.write_text(text)
                os.replace(partial, args.site_out)
            print("# site file of the simulated receiver (reach-run --site <file>)")
            print(text, flush=True)
            print(f"# serving at {settings.compression:g}x real time; Ctrl-C stops", flush=True)
            stop.wait(args.run_for)
    except (ReceiverError, OSError) as err:
        print(f"reach-sim: {err}", file=sys.stderr)
        return 1
    return 0
