"""``reach-run``: check a schedule before anything moves, then run it and summarise.

A thin command over the run layer (:class:`~reach_receiver.run.session.RunSession`):

1. The site file is found (``--site``, else ``$REACH_SITE``, else
   ``/etc/reach/site.yaml``; with ``--sim`` the simulated receiver's) and checked, and
   the schedule is compiled against it; every mistake is printed as ``file:line: key:
   message``: exit 2, and no device has been contacted. The estimated duration is
   printed. When ``reachd`` owns the hardware, the schedule goes to it instead
   (:mod:`.remote`: submit, follow, detach, ``--attach``); otherwise ``reach-run`` runs
   it itself, holding the same hardware lock the daemon takes.
2. ``--validate`` stops there; ``--dry-run`` prints the step list with its timing.
3. Otherwise the run goes, with progress on standard error. SIGINT (Ctrl-C), SIGTERM
   and SIGHUP (a dropped SSH session) ask it to stop: the front-end goes to its safe
   state, the run file is closed with the reason, exit 1. A second signal stops at once.
4. A completed run prints its checks, the solution (orders, noise scale, distance to the
   noise floor) and, with ``--sim``, the actual calibration error against the
   simulator's truth; a run that made a calibration gets its report in
   ``<run dir>/report/``, drawn by the run session (:mod:`reach_receiver.run.report`;
   ``--no-report`` skips it).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import signal
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING

from .logs import add_version, configure_logging

# The engine, the run layer and the simulator are imported when a schedule is checked or
# run, not for ``--help``: they cost about a second before anything is printed.
if TYPE_CHECKING:
    from reach_receiver.clock import Clock
    from reach_receiver.config.site import SiteConfig
    from reach_receiver.run.context import Progress
    from reach_receiver.run.session import RunSession
    from reach_receiver.sim.receiver import SimulatedReceiver

#: Simulated seconds per real second of ``--sim`` (the simulator's ``DEFAULT_COMPRESSION``;
#: tests/test_cli_commands.py holds the two equal).
DEFAULT_COMPRESSION = 3000.0

log = logging.getLogger(__name__)

#: Signals that stop a run cooperatively; a second one stops it at once.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def parser() -> argparse.ArgumentParser:
    """The command line of ``reach-run``."""
    p = argparse.ArgumentParser(
        prog="reach-run",
        description="Check and run a YAML schedule against the receiver (a site file) or the "
        "simulated receiver (--sim).",
    )
    p.add_argument(
        "schedule", type=Path, nargs="?", help="the schedule, e.g. schedules/calibrate.yaml"
    )
    target = p.add_mutually_exclusive_group()
    target.add_argument(
        "--site",
        type=Path,
        help="site file of the instrument (default: $REACH_SITE, else /etc/reach/site.yaml)",
    )
    target.add_argument(
        "--sim", action="store_true", help="run against the simulated receiver, in-process"
    )
    p.add_argument("--validate", action="store_true", help="check the schedule, print its duration")
    p.add_argument("--dry-run", action="store_true", help="print the step list and its timing")
    p.add_argument("--out", type=Path, default=Path("runs"), help="directory of run directories")
    p.add_argument(
        "--compression",
        type=float,
        default=DEFAULT_COMPRESSION,
        help=f"--sim: simulated seconds per real second (default {DEFAULT_COMPRESSION:g})",
    )
    p.add_argument(
        "--spectrum-period",
        type=float,
        default=None,
        help="--sim: the simulated iTPM's seconds per spectrum (default: compression / 100, "
        "at least 1)",
    )
    p.add_argument("--seed", type=int, default=0, help="--sim: seed of the simulation")
    p.add_argument(
        "--effects",
        action="store_true",
        help="--sim: an MTS two-port, cables warmer at one end, a cable-cooled hot load, RFI "
        "spikes (reach_receiver.sim.effects); the simulated site describes their corrections, "
        "which the calibrate step applies",
    )
    p.add_argument(
        "--no-report",
        action="store_true",
        help="do not draw the calibration's report (figures, summary) into <run dir>/report/",
    )
    daemon = p.add_argument_group("with reachd running (it owns the hardware)")
    daemon.add_argument("--detach", action="store_true", help="submit, do not follow")
    daemon.add_argument(
        "--attach", nargs="?", type=int, const=0, metavar="JOB",
        help="follow a job again (the current one by default)",
    )
    daemon.add_argument(
        "--status", action="store_true",
        help="the daemon's state, alarms and latest readings (also: reach-run status)",
    )
    daemon.add_argument("--queue", action="store_true", help="its jobs")
    daemon.add_argument("--cancel", type=int, metavar="JOB", help="drop or stop a job")
    daemon.add_argument("--abort", action="store_true", help="stop the run now, go safe")
    daemon.add_argument("--resume", action="store_true", help="run the queue again")
    p.add_argument("--json", action="store_true",
                   help="with --validate/--dry-run: the checked schedule as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on standard error")
    p.add_argument("-v", "--verbose", action="store_true", help="log every action")
    add_version(p)
    return p


def run_main(argv: Sequence[str] | None = None) -> int:
    """``reach-run``: validate, then run a schedule; exit 0 only if it completed.

    ``reach-run metrics ...`` and ``reach-run status ...`` are the health commands
    (:mod:`.health`; ``status`` is ``--status``): a schedule is a YAML file, so a schedule
    literally named ``metrics`` or ``status`` is given as ``./metrics``.
    """
    words = list(sys.argv[1:] if argv is None else argv)
    if words[:1] == ["metrics"]:
        from .health import metrics_main

        return metrics_main(words[1:])
    if words[:1] == ["status"]:
        words = ["--status", *words[1:]]
    args = parser().parse_args(words)
    configure_logging(args.verbose)
    return _run(args)


def _run(args: argparse.Namespace) -> int:
    """The command once its arguments are read: the heavy modules are imported here."""
    from reach_receiver.config.site import find_site, load_site
    from reach_receiver.daemon.client import DaemonClient, daemon_answers, socket_path
    from reach_receiver.daemon.lock import HardwareBusy
    from reach_receiver.errors import ReceiverError
    from reach_receiver.run.session import RunFailed, RunSession
    from reach_receiver.schedule.compile import ScheduleError
    from reach_receiver.schedule.timing import format_timeline, hms
    from reach_receiver.sim.effects import SimEffects
    from reach_receiver.sim.physics import PhysicsConfig
    from reach_receiver.sim.receiver import (
        SimulatedReceiver,
        SimulationSettings,
        simulated_site,
        spectrum_period_for,
    )

    from . import remote
    from .steer import request

    settings = SimulationSettings(
        compression=args.compression,
        spectrum_period_s=args.spectrum_period or spectrum_period_for(args.compression),
        seed=args.seed,
        physics=PhysicsConfig(effects=SimEffects.all() if args.effects else SimEffects()),
    )
    try:
        site = simulated_site(settings) if args.sim else load_site(find_site(args.site))
    except ReceiverError as err:
        print(f"reach-run: {err}", file=sys.stderr)
        return 2
    control = None if args.sim else socket_path(site.daemon.runtime_directory())
    if control is not None and not daemon_answers(control):
        control = None
    steering = _steering(args)
    if steering is not None:
        if control is None:
            where = socket_path(site.daemon.runtime_directory())
            print(f"reach-run: no daemon answers at {where}", file=sys.stderr)
            return 1
        with DaemonClient(control) as client:
            if steering == "attach":
                return remote.follow(client, args.attach or None)
            fields = {"job": args.cancel} if args.cancel else {}
            return request(client, steering, json_out=args.json, every=True, **fields)
    if args.schedule is None:
        print("reach-run: give a schedule (or --attach, --status, ...)", file=sys.stderr)
        return 2
    try:
        session = RunSession.prepare(
            args.schedule, site, site.clock(), args.out, report=not args.no_report
        )
    except ScheduleError as err:
        print(f"reach-run: {args.schedule} is not valid; nothing was run:", file=sys.stderr)
        print(str(err), file=sys.stderr)
        return 2
    except ReceiverError as err:
        print(f"reach-run: {err}", file=sys.stderr)
        return 2
    entries = session.timeline()
    total_s = max((e.start_s + e.duration_s for e in entries if e.depth == 0), default=0.0)
    steps = len(session.schedule.steps)
    if args.json:
        print(json.dumps(_timeline_json(args.schedule, total_s, entries), indent=1))
        return 0
    print(f"{args.schedule}: {steps} steps, estimated duration {hms(total_s)}", flush=True)
    if args.dry_run:
        print(format_timeline(entries))
        return 0
    if args.validate:
        return 0
    if control is not None:
        with DaemonClient(control) as client:
            return remote.submit(client, session.schedule, str(args.schedule), args.detach)
    with contextlib.ExitStack() as stack:
        if not args.sim:
            try:
                stack.enter_context(_owning_the_hardware(site))
            except HardwareBusy as err:
                print(f"reach-run: {err}", file=sys.stderr)
                return 1
        # First in, last out: signals stay handled until the simulator has stopped too.
        stack.enter_context(_stopping_on_signals(session))
        sim: SimulatedReceiver | None = None
        if args.sim:
            sim = stack.enter_context(SimulatedReceiver(settings))
            session.site, session.clock = sim.site(), sim.clock
        session.metadata = _metadata(args, session.site, sim)
        session.progress = stack.enter_context(_display(session.clock, args.quiet))
        try:
            summary = session.run()
        except RunFailed as err:
            print(f"reach-run: run {err.status}: {err}", file=sys.stderr)
            if err.run_file is not None:
                print(f"reach-run: measurements so far are in {err.run_file}", file=sys.stderr)
            return 1
        except (ReceiverError, OSError) as err:  # the run directory could not be made
            print(f"reach-run: the run did not start: {err}", file=sys.stderr)
            return 1
        # The same lines a followed job and run.log show (reach_receiver.run.summary).
        from reach_receiver.run.summary import report_line, summary_lines

        print("\n".join(summary_lines(summary, sim.physics if sim is not None else None)))
        if session.report and report_line(summary):
            print(report_line(summary))
    return 0


def _timeline_json(path: Path, total_s: float, entries: Sequence[object]) -> dict[str, object]:
    """A checked schedule for a program: its duration and every step's timing."""
    return {
        "schedule": str(path),
        "valid": True,
        "duration_s": total_s,
        "steps": [
            {k: str(v) if k == "where" else v for k, v in vars(e).items()} for e in entries
        ],
    }


