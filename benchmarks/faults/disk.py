"""A full disk: ``reach-run --sim`` on small disks, a file-size limit, reachd's state full.

Each trial runs in a mount namespace of its own (``unshare -m`` as root, else
``unshare --user --map-root-user --mount``) with a tmpfs of the size tried mounted
there, so nothing stays mounted whatever happens; "space returns" is the tmpfs
remounted larger inside the same namespace. Where no namespace can be had, the
file-size limit (``RLIMIT_FSIZE``, which needs no privilege) stands in for the full
disk. A trial is judged:

* ``crash``: a traceback, a death by a signal, a hang, or the daemon gone;
* ``lost``: a measurement that was stored (a part file, or in ``run.h5``) is not in
  the run once there is room again and it is merged, or cannot be read;
* ``silent``: the run failed without naming the disk (or the file-size limit);
* ``clean``: the error names the full disk and everything stored is still readable.
"""

from __future__ import annotations

import contextlib
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from functools import cache
from pathlib import Path
from typing import Any

from .core import Answer, Trial, judge_refusal, run_command

CLASS = "disk"
ROOT = Path(__file__).resolve().parents[2]
#: Words a refusal must hold: the full disk, or the file-size limit, named.
NAMED = ("no space left on device", "file-size limit")

#: Four calibrators, their Dicke cycles ~0.8 MB each: about 3.3 MB of parts, as much
#: again for the merged run file.
SCHEDULE = """\
schedule: diskfill
steps:
  - initialise: {rails: [12v, 24v, 6v, fan]}
  - s11: {targets: [hot, cold, lna]}
  - dicke: {sources: [cold, hot, r25, r100], seconds: 60}
  - safe
"""
#: tmpfs sizes: too small for the description, full at the first Dicke cycle, at a later
#: one, at the merge, and room for all.
SIZES = ("64k", "1m", "2m", "6m", "16m")
QUICK_SIZES = ("2m",)
#: File-size limits (kB): one Dicke cycle does not fit, the merged run does not.
FSIZE_KB = (500, 2000)


# ------------------------------------------------------------------ namespaces
@cache
def confinement() -> list[str] | None:
    """The command prefix that gives a mount namespace with tmpfs, ``None`` if none does."""
    prefixes = [["unshare", "-m"]] if os.geteuid() == 0 else []
    prefixes.append(["unshare", "--user", "--map-root-user", "--mount"])
    probe = "d=$(mktemp -d) && mount -t tmpfs -o size=64k tmpfs $d && umount $d; rmdir $d"
    for prefix in prefixes:
        if shutil.which(prefix[0]) is None:
            continue
        try:
            done = subprocess.run([*prefix, "sh", "-c", probe], capture_output=True, timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            continue
        if done.returncode == 0:
            return prefix
    return None


def run_scenario(prefix: list[str], scenario: str, *args: str) -> dict[str, Any]:
    """The JSON ``scenario(*args)`` of this module prints, run in a child process.

    ``prefix`` is the command that gives the child its mount namespace (or ``[]``).
    """
    code = f"from benchmarks.faults import disk; disk.{scenario}(*{list(args)!r})"
    done = run_command([*prefix, sys.executable, "-c", code], cwd=ROOT, timeout_s=240,
                       env={"PYTHONPATH": str(ROOT)})
    lines = done.stdout.strip().splitlines()
    if done.code != 0 or not lines:
        return {"error": f"exit {done.code}: {(done.stderr.strip().splitlines() or [''])[-1]}"}
    answer: dict[str, Any] = json.loads(lines[-1])
    return answer


def _mount(directory: Path, size: str) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(directory)],
                   check=True)


def _grow(directory: Path) -> None:
    subprocess.run(["mount", "-o", "remount,size=256m", str(directory)], check=True)


# ------------------------------------------------------------------ what was stored
def stored(runs: Path) -> dict[str, list[int]]:
    """Each run directory's stored measurements by number: in its parts and its ``run.h5``.

    The run's description and its status records are not measurements: the merge folds
    them into the file's ``/run`` group and root attributes.
    """
    from reach_receiver.store import RUN_FILE
    from reach_receiver.store.merge import records_in_file
    from reach_receiver.store.parts import list_parts

    found: dict[str, list[int]] = {}
    for directory in sorted(p for p in runs.iterdir() if p.is_dir()) if runs.is_dir() else []:
        records = [(p.sequence, p.kind) for p in list_parts(directory)]
        if (directory / RUN_FILE).is_file():
            records += [(r.sequence, r.kind) for r in records_in_file(directory / RUN_FILE)]
        found[directory.name] = sorted({n for n, kind in records if kind not in ("run", "status")})
    return found


