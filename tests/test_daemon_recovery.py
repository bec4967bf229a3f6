"""reachd against a reach-sim in another process: killed and restarted, timers missed.

The simulated receiver runs as its own process (``reach-sim``), as the hardware does, so
it outlives the daemon: SIGKILL the daemon at random moments of a run, start it again,
and the front-end, the run files and the queue must be as the issue says.
"""

import json
import os
import signal
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from reach_receiver.cli import run_main
from reach_receiver.daemon.client import DaemonClient, daemon_answers
from reach_receiver.run.resume import carry
from reach_receiver.schedule.lst import local_sidereal_time_h
from reach_receiver.store import RunStore, read_run_file
from reach_receiver.store.parts import list_parts

ENTRY = "from reach_receiver.cli import {main}; import sys; sys.exit({main}(sys.argv[1:]))"
SCHEDULE = """\
schedule: resumable
steps:
  - initialise: {rails: [12v, 24v, 6v]}
  - temperatures: {period_s: 30}
  - dicke: {sources: [cold, hot, r25, r100, c2r27, c2r36], seconds: 600}
  - vna_calibrate
  - s11: {targets: [cold, hot, r25, lna]}
  - safe
"""
EXPECTED = {("dicke", s) for s in ("cold", "hot", "r25", "r100", "c2r27", "c2r36")} | {
    ("s11", t) for t in ("cold", "hot", "r25", "lna")
}
SAFE_PINS = ("ns=0", "6v=0", "12v=0", "ms1=0", "ms2=0", "ms3=0", "ms4=0", "mts=lna")


def python(main, *args, **options):
    return subprocess.Popen(
        [sys.executable, "-c", ENTRY.format(main=main), *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **options,
    )


@pytest.fixture(scope="module")
def reach_sim(tmp_path_factory):
    root = tmp_path_factory.mktemp("sim")
    site = root / "sim.yaml"
    process = python("sim_main", "--site-out", str(site), "--compression", "3000")
    deadline = time.monotonic() + 60
    while not site.exists():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.05)
    yield yaml.safe_load(site.read_text())
    process.send_signal(signal.SIGTERM)
    process.communicate(timeout=30)


def site_file(root: Path, sim: dict, **daemon) -> Path:
    document = {**sim, "daemon": {"state_dir": str(root / "state"),
                                  "runtime_dir": str(root / "run"), **daemon}}
    path = root / "site.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


def start_reachd(site: Path) -> subprocess.Popen:
    process = python("reachd_main", "--site", str(site), "-v")
    runtime = Path(yaml.safe_load(site.read_text())["daemon"]["runtime_dir"])
    deadline = time.monotonic() + 60
    while not daemon_answers(runtime / "control.sock"):  # a killed one leaves its file
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.05)
    return process


def finish(process: subprocess.Popen, sig=signal.SIGTERM) -> tuple[int, str]:
    if process.poll() is None:
        process.send_signal(sig)
    _, err = process.communicate(timeout=60)
    return process.returncode, err


def jobs(root: Path) -> list[dict]:
    with DaemonClient(root / "run" / "control.sock") as client:
        return client.request("queue")["jobs"]


