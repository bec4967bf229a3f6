"""``reach-run``: check a schedule before anything moves, then run it and summarise.

1. The schedule is compiled against the site file (or, with ``--sim``, the simulated
   receiver's) and every mistake is printed with its file, line and key: exit 2, and no
   device has been contacted. The estimated duration is printed.
2. ``--validate`` stops there; ``--dry-run`` prints the step list with its timing.
3. Otherwise the instruments connect and the runner executes the steps, printing
   progress. Ctrl-C, SIGTERM or any device fault put the front-end into its safe state,
   close the run file and exit 1 with the reason.
4. A completed run prints its checks, the solution (orders, noise scale, distance to
   the noise floor) and, in ``--sim``, the actual calibration error against the
   simulator's truth.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import time
from collections.abc import Iterator
from datetime import datetime, timezone
from importlib import metadata
from types import FrameType

from reach_receiver.clock import Clock, CompressedClock, SystemClock
from reach_receiver.errors import ReceiverError
from reach_receiver.instruments import Instruments
from reach_receiver.schedule import steps as st
from reach_receiver.schedule.actions import Actions
from reach_receiver.schedule.compile import ScheduleError, compile_schedule
from reach_receiver.schedule.runner import RunFailed, RunInterrupted, Runner, RunSummary, describe
from reach_receiver.schedule.timing import format_timeline, timeline
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings
from reach_receiver.site import SiteConfig, load_site
from reach_receiver.store.run_store import RunStore

#: Where the simulated receiver is said to be (REACH's site in the Karoo).
SIM_SITE = SiteConfig(name="simulated receiver", longitude_deg=21.52, latitude_deg=-30.97)


class ProgressPrinter:
    """One line per top-level step on standard error: position, time left, where."""

    def __init__(self, clock: Clock, quiet: bool = False) -> None:
        self.clock = clock
        self.quiet = quiet
        self.start = clock.now()
        self.real_start = time.monotonic()

    def step(self, index: int, total: int, step: st.Step, left_s: float | None) -> None:
        """Print the step about to run."""
        if self.quiet:
            return
        elapsed = _hms(self.clock.now() - self.start)
        left = f", about {_hms(left_s)} left" if left_s is not None else ""
        real = time.monotonic() - self.real_start
        print(
            f"[{index:>3}/{total}] {elapsed} elapsed{left} ({real:.1f} s real) | "
            f"{describe(step)}  ({step.where})",
            file=sys.stderr,
            flush=True,
        )


def _hms(seconds: float) -> str:
    seconds = max(0.0, seconds)
    return f"{int(seconds // 3600)}:{int(seconds % 3600 // 60):02d}:{int(seconds % 60):02d}"


@contextlib.contextmanager
def _interruptible() -> Iterator[None]:
    """SIGTERM raises :class:`RunInterrupted` in the main thread, as Ctrl-C does."""

    def on_term(signum: int, frame: FrameType | None) -> None:
        del frame
        raise RunInterrupted(f"signal {signal.Signals(signum).name}")

    previous = signal.signal(signal.SIGTERM, on_term)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def run_command(args: argparse.Namespace) -> int:
    """The body of ``reach-run`` (see the module docstring)."""
    try:
        site = SIM_SITE if args.sim or args.site is None else load_site(args.site)
        schedule = compile_schedule(args.schedule, site=site)
    except ScheduleError as err:
        print(f"reach-run: {args.schedule} is not valid; nothing was run:", file=sys.stderr)
        print(str(err), file=sys.stderr)
        return 2
    except ReceiverError as err:
        print(f"reach-run: {err}", file=sys.stderr)
        return 2
    now = datetime.now(tz=timezone.utc)
    entries = timeline(schedule, start_utc=now, longitude_deg=site.longitude_deg)
    total_s = max((e.start_s + e.duration_s for e in entries), default=0.0)
    print(f"{args.schedule}: {len(schedule.steps)} steps, estimated duration {_hms(total_s)}")
    if args.dry_run:
        print(format_timeline(entries))
        return 0
    if args.validate:
        return 0
    if not args.sim and args.site is None:
        print("reach-run: give --site <file> for the instrument, or --sim", file=sys.stderr)
        return 2
    top = [e for e in entries if e.depth == 0]

    def remaining(index: int) -> float | None:
        return total_s - top[index].start_s if index < len(top) else None

    with contextlib.ExitStack() as stack:
        sim: SimulatedReceiver | None = None
        clock: Clock = SystemClock()
        if site.simulation:  # a reach-sim in another process: share its simulated time
            clock = CompressedClock(
                site.simulation["compression"],
                site.simulation["start"],
                site.simulation["monotonic_origin"],
            )
        if args.sim:
            settings = SimulationSettings(compression=args.compression, seed=args.seed)
            sim = stack.enter_context(SimulatedReceiver(settings))
            site, clock = sim.site(), sim.clock
        summary = _execute(args, schedule, site, clock, sim, remaining)
    if summary is None:
        return 1
    _print_summary(summary)
    return 0


def _execute(
    args: argparse.Namespace,
    schedule: st.Schedule,
    site: SiteConfig,
    clock: Clock,
    sim: SimulatedReceiver | None,
    remaining: object,
) -> RunSummary | None:
    stamp = datetime.now(tz=timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    directory = args.out / f"{stamp}-{schedule.name}"
    suffix = 1
    while directory.exists():  # two runs started within one second
        suffix += 1
        directory = args.out / f"{stamp}-{schedule.name}-{suffix}"
    store = RunStore(
        directory,
        name=schedule.name,
        schedule_files=schedule.files,
        site_yaml=site.to_yaml(),
        metadata={
            "simulated": sim is not None or bool(site.simulation),
            "compression": args.compression if sim is not None else 1.0,
            "reach_receiver": metadata.version("reach-receiver"),
            "started_utc": stamp,
        },
        channel_width_hz=400e6 / 32768,
    )
    store.open()
    actions = Actions(
        Instruments.from_site(site, clock),
        store,
        truth=sim.physics.effective_theta if sim is not None else None,
        spectrum_period_s=sim.settings.spectrum_period_s if sim is not None else 1.0,
    )
    runner = Runner(
        schedule,
        actions,
        ProgressPrinter(clock, quiet=args.quiet),
        remaining,  # type: ignore[arg-type]
    )
    print(f"run directory: {directory}")
    try:
        with _interruptible():
            return runner.run()
    except RunFailed as err:
        print(f"reach-run: run {err.status}: {err}", file=sys.stderr)
        if err.run_file is not None:
            print(f"reach-run: measurements so far are in {err.run_file}", file=sys.stderr)
        return None


def _print_summary(summary: RunSummary) -> None:
    print(f"run file: {summary.run_file}")
    print(f"simulated/real time of the run: {_hms(summary.elapsed_s)}")
    for check in summary.checks:
        print(f"check {check.name}: {'PASS' if check.passed else 'FAIL'} ({check.detail})")
    solution = summary.results.get("solution")
    if isinstance(solution, dict):
        print(f"solution: orders {solution['orders']} (T_unc, T_cos, T_sin, T_NS, T_L)")
        print(f"  noise scale s^2 {solution['noise_scale']:.3f} (1 = radiometer equation)")
        floor, predicted = solution["floor_k"], solution["predicted_k"]
        print(
            f"  on {solution['validation']!r}: noise floor {1e3 * floor:.3f} mK, predicted "
            f"calibration std {1e3 * predicted:.3f} mK, distance to floor "
            f"{predicted / floor:.3f}"
        )
        if "actual_k" in solution:
            actual = solution["actual_k"]
            print(
                f"  actual calibration error against the simulator's truth: "
                f"{1e3 * actual:.3f} mK = {actual / floor:.3f} x floor"
            )