def readable(runs: Path, before: dict[str, list[int]]) -> str:
    """Merge every run under ``runs`` and read it back: ``""`` or what is missing."""
    from reach_receiver.store import merge_run, read_run_file
    from reach_receiver.store.parts import list_parts

    for name, numbers in before.items():
        directory = runs / name
        if not list_parts(directory) and not (directory / "run.h5").exists():
            continue  # no run began (nothing stored)
        try:
            if list_parts(directory):
                merge_run(directory)
            contents = read_run_file(directory / "run.h5")
            for m in contents.measurements:
                contents.read(m)
        except Exception as err:
            return f"{name}: unreadable after space returned: {type(err).__name__}: {err}"
        missing = sorted(set(numbers) - {m.sequence for m in contents.measurements})
        if missing:
            return f"{name}: measurements {missing} gone"
    return ""


def _answer(done: Answer) -> dict[str, Any]:
    return {"code": done.code, "stdout": done.stdout[-4000:], "stderr": done.stderr[-4000:]}


# ------------------------------------------------------------------ reach-run
def reach_run_scenario(work: str, size: str, fsize_kb: str) -> None:
    """Inside a namespace (or not, ``size`` empty): reach-run on a small disk; JSON out."""
    root = Path(work)
    runs = root / "disk"
    if size:
        _mount(runs, size)
    schedule = root / "diskfill.yaml"
    schedule.write_text(SCHEDULE)
    argv = ["reach-run", str(schedule), "--sim", "--out", str(runs / "runs"), "-q",
            "--compression", "3000"]
    done = _run_limited(argv, int(fsize_kb))
    before = stored(runs / "runs")
    if size:
        _grow(runs)
    missing = readable(runs / "runs", before)
    print(json.dumps({**_answer(done), "stored": before, "missing": missing}))


def _run_limited(argv: list[str], fsize_kb: int) -> Answer:
    """Run ``argv`` (a hang limit; a file-size limit when ``fsize_kb``, SIGXFSZ ignored)."""
    def limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        if fsize_kb:
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize_kb * 1024, fsize_kb * 1024))

    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=180,
                              preexec_fn=limit, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return Answer(None, "", "hung: no answer in 180 s")
    return Answer(done.returncode, done.stdout, done.stderr)


def _judge_run(name: str, found: dict[str, Any]) -> Trial:
    if "error" in found:
        return Trial(name, "crash", found["error"][:200])
    # What the user reads: reach-run's own lines (the simulator may log after them).
    said = [line for line in found["stderr"].splitlines() if line.startswith("reach-run:")]
    answer = Answer(found["code"], found["stdout"], found["stderr"])
    if said and not answer.traceback:
        answer = Answer(found["code"], found["stdout"], " | ".join(said))
    intact = not found["missing"]
    if answer.code == 0 and not answer.traceback:  # there was room enough
        return Trial(name, "clean" if intact else "lost", found["missing"] or "completed")
    trial = judge_refusal(name, answer, intact=intact)
    if trial.verdict == "lost":
        return Trial(name, "lost", found["missing"][:200])
    if trial.verdict == "clean" and not any(w in answer.message.lower() for w in NAMED):
        return Trial(name, "silent", f"the full disk not named: {answer.message[:160]}")
    return trial


def reach_run_trials(workdir: Path, quick: bool) -> Iterator[Trial]:
    """``reach-run --sim`` on tmpfs of each size, then under file-size limits.

    The quick subset is one trial: a tmpfs that fills at the second Dicke cycle (or,
    without namespaces, a file-size limit that one Dicke cycle exceeds).
    """
    prefix = confinement()
    sizes = (QUICK_SIZES if quick else SIZES) if prefix is not None else ()
    for size in sizes:
        work = workdir / f"tmpfs-{size}"
        work.mkdir(parents=True)
        found = run_scenario(prefix or [], "reach_run_scenario", str(work), size, "0")
        yield _judge_run(f"reach-run on a tmpfs of {size}", found)
    for kb in FSIZE_KB[:1] if quick else FSIZE_KB:
        if quick and sizes:
            break
        work = workdir / f"fsize-{kb}"
        work.mkdir(parents=True)
        found = run_scenario([], "reach_run_scenario", str(work), "", str(kb))
        yield _judge_run(f"reach-run under a file-size limit of {kb} kB", found)