def _steering(args: argparse.Namespace) -> str | None:
    """The daemon request asked for, if any."""
    if args.attach is not None:
        return "attach"
    for op in ("status", "queue", "abort", "resume"):
        if getattr(args, op):
            return op
    return "cancel" if args.cancel is not None else None


@contextlib.contextmanager
def _owning_the_hardware(site: SiteConfig) -> Iterator[None]:
    """The hardware lock the daemon takes too; a warning where it cannot be made."""
    from reach_receiver.daemon.lock import HardwareLock

    lock = HardwareLock(site.daemon.state_directory(), "reach-run")
    try:
        lock.acquire()
    except PermissionError as err:
        log.warning("no hardware lock (%s): make sure no daemon runs", err)
        yield
        return
    try:
        yield
    finally:
        lock.release()


def _metadata(
    args: argparse.Namespace, site: SiteConfig, sim: SimulatedReceiver | None
) -> dict[str, object]:
    return {
        "simulated": sim is not None or bool(site.simulation),
        "compression": args.compression if sim is not None else 1.0,
        "seed": args.seed if sim is not None else None,
        "site_file": site.source,
    }


@contextlib.contextmanager
def _display(clock: Clock, quiet: bool) -> Iterator[Progress]:
    from reach_receiver.run.context import NoProgress

    from .display import PlainProgress, RichProgressDisplay

    if quiet:
        yield NoProgress()
    elif sys.stderr.isatty():
        with RichProgressDisplay(clock) as display:
            yield display
    else:
        yield PlainProgress(clock)


@contextlib.contextmanager
def _stopping_on_signals(session: RunSession) -> Iterator[None]:
    """SIGINT, SIGTERM, SIGHUP stop the run cooperatively; a second one at once."""

    def on_signal(signum: int, frame: FrameType | None) -> None:
        del frame
        name = signal.Signals(signum).name
        if session.closing:  # the safe state and the run file come first
            log.warning("%s while the run is closing: ignored", name)
        elif session.token.requested:
            raise KeyboardInterrupt(f"second signal {name}")
        else:
            session.stop(f"signal {name}")

    previous = {s: signal.signal(s, on_signal) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for handled, handler in previous.items():
            signal.signal(handled, handler)
