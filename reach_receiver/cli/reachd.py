"""``reachd``: the receiver daemon in the foreground (systemd ``Type=notify``), or its checks.

::

    reachd --site /etc/reach/site.yaml        # the service (deploy/reachd.service)
    reachd --check --site /etc/reach/site.yaml
    reachd --sim --state-dir DIR --runtime-dir DIR --site-out sim-site.yaml

With ``--sim`` it owns a simulated receiver in the same process (the devices of the
simulator, the rest of ``--site`` when given: timers, policies); ``--site-out`` writes a
site file through which ``reach-run`` finds the daemon and submits to it. SIGTERM,
SIGHUP and SIGINT stop it: the current run stops cooperatively (the front-end safe, the
run file closed with the reason), then the daemon exits 0.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING

from reach_receiver.errors import ReceiverError

from .logs import add_version, configure_logging

# The site file's modules, the lock and the Teensy's driver are imported once the
# arguments are read (``reachd --help`` answers without them); the run layer and the
# engine only after the front-end is safe (:func:`_serve`).
if TYPE_CHECKING:
    from reach_receiver.clock import Clock
    from reach_receiver.config.site import SiteConfig
    from reach_receiver.run.summary import Truth

log = logging.getLogger("reach_receiver.daemon")

STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP, signal.SIGINT)


def _stopped_while_starting() -> int | None:
    """The exit status (128 + signal) if a stop signal came before the daemon's handlers.

    :data:`reach_receiver.cli.EARLY_STOPS` keeps them; each step of the start looks here,
    so that a signal is answered at the next step instead of lost.
    """
    from . import EARLY_STOPS

    if not EARLY_STOPS:
        return None
    signum = EARLY_STOPS[0]
    print(f"reachd: stopped by {signal.Signals(signum).name} while starting", file=sys.stderr)
    return 128 + signum


def parser() -> argparse.ArgumentParser:
    """The command line of ``reachd``."""
    p = argparse.ArgumentParser(
        prog="reachd",
        description="The REACH receiver daemon: runs schedules from its queue and timers, "
        "answers its control socket, recovers from crashes.",
    )
    p.add_argument("--site", type=Path, help="site file ($REACH_SITE, /etc/reach/site.yaml)")
    p.add_argument("--sim", action="store_true", help="own a simulated receiver (dry runs)")
    p.add_argument("--check", action="store_true", help="check the installation and exit")
    p.add_argument("--runtime-dir", type=Path, help="control socket (default: the site's)")
    p.add_argument("--state-dir", type=Path, help="queue, lock and runs (default: the site's)")
    p.add_argument("--site-out", type=Path, help="--sim: write the site file clients use here")
    p.add_argument("--compression", type=float, default=None,
                   help="--sim: simulated seconds per real second (the simulator's default)")
    p.add_argument("--seed", type=int, default=0, help="--sim: seed of the simulation")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="log more: INFO on a terminal (default WARNING), DEBUG under the "
                   "journal (default INFO: every read request too)")
    add_version(p)
    return p


def reachd_main(argv: Sequence[str] | None = None) -> int:
    """``reachd``: exit 0 after a clean stop, 1 when it cannot start, 2 for bad input."""
    args = parser().parse_args(argv)
    configure_logging(args.verbose)
    if (stopped := _stopped_while_starting()) is not None:
        return stopped
    problem = _site_out_problem(args.site_out) if args.sim else None
    if problem:
        print(f"reachd: --site-out {args.site_out}: {problem}", file=sys.stderr)
        return 2
    from reach_receiver.config.site import find_site, load_site

    try:
        base = load_site(find_site(args.site)) if (args.site or not args.sim) else None
    except ReceiverError as err:
        print(f"reachd: {err}", file=sys.stderr)
        return 2
    if args.check:
        if base is None:
            print("reachd: --check needs a site file", file=sys.stderr)
            return 2
        return _check(base, args)
    if args.sim:
        return _serve_sim(base, args)
    assert base is not None
    return _serve(_with_dirs(base, args), base.clock(), args)


def _with_dirs(site: SiteConfig, args: argparse.Namespace) -> SiteConfig:
    daemon = site.daemon
    if args.runtime_dir is not None:
        daemon = dataclasses.replace(daemon, runtime_dir=args.runtime_dir.resolve())
    if args.state_dir is not None:
        daemon = dataclasses.replace(daemon, state_dir=args.state_dir.resolve())
    return dataclasses.replace(site, daemon=daemon)


def _with_sim(base: SiteConfig | None, sim: SiteConfig, args: argparse.Namespace) -> SiteConfig:
    """The simulator's devices; the rest (timers, policies, tables) from ``--site``."""
    from reach_receiver.config.daemon import DaemonSettings

    site = sim if base is None else dataclasses.replace(
        base, devices=sim.devices, references=sim.references, simulation=sim.simulation,
        longitude_deg=sim.longitude_deg, latitude_deg=sim.latitude_deg, source=base.source,
    )
    if base is None:
        site = dataclasses.replace(site, daemon=DaemonSettings())
    return _with_dirs(site, args)


def _site_out_problem(path: Path | None) -> str | None:
    """Why ``--site-out`` cannot be written, checked before the simulator starts."""
    if path is None:
        return None
    if path.is_dir():
        return "is a directory"
    if not path.parent.is_dir():
        return f"no directory {path.parent}"
    if not os.access(path.parent, os.W_OK | os.X_OK):
        return f"the directory {path.parent} is not writable"
    return None


def _write(path: Path, text: str) -> None:
    partial = path.with_name(path.name + ".partial")
    partial.write_text(text)
    os.replace(partial, path)