def wait(predicate, timeout_s=90.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = predicate()
        if found:
            return found
        time.sleep(0.05)
    raise AssertionError("timed out")


# (Dicke cycles stored, extra seconds) before SIGKILL: inside an integration after three stored
# cycles. Kills right after a stored measurement are tests/test_store_crash.py's; two more
# points here (after one and six cycles) cost 30 s of a suite at its time budget.
KILLS = [(3, 0.13)]


@pytest.mark.parametrize(("cycles", "extra_s"), KILLS)
def test_a_killed_daemon_recovers_and_the_schedule_carries_on(reach_sim, tmp_path, cycles,
                                                              extra_s):
    schedule = tmp_path / "resumable.yaml"
    schedule.write_text(SCHEDULE)
    site = site_file(tmp_path, reach_sim, resume=True)
    reachd = start_reachd(site)
    assert run_main(["--site", str(site), str(schedule), "--detach"]) == 0
    runs = tmp_path / "state" / "runs"

    def stored():
        directories = list(runs.iterdir()) if runs.exists() else []
        parts = list_parts(directories[0]) if directories else []
        return parts if sum(p.kind == "dicke" for p in parts) >= cycles else None

    wait(stored)
    time.sleep(extra_s)
    (first_run,) = list(runs.iterdir())
    before = {(p.sequence, p.kind, p.name) for p in list_parts(first_run)}
    os.kill(reachd.pid, signal.SIGKILL)
    reachd.wait(timeout=10)
    reachd.communicate()

    again = start_reachd(site)
    done = wait(lambda: [j for j in jobs(tmp_path) if j["state"] in ("completed", "failed")])
    code, log = finish(again)
    assert code == 0
    # The restarted daemon put the front-end in its safe state before anything else.
    safe_line = next(line for line in log.splitlines() if "front-end safe:" in line)
    for pin in SAFE_PINS:
        assert pin in safe_line
    # The interrupted run: closed by recovery, every measurement stored before the kill.
    interrupted = read_run_file(first_run / "run.h5")
    assert interrupted.status == "interrupted"
    assert "the daemon stopped during the run" in interrupted.reason
    kept = {(m.sequence, m.kind, m.name) for m in interrupted.measurements}
    assert {b for b in before if b[1] not in ("run", "status")} <= kept
    # The continuation: completed, every measurement of the schedule exactly once.
    (resumed,) = done
    assert resumed["state"] == "completed", resumed["reason"]
    assert resumed["origin"] == "resumption of job 1"
    contents = read_run_file(Path(resumed["run"]) / "run.h5")
    measured = [(m.kind, m.name) for m in contents.measurements if m.kind in ("dicke", "s11")]
    assert sorted(measured) == sorted(EXPECTED)
    carried = [m for m in contents.measurements if "carried_from" in m.attrs]
    old = [m for m in interrupted.measurements if m.kind in ("dicke", "s11")]
    assert len([m for m in carried if m.kind in ("dicke", "s11")]) == len(old)


def lst_in(minutes: float, clock_start: float) -> float:
    now = datetime.fromtimestamp(clock_start + minutes * 60, tz=timezone.utc)
    return round(local_sidereal_time_h(now, 21.52), 6) % 24


def simulated_now(sim: dict) -> float:
    clock = sim["simulation"]
    return clock["start"] + clock["compression"] * (time.monotonic() - clock["monotonic_origin"])


# A daemon's start takes seconds of real time, hours of simulated time at 3000x: the
# "late" window is wide enough for that, the "skip" one narrower than the 25 minutes.
@pytest.mark.parametrize(("window_s", "expected"), [(12 * 3600.0, "late"), (600.0, "skipped")])
def test_a_trigger_missed_while_the_daemon_was_down(reach_sim, tmp_path, window_s, expected):
    schedule = tmp_path / "timed.yaml"
    schedule.write_text("schedule: timed\nsteps:\n  - initialise: {rails: [12v, 24v]}\n  - safe\n")
    first = start_reachd(site_file(tmp_path, reach_sim))  # remembers it was up, no timers
    assert finish(first)[0] == 0
    # While it is down, the sky passes the timer's LST: 5 simulated minutes after it
    # stopped; it starts again 20 minutes after that (0.5 s of real time at 3000x).
    stopped = simulated_now(reach_sim)
    at = lst_in(5, stopped)
    wait(lambda: simulated_now(reach_sim) >= stopped + 25 * 60)
    timers = [{"name": "night", "schedule": str(schedule), "at_lst_h": at}]
    site = site_file(tmp_path, reach_sim, timers=timers,
                     missed={"policy": "late", "window_s": window_s})
    second = start_reachd(site)
    try:
        if expected == "late":
            (job,) = wait(lambda: jobs(tmp_path))
            assert job["origin"] == "timer night (late)"
        else:
            time.sleep(1.0)
            assert jobs(tmp_path) == []
    finally:
        code, log = finish(second)
    assert code == 0
    assert ("run late" if expected == "late" else "skipped") in log


def test_a_timer_fires_when_its_sidereal_time_comes(reach_sim, tmp_path):
    schedule = tmp_path / "timed.yaml"
    schedule.write_text("schedule: timed\nsteps:\n  - initialise: {rails: [12v, 24v]}\n  - safe\n")
    first = start_reachd(site_file(tmp_path, reach_sim))
    assert finish(first)[0] == 0
    # Twenty simulated hours from now: 24 s of real time at 3000x, beyond the daemon's
    # start even on a loaded machine (3.6 s, then 9.6 s, were once too little under a
    # full suite on two cores: the timer then ran late).
    at = lst_in(1200, simulated_now(reach_sim))
    site = site_file(tmp_path, reach_sim, timers=[
        {"name": "soon", "schedule": str(schedule), "at_lst_h": at}])
    second = start_reachd(site)
    try:
        (job,) = wait(lambda: [j for j in jobs(tmp_path) if j["state"] == "completed"])
        assert job["origin"] == "timer soon (on time)"
    finally:
        assert finish(second)[0] == 0


QUICK = Path(__file__).parent.parent / "schedules" / "quick.yaml"


@pytest.fixture(scope="module")
def completed_quick(reach_sim, tmp_path_factory):
    """A quick.yaml run through reachd to completion (calibrated): the root and its job."""
    root = tmp_path_factory.mktemp("quick")
    site = site_file(root, reach_sim, resume=True)
    reachd = start_reachd(site)
    assert run_main(["--site", str(site), str(QUICK), "--detach"]) == 0
    (job,) = wait(lambda: [j for j in jobs(root) if j["state"] not in ("queued", "running")],
                  timeout_s=180)
    code, log = finish(reachd)
    assert code == 0, log
    assert job["state"] == "completed", job["reason"]
    return root, site, job


def test_a_daemon_killed_after_the_final_merge_records_the_run_as_it_ended(completed_quick):
    # SIGKILL between a run's final merge and the job's record: the queue still says
    # "running"; the run file says "completed". The run file is the truth.
    root, site, job = completed_quick
    queue_file = root / "state" / "queue.json"
    kept = queue_file.read_text()
    queue = json.loads(kept)
    queue["jobs"][0].update(state="running", ended=None)
    queue_file.write_text(json.dumps(queue))
    try:
        again = start_reachd(site)
        (after,) = jobs(root)
        code, log = finish(again)
    finally:
        queue_file.write_text(kept)
    assert code == 0, log
    assert after["id"] == job["id"]
    assert after["state"] == "completed", after
    assert "resumption" not in log  # nothing queued again: the run had ended
    assert read_run_file(Path(job["run"]) / "run.h5").status == "completed"


def test_a_carried_calibration_names_the_copies_of_what_it_used(completed_quick, tmp_path):
    # A resumed run copies the measurements under its own numbers; the calibration it
    # carries must name those copies, or the merge reads other measurements (or none).
    _, _, job = completed_quick
    original = Path(job["run"]) / "run.h5"
    with h5py.File(original, "r") as f:
        width, band = float(f["run"].attrs["channel_width_hz"]), f["run"].attrs["band_hz"]
    store = RunStore(tmp_path / "resumed", name="quick", schedule_files=[], site_yaml="",
                     metadata={}, channel_width_hz=width, band_hz=(band[0], band[1]))
    store.open()
    store.add_event("note", "a first measurement, so that every number moves", timestamp=0.0)
    carried = carry(store, original)
    merged = store.finish("completed")
    assert carried > 0
    with h5py.File(original, "r") as before, h5py.File(merged, "r") as after:
        for name in ("lna_s11", "hot_spectra", "cold_s11"):
            np.testing.assert_array_equal(after["observation_data"][name][()],
                                          before["observation_data"][name][()])
        used = json.loads(after["observation_metadata"].attrs["handover"])
        names = {int(n): after["measurements"][k].attrs["name"]
                 for k in after["measurements"]
                 for n in [after["measurements"][k].attrs["sequence"]]}
        assert names[used["s11"]["lna"]] == "lna"
        assert {names[n] for n in used["cycles"]["hot"]} == {"hot"}


@pytest.mark.parametrize("sig", [signal.SIGTERM])
def test_a_run_stopped_by_a_restart_carries_on_after_it(reach_sim, tmp_path, sig):
    # systemctl restart (SIGTERM) or a reboot: the run stops cooperatively, and with
    # resume: true the schedule goes on from where it stopped once the daemon is back.
    schedule = tmp_path / "resumable.yaml"
    schedule.write_text(SCHEDULE)
    site = site_file(tmp_path, reach_sim, resume=True)
    reachd = start_reachd(site)
    assert run_main(["--site", str(site), str(schedule), "--detach"]) == 0
    runs = tmp_path / "state" / "runs"
    wait(lambda: runs.exists() and any(
        sum(p.kind == "dicke" for p in list_parts(d)) >= 2 for d in runs.iterdir()))
    code, log = finish(reachd, sig)
    assert code == 0, log
    again = start_reachd(site)
    done = wait(lambda: [j for j in jobs(tmp_path) if j["state"] in ("completed", "failed")])
    code, log = finish(again)
    assert code == 0, log
    (resumed,) = done
    assert resumed["state"] == "completed", resumed["reason"]
    assert resumed["origin"] == "resumption of job 1"
    first = next(j for j in jobs_file(tmp_path) if j["id"] == 1)
    assert first["state"] == "interrupted"
    contents = read_run_file(Path(resumed["run"]) / "run.h5")
    measured = [(m.kind, m.name) for m in contents.measurements if m.kind in ("dicke", "s11")]
    assert sorted(measured) == sorted(EXPECTED)


def jobs_file(root: Path) -> list[dict]:
    return json.loads((root / "state" / "queue.json").read_text())["jobs"]
