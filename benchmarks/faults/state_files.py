"""The daemon's own files damaged while it was down: its queue, its timers, its runs.

A disk fault, a hand edit or a half-copied state directory must not keep ``reachd``
from starting (under systemd that is a restart loop with the front-end never commanded
safe). Each trial damages one file in a fresh state directory, starts ``reachd --sim``
and asks it for its status over the control socket:

* ``clean``: it serves, and an alarm names the file (what could not be read is kept);
* ``silent``: it serves, with no word of the damage;
* ``crash``: it does not start, or prints a traceback;
* ``lost``: the damaged file is gone without a copy kept.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from reach_receiver.daemon.client import DaemonClient, daemon_answers

from .core import HANG_S, Trial

CLASS = "state files"

ENTRY = "import sys; from reach_receiver.cli import reachd_main; sys.exit(reachd_main())"

Damage = Callable[[Path], None]


def _write(name: str, data: bytes) -> Damage:
    def damage(state: Path) -> None:
        (state / name).write_bytes(data)

    return damage


def _broken_run(state: Path) -> None:
    """A run directory whose only part is not HDF5 (a run cut off in its first write)."""
    parts = state / "runs" / "20260101T000000Z-broken" / "parts"
    parts.mkdir(parents=True)
    (parts / "000000-run-description.h5").write_bytes(b"not hdf5")


CASES: dict[str, tuple[str, Damage]] = {
    "queue.json empty": ("queue file", _write("queue.json", b"")),
    "queue.json garbage": ("queue file", _write("queue.json", b"garbage{")),
    "queue.json wrong types": ("queue file", _write("queue.json", b'{"jobs": 3, "next_id": 1}')),
    "queue.json job fields": ("queue file",
                              _write("queue.json", b'{"jobs": [{"x": 1}], "next_id": 2}')),
    "queue.json binary": ("queue file", _write("queue.json", bytes(range(256)))),
    "timers.json garbage": ("timers file", _write("timers.json", b"[1, 2")),
    "timers.json wrong types": ("timers file",
                                _write("timers.json", b'{"fired": {"a": "x"}, "checked": 1}')),
    "a run that is not HDF5": ("recovery", _broken_run),
}
QUICK = ("timers.json wrong types", "a run that is not HDF5")


def _status(runtime: Path) -> dict[str, object] | None:
    deadline = time.monotonic() + HANG_S
    while time.monotonic() < deadline:
        if daemon_answers(runtime / "control.sock"):
            with DaemonClient(runtime / "control.sock") as client:
                return client.request("status")
        time.sleep(0.1)
    return None


def trial(workdir: Path, name: str) -> Trial:
    """Damage one file, start ``reachd --sim`` on it, judge what it says."""
    word, damage = CASES[name]
    state, runtime = workdir / "state", workdir / "run"
    state.mkdir(parents=True)
    damage(state)
    process = subprocess.Popen(
        [sys.executable, "-c", ENTRY, "--sim", "--state-dir", str(state),
         "--runtime-dir", str(runtime)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True,
    )
    try:
        status = _status(runtime) if process.poll() is None else None
    finally:
        process.send_signal(signal.SIGTERM)
        try:
            _, err = process.communicate(timeout=HANG_S)
        except subprocess.TimeoutExpired:
            process.kill()
            _, err = process.communicate()
    if status is None or "Traceback (most recent call last)" in err:
        last = err.strip().splitlines()[-1:] or ["no answer"]
        return Trial(name, "crash", last[0][:200])
    alarms = [str(a) for a in list(status.get("alarms") or [])]  # type: ignore[call-overload]
    named = [a for a in alarms if "unreadable" in a or "could not merge" in a]
    kept = list(state.rglob("*.unreadable-*")) or list((state / "runs").rglob("*.h5"))
    if not kept:
        return Trial(name, "lost", "the damaged file is gone")
    if not named:
        return Trial(name, "silent", f"serves, alarms {alarms}")
    return Trial(name, "clean", f"{word}: {named[0][:160]}")


def trials(workdir: Path, quick: bool) -> Iterator[Trial]:
    """Each damaged file (the quick set: one of each kind)."""
    for index, name in enumerate(QUICK if quick else tuple(CASES)):
        yield trial(workdir / f"case-{index}", name)
