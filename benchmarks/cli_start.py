"""How long each command takes to start: ``python -m benchmarks.cli_start``.

An operator over a satellite link types ``reach-run status`` and waits; every tenth of a
second before the command answers is the command's own. Each command below is run
``--runs`` times as a process of its own (the same entry points as the installed
scripts, through this Python), and its median wall time is printed against the 0.2 s
target and against ``python -c pass`` measured in the same run: the interpreter's own
start, which no command can beat, and which tells a loaded machine from a slow command.
``reach-run status`` is measured against a ``reachd --sim`` started for the purpose.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 0.2
ENTRY = "import sys; from {module} import {main}; sys.exit({main}(sys.argv[1:]))"
COMMANDS: list[tuple[str, str, str, list[str]]] = [
    ("reach-run --version", "reach_receiver.cli", "run_main", ["--version"]),
    ("reach-run --help", "reach_receiver.cli", "run_main", ["--help"]),
    ("reach-run status --help", "reach_receiver.cli", "run_main", ["status", "--help"]),
    ("reachd --help", "reach_receiver.cli", "reachd_main", ["--help"]),
    ("reachd --version", "reach_receiver.cli", "reachd_main", ["--version"]),
    ("reach-sim --help", "reach_receiver.cli", "sim_main", ["--help"]),
    ("reach-cal --help", "calibration.cli", "main", ["--help"]),
    ("reach-cal --version", "calibration.cli", "main", ["--version"]),
]


def median_s(argv: list[str], runs: int) -> float:
    """The median wall time of ``argv`` over ``runs`` runs (output discarded)."""
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def _reachd(root: Path) -> tuple[subprocess.Popen[bytes], Path]:
    site = root / "site.yaml"
    process = subprocess.Popen(
        [sys.executable, "-c", ENTRY.format(module="reach_receiver.cli", main="reachd_main"),
         "--sim", "--state-dir", str(root / "state"), "--runtime-dir", str(root / "run"),
         "--site-out", str(site)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 60
    while not (root / "run" / "control.sock").exists() or not site.exists():
        if process.poll() is not None or time.monotonic() > deadline:
            raise SystemExit("cli_start: reachd --sim did not start")
        time.sleep(0.1)
    return process, site


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.cli_start", description=__doc__)
    p.add_argument("--runs", type=int, default=7, help="runs of each command (default 7)")
    p.add_argument("--no-daemon", action="store_true", help="skip reach-run status")
    args = p.parse_args(argv)
    baseline = median_s([sys.executable, "-c", "pass"], args.runs)
    rows = [(name, median_s([sys.executable, "-c", ENTRY.format(module=m, main=f), *words],
                            args.runs)) for name, m, f, words in COMMANDS]
    if not args.no_daemon:
        with tempfile.TemporaryDirectory() as tmp:
            process, site = _reachd(Path(tmp))
            try:
                status = ENTRY.format(module="reach_receiver.cli", main="run_main")
                rows.append(("reach-run status", median_s(
                    [sys.executable, "-c", status, "status", "--site", str(site)], args.runs)))
            finally:
                process.terminate()
                process.wait(30)
    print(f"median wall time over {args.runs} runs; target {TARGET_S} s; "
          f"baseline python -c pass {baseline:.3f} s")
    print(f"{'command':<26} {'median s':>8} {'- baseline':>10}  target")
    for name, took in rows:
        verdict = "ok" if took <= TARGET_S else "OVER"
        print(f"{name:<26} {took:>8.3f} {took - baseline:>10.3f}  {verdict}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