# ------------------------------------------------------------------ reachd's state directory
def reachd_scenario(work: str, size: str) -> None:
    """Inside a namespace: reachd --sim whose state directory (and runs) fills; JSON out."""
    from reach_receiver.daemon.client import DaemonClient

    root = Path(work)
    state = root / "state"
    _mount(state, size)
    schedule = root / "diskfill.yaml"
    schedule.write_text(SCHEDULE)
    log = root / "reachd.log"
    notes: list[str] = []
    daemon = _start_reachd(root, log)
    try:
        with DaemonClient(root / "run" / "control.sock") as client:
            first = _submit_and_wait(client, schedule)
            notes.append(f"job 1 {first['state']}: {first['reason']}")
            filler = state / "filler"
            _fill(filler)
            client.request("resume")
            second = _submit_and_wait(client, schedule)
            notes.append(f"job 2 {second['state']}: {second['reason']}")
            status = client.request("status")
            notes.append(f"daemon {status['state']} on a full disk")
            alarms = status["alarms"] + status.get("health", {}).get("alarms", [])
            notes.append(f"alarms: {alarms}")
        before = stored(state / "runs")
        filler.unlink()
        _grow(state)
        _wait_for_queue_file(state / "queue.json", int(second["id"]))
        daemon.send_signal(signal.SIGTERM)
        code = daemon.wait(timeout=60)
        notes.append(f"exit {code} on SIGTERM")
        daemon = _start_reachd(root, log)  # recovery merges what the full disk left
        with DaemonClient(root / "run" / "control.sock") as client:
            notes.append(f"restarted: {client.request('status')['state']}")
        daemon.send_signal(signal.SIGTERM)
        code = daemon.wait(timeout=60)
        missing = readable(state / "runs", before)
        jobs = json.loads((state / "queue.json").read_text())["jobs"]
        reasons = [j["reason"] for j in jobs]
    except Exception as err:
        print(json.dumps({"error": f"{type(err).__name__}: {err}; " + "; ".join(notes)}))
        return
    finally:
        if daemon.poll() is None:
            daemon.kill()
            daemon.wait()
    print(json.dumps({"code": code, "log": log.read_text()[-20000:], "notes": notes,
                      "missing": missing, "reasons": reasons, "stored": before}))


def _start_reachd(root: Path, log: Path) -> subprocess.Popen[bytes]:
    argv = ["reachd", "--sim", "--state-dir", str(root / "state"), "--runtime-dir",
            str(root / "run"), "--site-out", str(root / "site.yaml"), "--compression", "3000"]
    with log.open("ab") as out:
        process = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT,
                                   stdin=subprocess.DEVNULL)
    deadline = time.monotonic() + 90
    sock = root / "run" / "control.sock"
    while not sock.exists():
        if process.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"reachd did not start (exit {process.poll()})")
        time.sleep(0.1)
    return process


def _submit_and_wait(client: Any, schedule: Path) -> dict[str, Any]:
    answer = client.request("submit", schedule=str(schedule),
                            files={str(schedule): schedule.read_text()})
    job = int(answer["job"]["id"])
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        found = [j for j in client.request("queue")["jobs"] if j["id"] == job]
        if found and found[0]["state"] in ("completed", "failed", "interrupted"):
            return dict(found[0])
        time.sleep(0.2)
    raise RuntimeError(f"job {job} did not end in 120 s")


def _wait_for_queue_file(path: Path, job: int) -> None:
    """Wait (10 s at most) for the daemon to write its queue file again, with ``job``."""
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError, ValueError):
            if any(j["id"] == job for j in json.loads(path.read_text())["jobs"]):
                return
        time.sleep(0.2)
    raise RuntimeError(f"{path}: not written again once there was room")


def _fill(path: Path) -> None:
    """Write ``path`` until the disk is full."""
    block = b"\0" * 65536
    with path.open("wb", buffering=0) as out:
        try:
            while True:
                out.write(block)
        except OSError:
            pass
        try:
            while True:
                out.write(b"\0" * 512)
        except OSError:
            pass


def reachd_trial(workdir: Path) -> Iterator[Trial]:
    """``reachd --sim`` whose state directory fills during a run, then altogether."""
    name = "reachd with its state directory full"
    prefix = confinement()
    if prefix is None:
        return
    work = workdir / "reachd"
    work.mkdir(parents=True)
    found = run_scenario(prefix, "reachd_scenario", str(work), "4m")
    if "error" in found:
        yield Trial(name, "crash", found["error"][:200])
        return
    detail = "; ".join(found["notes"])
    if "Traceback (most recent call last)" in found["log"] or found["code"] != 0:
        yield Trial(name, "crash", f"traceback or exit {found['code']}: {detail}"[:200])
    elif found["missing"]:
        yield Trial(name, "lost", found["missing"][:200])
    elif not all("no space left on device" in r for r in found["reasons"][:2]):
        yield Trial(name, "silent", f"a job's reason does not name the disk: {detail}"[:200])
    else:
        yield Trial(name, "clean", detail[:200])


def trials(workdir: Path, quick: bool) -> Iterator[Trial]:
    """reach-run on small disks and under file-size limits; reachd's state dir filled."""
    yield from reach_run_trials(workdir, quick)
    if not quick:
        yield from reachd_trial(workdir)


if __name__ == "__main__":  # the scenarios are called by name through ``python -c``
    sys.exit("python -m benchmarks.faults --only disk")