def _serve_sim(base: SiteConfig | None, args: argparse.Namespace) -> int:
    """The daemon over a simulated receiver started in this process."""
    from reach_receiver.sim.receiver import (
        DEFAULT_COMPRESSION,
        SimulatedReceiver,
        SimulationSettings,
        spectrum_period_for,
    )

    compression = DEFAULT_COMPRESSION if args.compression is None else args.compression
    settings = SimulationSettings(
        compression=compression,
        spectrum_period_s=spectrum_period_for(compression),
        seed=args.seed,
    )
    with SimulatedReceiver(settings) as sim:
        if (stopped := _stopped_while_starting()) is not None:
            return stopped
        site = _with_sim(base, sim.site(), args)
        if args.site_out is not None:
            _write(args.site_out, site.to_yaml())
        return _serve(site, sim.clock, args, truth=sim.physics)


def _serve(
    site: SiteConfig, clock: Clock, args: argparse.Namespace, truth: Truth | None = None
) -> int:
    """Lock, safe state, then the daemon; exit 0 after a clean stop, 1 if it cannot start.

    The lock comes first, so that a second ``reachd`` on the same directories is refused
    before it touches anything of the first (its socket, its queue, the front-end); the
    safe state second, through the Teensy alone, before the rest of the daemon (the run
    layer, the engine, astropy) is even imported: a front-end a crash left powered is
    safe within a second of the restart.
    """
    from reach_receiver.daemon.lock import HardwareBusy, HardwareLock

    dirs_state = site.daemon.state_directory()
    lock = HardwareLock(dirs_state, f"reachd ({site.source})")
    try:
        lock.acquire()
    except (HardwareBusy, OSError) as err:
        print(f"reachd: cannot start: {err}", file=sys.stderr)
        return 1
    made_safe = _safe_first(site)
    if (stopped := _stopped_while_starting()) is not None:
        lock.release()
        return stopped

    from reach_receiver.daemon.service import Daemon, Directories

    dirs = Directories(site.daemon.runtime_directory(), dirs_state)
    daemon = Daemon(site, clock, dirs, lock=lock, truth=truth)

    def on_signal(signum: int, frame: FrameType | None) -> None:
        del frame
        daemon.halt(f"signal {signal.Signals(signum).name}")

    for handled in STOP_SIGNALS:
        signal.signal(handled, on_signal)
    from . import EARLY_STOPS

    if EARLY_STOPS:  # after the last look, before these handlers: the loop stops at once
        daemon.halt(f"signal {signal.Signals(EARLY_STOPS[0]).name} while starting")
    try:
        daemon.start(made_safe)
    except (ReceiverError, OSError) as err:
        print(f"reachd: cannot start: {err}", file=sys.stderr)
        daemon.close()
        return 1
    if daemon.page is not None:
        print(f"reachd: status page {daemon.page.url}", flush=True)
    print(f"reachd: serving {dirs.runtime / 'control.sock'} ({daemon.machine.state})", flush=True)
    try:
        clean = daemon.serve()
    finally:
        daemon.close()
    if not clean:
        print("reachd: stopped by an internal error (the journal has its traceback); "
              "the front-end was commanded safe", file=sys.stderr)
        return 1
    return 0


def _safe_first(site: SiteConfig) -> str:
    """Command the safe state through the Teensy alone; ``""`` or what went wrong."""
    from reach_receiver.devices.teensy import Teensy

    teensy = site.devices.teensy
    try:
        state = Teensy.command_safe(teensy.port, teensy.timeout_s)
    except (ReceiverError, OSError) as err:
        log.error("front-end: cannot command the safe state at start: %s", err)
        return str(err) or type(err).__name__
    log.info("front-end safe: %s (%.2f s after reachd started)",
             state.describe(), seconds_since_start())
    return ""


def seconds_since_start() -> float:
    """Seconds since this process started (its start time in ``/proc/self/stat``)."""
    try:
        stat = Path("/proc/self/stat").read_text()
        ticks = int(stat.rsplit(")", 1)[1].split()[19])  # field 22, starttime
        uptime = float(Path("/proc/uptime").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return float("nan")
    return uptime - ticks / os.sysconf("SC_CLK_TCK")


def _check(site: SiteConfig, args: argparse.Namespace) -> int:
    """The installation's checks; the devices only when no daemon owns them."""
    from reach_receiver.clock import SystemClock
    from reach_receiver.daemon.doctor import run_checks
    from reach_receiver.daemon.doctor.clock import check_clock
    from reach_receiver.daemon.doctor.disk import (
        DEFAULT_MIN_FREE_BYTES,
        check_disk,
        run_bytes_per_hour,
    )
    from reach_receiver.daemon.doctor.outcome import Check, failed, format_checks
    from reach_receiver.daemon.doctor.paths import check_directory, device_path_checks
    from reach_receiver.daemon.lock import HardwareBusy, HardwareLock

    site = _with_dirs(site, args)
    state, runtime = site.daemon.state_directory(), site.daemon.runtime_directory()
    lock = HardwareLock(state, "reachd --check")
    try:
        lock.acquire()
    except (HardwareBusy, OSError) as err:
        checks = [Check("devices", "warn", f"not probed: {err}")]
        checks += device_path_checks(site)
        checks.append(check_clock())
        data = state / "runs"
        checks.append(check_disk(data, DEFAULT_MIN_FREE_BYTES, run_bytes_per_hour(site)))
        checks.append(check_directory("data dir", data, private=True))
        checks.append(check_directory("runtime dir", runtime, private=False))
    else:
        try:
            checks = run_checks(site, clock=SystemClock(), data_dir=state / "runs",
                                runtime_dir=runtime)
        finally:
            lock.release()
    print(format_checks(checks))
    return 1 if failed(checks) else 0
