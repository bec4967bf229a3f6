"""Signals at any moment: SIGINT, SIGTERM and SIGHUP to ``reach-run`` and ``reachd``.

Each trial starts the real command (``reach-run --sim`` on a short schedule, ``reachd
--sim``), sends one signal at a chosen moment from its start (while it imports, while
the simulator starts, during the run) and judges how it ended:

* ``crash``: a traceback, an internal error, or no end within the hang limit;
* ``lost``: a run directory left with part files and no merged ``run.h5``;
* ``clean``: anything else: a signal is the operator's word, so any exit (0, 1, 130,
  or death by the signal before Python handles it) is an answer.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from reach_receiver.store.parts import list_parts

from .core import HANG_S, Trial

CLASS = "signals"

SCHEDULE = """\
schedule: signalled
steps:
  - initialise: {}
  - dicke: {sources: [cold, hot], seconds: 600}
  - safe
"""
#: Moments (s from the start) to signal, quick and full. Before ~0.1 s the interpreter is
#: still starting (its site-packages' ``.pth`` files): a SIGINT there is Python's own
#: KeyboardInterrupt, before any program can handle it; the full set shows that window.
QUICK_AT = (0.5, 1.5, 3.0)
FULL_AT = (0.0, 0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0)
SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _command(program: str, *args: str) -> list[str]:
    """What the console script does: import the entry point, call it."""
    entry = f"import sys; from reach_receiver.cli import {program}; sys.exit({program}())"
    return [sys.executable, "-c", entry, *args]


def _signalled(argv: list[str], cwd: Path, at_s: float, signum: int) -> tuple[int | None, str]:
    """The exit code and output; ``None`` and the threads' stacks where it did not end.

    The child runs with Python's fault handler on, so that a hung one, sent SIGABRT,
    prints where each of its threads was (the detail a hang in CI needs).
    """
    env = {**os.environ, "PYTHONFAULTHANDLER": "1"}
    process = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               stdin=subprocess.DEVNULL, text=True, env=env)
    time.sleep(at_s)
    if process.poll() is None:
        process.send_signal(signum)
    try:
        out, err = process.communicate(timeout=HANG_S)
    except subprocess.TimeoutExpired:
        process.send_signal(signal.SIGABRT)
        try:
            out, err = process.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            out, err = process.communicate()
        return None, err
    return process.returncode, out + err


def _stuck_at(dump: str) -> str:
    """Each thread of a fault-handler dump: its innermost frame and its innermost of ours."""
    threads: list[str] = []
    for block in dump.split("\n\n"):
        lines = [line.strip().replace("File ", "") for line in block.splitlines()]
        if not lines or not lines[0].startswith(("Thread 0x", "Current thread 0x")):
            continue
        frames = lines[1:]
        ours = [f for f in frames if _reached_our_code(f)]
        threads.append(" < ".join(dict.fromkeys(frames[:1] + ours[:1])))
    return "; ".join(reversed(threads))[:800] or dump.strip()[-300:]


def _judge(name: str, code: int | None, text: str, runs: Path) -> Trial:
    if code is None:
        return Trial(name, "crash",
                     f"no end within {HANG_S:g} s after the signal; threads at: {_stuck_at(text)}")
    if "Traceback (most recent call last)" in text or "internal error" in text:
        last = [line for line in text.strip().splitlines() if line.strip()][-1:]
        where = "" if _reached_our_code(text) else " (in Python's own start-up, before main)"
        return Trial(name, "crash", (last or [""])[0][:160] + where)
    open_runs = [d for d in runs.glob("*") if d.is_dir() and list_parts(d)
                 and not (d / "run.h5").exists()] if runs.is_dir() else []
    if open_runs:
        return Trial(name, "lost", f"{open_runs[0].name}: parts left unmerged")
    lines = text.strip().splitlines()
    return Trial(name, "clean", f"exit {code}: {lines[-1][:160] if lines else ''}")


def _reached_our_code(traceback: str) -> bool:
    """Whether a traceback holds a frame of the program (not only the interpreter's start)."""
    return any(f"/{package}/" in traceback for package in ("reach_receiver", "calibration"))


def trials(workdir: Path, quick: bool) -> Iterator[Trial]:
    """Each signal at each moment, to ``reach-run --sim`` and to ``reachd --sim``."""
    schedule = workdir / "signalled.yaml"
    schedule.write_text(SCHEDULE)
    moments = QUICK_AT if quick else FULL_AT
    for index, at_s in enumerate(moments):
        for signum in SIGNALS if not quick else (SIGNALS[index % len(SIGNALS)],):
            name = signal.Signals(signum).name
            here = workdir / f"run-{index}-{name}"
            here.mkdir()
            code, text = _signalled(
                _command("run_main", "--sim", "--out", str(here / "runs"), str(schedule)),
                here, at_s, signum,
            )
            yield _judge(f"reach-run {name} at {at_s:g} s", code, text, here / "runs")
            there = workdir / f"daemon-{index}-{name}"
            there.mkdir()
            code, text = _signalled(
                _command("reachd_main", "--sim", "--state-dir", str(there / "state"),
                         "--runtime-dir", str(there / "run")),
                there, at_s, signum,
            )
            yield _judge(f"reachd {name} at {at_s:g} s", code, text, there / "state" / "runs")
