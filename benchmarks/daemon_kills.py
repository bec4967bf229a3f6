"""SIGKILL ``reachd`` at points spread over a ``calibrate.yaml`` run; check what restarts find.

Usage::

    python -m benchmarks.daemon_kills [--points 20] [--compression 3000]

The simulated receiver runs in its own process (``reach-sim``), as the hardware does, so
it outlives the daemon. For each point a fresh daemon (``resume: true``) is given
``schedules/calibrate.yaml`` and SIGKILLed at that moment of the run; a new ``reachd``
is started on the same directories and left until its queue is empty. Then:

* every run directory is merged (a ``run.h5``, no part files left);
* every job's state is its run file's status (``completed`` for a completed run);
* the last job completed (the schedule was carried to its end), and the daemon is idle;
* the time from the restarted ``reachd``'s start to its safe command is read from its
  log line ``front-end safe: ... (N s after reachd started)``.

The points: the first at 0.5 s, the rest spread evenly up to the run's length (measured
by an unkilled run first), and one taken at the moment the run's final ``run.h5``
appears, before the daemon has recorded the job's end (the window of a kill after the
merge). Prints one line a point and a summary; exit 1 if any check failed.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from reach_receiver.daemon.client import DaemonClient, daemon_answers
from reach_receiver.store import read_run_file
from reach_receiver.store.parts import list_parts

SCHEDULE = Path(__file__).resolve().parent.parent / "schedules" / "calibrate.yaml"
ENTRY = "import sys; from reach_receiver.cli import {main}; sys.exit({main}())"
SAFE_LINE = re.compile(r"front-end safe: .*\(([0-9.]+) s after reachd started\)")


def _python(main: str, *args: str, log: Path | None = None) -> subprocess.Popen[bytes]:
    out = open(log, "ab") if log is not None else subprocess.DEVNULL  # noqa: SIM115
    return subprocess.Popen([sys.executable, "-c", ENTRY.format(main=main), *args],
                            stdout=out, stderr=out, stdin=subprocess.DEVNULL)


def _wait(predicate: Any, timeout_s: float, what: str) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = predicate()
        if found:
            return found
        time.sleep(0.01)
    raise TimeoutError(f"timed out waiting for {what}")


def _start_reachd(site: Path, runtime: Path, log: Path) -> subprocess.Popen[bytes]:
    process = _python("reachd_main", "--site", str(site), "-v", log=log)
    _wait(lambda: process.poll() is not None or daemon_answers(runtime / "control.sock"),
          120, "reachd to answer")
    if process.poll() is not None:
        raise RuntimeError(f"reachd exited {process.returncode}: see {log}")
    return process


def _request(runtime: Path, op: str, **fields: Any) -> dict[str, Any]:
    with DaemonClient(runtime / "control.sock") as client:
        return client.request(op, **fields)


def _submit(runtime: Path) -> None:
    files = {str(p): p.read_text() for p in SCHEDULE.parent.glob("*.yaml")}
    _request(runtime, "submit", schedule=str(SCHEDULE), files=files)


def _queue_file_jobs(state: Path) -> list[dict[str, Any]]:
    return list(json.loads((state / "queue.json").read_text())["jobs"])


def one_point(sim_site: dict[str, Any], root: Path, kill_at: float | None) -> dict[str, Any]:
    """One kill (``None``: at the final merge; a negative time: no kill) and the checks."""
    root.mkdir(parents=True)
    state, runtime = root / "state", root / "run"
    site = root / "site.yaml"
    site.write_text(yaml.safe_dump({**sim_site, "daemon": {
        "state_dir": str(state), "runtime_dir": str(runtime), "resume": True}}))
    log = root / "reachd.log"
    reachd = _start_reachd(site, runtime, log)
    started = time.monotonic()
    _submit(runtime)
    runs = state / "runs"
    killed_running = False
    if kill_at is None or kill_at >= 0:
        if kill_at is None:  # the moment the final run.h5 appears
            _wait(lambda: any((d / "run.h5").exists() for d in runs.glob("*")), 600, "run.h5")
        else:
            time.sleep(kill_at)
        os.kill(reachd.pid, signal.SIGKILL)
        reachd.wait()
        killed_running = any(j["state"] == "running" for j in _queue_file_jobs(state))
        reachd = _start_reachd(site, runtime, log)
    idle = _wait(lambda: (s := _request(runtime, "status"))["state"] == "idle"
                 and not s["queue"] and s["job"] is None and s, 900, "an idle daemon")
    length = time.monotonic() - started
    jobs = _request(runtime, "queue")["jobs"]
    reachd.send_signal(signal.SIGTERM)
    reachd.wait(timeout=60)
    problems = []
    for directory in sorted(p for p in runs.glob("*") if p.is_dir()):
        if list_parts(directory):  # (a directory killed before its first part holds none)
            problems.append(f"{directory.name}: not merged")
    for job in jobs:
        if job["run"] and (Path(job["run"]) / "run.h5").exists():
            status = read_run_file(Path(job["run"]) / "run.h5").status
            if status != job["state"]:
                problems.append(f"job {job['id']} {job['state']} but its run {status}")
    last = max(jobs, key=lambda j: int(j["id"]), default=None)
    if last is None or last["state"] != "completed":
        problems.append(f"last job {last['state'] if last else 'missing'}")
    if idle["state"] != "idle":
        problems.append(f"daemon {idle['state']}")
    safe_s = [float(m.group(1)) for m in SAFE_LINE.finditer(log.read_text(errors="replace"))]
    return {"problems": problems, "jobs": len(jobs), "length_s": length,
            "safe_s": safe_s[-1] if safe_s else float("nan"), "killed_running": killed_running}


def main(argv: list[str] | None = None) -> int:
    """Run the points; print each and the summary."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.daemon_kills", description=__doc__)
    p.add_argument("--points", type=int, default=20, help="kill points (default 20)")
    p.add_argument("--compression", type=float, default=3000.0)
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="daemon-kills-") as work:
        work_dir = Path(work)
        sim_file = work_dir / "sim.yaml"
        sim = _python("sim_main", "--site-out", str(sim_file), "--compression",
                      str(args.compression), log=work_dir / "sim.log")
        try:
            _wait(sim_file.exists, 120, "reach-sim")
            sim_site = yaml.safe_load(sim_file.read_text())
            baseline = one_point(sim_site, work_dir / "baseline", -1.0)
            length = baseline["length_s"]
            print(f"unkilled run: {length:.1f} s, problems {baseline['problems'] or 'none'}")
            points: list[float | None] = [None, 0.5]
            points += list(np.linspace(0.5, length, args.points - 1)[1:])
            results = []
            for index, at in enumerate(points):
                result = one_point(sim_site, work_dir / f"point-{index}", at)
                results.append(result)
                when = "at the final merge" if at is None else f"at {at:5.1f} s"
                print(f"kill {when}: {result['jobs']} jobs, safe {result['safe_s']:.2f} s "
                      f"after start, job running at the kill: {result['killed_running']}, "
                      f"{'; '.join(result['problems']) or 'all checks pass'}", flush=True)
        finally:
            sim.send_signal(signal.SIGTERM)
            sim.wait(timeout=60)
    safe = np.array([r["safe_s"] for r in results])
    failed = sum(bool(r["problems"]) for r in results)
    print(f"{len(results)} kills: {len(results) - failed} with every check passed; "
          f"start to safe command median {np.nanmedian(safe):.2f} s, "
          f"max {np.nanmax(safe):.2f} s (target < 1 s)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
