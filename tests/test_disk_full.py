"""A full disk is named as such, nothing stored is lost, and the daemon's state survives it.

Each test runs its code in a child process on a small disk of its own: a tmpfs mounted in
a mount namespace of the child (``unshare``, as root or in a user namespace), so nothing
stays mounted; where no namespace is allowed, the file-size limit (``RLIMIT_FSIZE``,
unprivileged) makes the writes fail instead. "Space returns" is the filler removed (or
the limit lifted) in the same child.
"""

import json
import subprocess
import sys
import textwrap
from pathlib import Path

from benchmarks.faults.disk import NAMED, confinement, run_scenario

ROOT = Path(__file__).resolve().parents[1]

#: What each child's code starts with: DISK (the small disk), full() and room().
PRELUDE = '''
import json, resource, subprocess, sys
from pathlib import Path
DISK, MODE, KB = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
if MODE == "fsize":
    resource.setrlimit(resource.RLIMIT_FSIZE, (KB * 1024, resource.RLIM_INFINITY))

def full(*pids):
    """No room at all from here on (for these child processes too)."""
    if MODE == "fsize":
        for pid in (0, *pids):
            resource.prlimit(pid, resource.RLIMIT_FSIZE, (1, resource.RLIM_INFINITY))
        return
    with open(DISK / "filler", "wb", buffering=0) as out:
        for block in (65536, 512):
            try:
                while True:
                    out.write(bytes(block))
            except OSError:
                pass

def room(*pids):
    """Space returns."""
    if MODE == "fsize":
        for pid in (0, *pids):
            resource.prlimit(pid, resource.RLIMIT_FSIZE, (resource.RLIM_INFINITY,) * 2)
    else:
        (DISK / "filler").unlink(missing_ok=True)
        subprocess.run(["mount", "-o", "remount,size=64m", str(DISK)], check=True)
'''


def on_small_disk(tmp_path: Path, kb: int, code: str, limit_kb: int | None = None) -> dict:
    """Run ``code`` (after :data:`PRELUDE`) on a disk of ``kb`` kB; the JSON it prints last.

    Without a namespace, files are limited to ``limit_kb`` (by default ``kb``) instead.
    """
    disk = tmp_path / "disk"
    disk.mkdir()
    script = PRELUDE + textwrap.dedent(code)
    prefix = confinement()
    if prefix is not None:
        mount = f"mount -t tmpfs -o size={kb}k tmpfs {disk} && exec \"$0\" \"$@\""
        argv = [*prefix, "sh", "-c", mount, sys.executable, "-c", script, str(disk), "tmpfs"]
    else:
        argv = [sys.executable, "-c", script, str(disk), "fsize"]
        kb = limit_kb or kb
    done = subprocess.run([*argv, str(kb)], capture_output=True, text=True, timeout=120,
                          cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def named(message: str) -> bool:
    return any(words in message for words in NAMED)


def test_a_measurement_that_does_not_fit_is_refused_by_name_and_the_run_still_closes(tmp_path):
    found = on_small_disk(tmp_path, 1536, '''
        import numpy as np
        from reach_receiver.store import DiskFull, RunStore, merge_run, read_run_file
        from reach_receiver.store.parts import list_parts
        store = RunStore(DISK / "run", name="full", schedule_files=[("s.yaml", "x: 1")],
                         site_yaml="site: {}", metadata={}, channel_width_hz=400e6 / 32768)
        store.open()
        f = np.linspace(50e6, 130e6, 801)
        store.add_s11("lna", f, np.full(f.size, 0.1 + 0j), timestamp=1.0, settings={},
                      calibrated=True)
        pos = ("source", "load", "ns")
        refused, added = "", 0
        for i in range(20):  # 0.8 MB each: the second does not fit
            try:
                store.add_dicke("cold", spectra={p: np.ones((2, 16384)) for p in pos},
                                timestamps={p: [1.0] for p in pos},
                                integration_s={p: 1.0 for p in pos},
                                n_spectra={p: 1 for p in pos}, temperature_k=300.0,
                                switch_states={}, counters={}, timestamp=2.0 + i)
                added += 1
            except DiskFull as err:
                refused = str(err)
                break
        stored = [p.sequence for p in list_parts(DISK / "run")]
        temporaries = [p.name for p in (DISK / "run" / "parts").glob("*.tmp")]
        store.add_event("failed", refused, timestamp=30.0)  # the reserve keeps room for these
        try:
            store.finish("failed", refused)
            merge = "merged"
        except DiskFull as err:
            merge = str(err)
        room()
        contents = read_run_file(merge_run(DISK / "run"))
        print(json.dumps({"refused": refused, "added": added, "stored": stored,
                          "temporaries": temporaries, "merge": merge, "status": contents.status,
                          "have": [m.sequence for m in contents.measurements]}))
    ''', limit_kb=512)
    assert named(found["refused"]), found["refused"]
    assert "a measurement (dicke cold) needs 7" in found["refused"]  # ~770 kB, said in kB
    assert found["temporaries"] == []
    assert found["merge"] == "merged" or named(found["merge"]), found["merge"]
    assert found["status"] == "failed"
    # Every measurement stored before the disk filled is in the run once there is room.
    assert set(found["stored"]) - {0} <= set(found["have"])
    assert len(found["have"]) == 1 + found["added"] + 1  # S11, the cycles, the event


def test_the_daemons_state_files_keep_their_old_contents_on_a_full_disk(tmp_path):
    found = on_small_disk(tmp_path, 1024, '''
        from reach_receiver.config.daemon import DaemonSettings
        from reach_receiver.daemon.jobs import JobQueue
        from reach_receiver.daemon.timers import Timers
        queue = JobQueue(DISK / "queue.json")
        queue.add("a", "a.yaml", {"a.yaml": "x"}, "test", 1.0)
        timers = Timers(DaemonSettings(), 21.3, DISK / "timers.json")
        timers.start(1000.0)
        before = (DISK / "queue.json").read_text(), (DISK / "timers.json").read_text()
        full()
        queue.add("b", "b.yaml", {"b.yaml": "x"}, "test", 2.0)  # must not raise
        timers.due(5000.0)
        during = (DISK / "queue.json").read_text(), (DISK / "timers.json").read_text()
        errors = [queue.write_error, timers.write_error]
        jobs = [j.name for j in queue.jobs()]
        leftovers = sorted(p.name for p in DISK.iterdir() if p.name.endswith(".tmp"))
        room()
        queue.update(queue.jobs()[1], state="running")
        timers.due(9000.0)
        after = json.loads((DISK / "queue.json").read_text())["jobs"]
        print(json.dumps({"same": list(before) == list(during), "errors": errors, "jobs": jobs,
                          "leftovers": leftovers, "after": [j["name"] for j in after],
                          "cleared": [queue.write_error, timers.write_error],
                          "checked": json.loads((DISK / "timers.json").read_text())["checked"]}))
    ''')
    assert found["same"]  # the files as they were before the disk filled
    assert all(e and "not written, its previous state kept" in e for e in found["errors"])
    assert found["jobs"] == ["a", "b"]  # the daemon goes on with the queue in memory
    assert found["leftovers"] == []
    assert found["after"] == ["a", "b"]
    assert found["cleared"] == [None, None]
    assert found["checked"] == 9000.0


def test_the_metrics_database_drops_a_batch_on_a_full_disk_and_resumes(tmp_path):
    found = on_small_disk(tmp_path, 1024, '''
        from reach_receiver.monitor.database import MetricsDatabase
        from reach_receiver.monitor.readings import Reading
        db = MetricsDatabase(DISK / "metrics.sqlite")
        def batch(t0, n=2000):
            return [Reading(f"reach_test_{i % 50}", float(i), "K", t0 + i) for i in range(n)]
        first = db.write(batch(0.0))
        full()
        counts = [db.write(batch(10_000.0 * k)) for k in range(1, 6)]  # must not raise
        error = db.write_error
        room()
        again = db.write(batch(100_000.0))
        print(json.dumps({"first": first, "counts": counts, "error": error, "again": again,
                          "cleared": db.write_error, "rows": db.count()}))
        db.close()
    ''')
    assert found["first"] == 2000
    assert 0 in found["counts"]
    assert "not stored" in found["error"]
    assert found["again"] == 2000
    assert found["cleared"] is None
    assert found["rows"] >= 4000


def test_reachd_stays_up_on_a_full_state_directory_and_names_it(tmp_path):
    found = on_small_disk(tmp_path, 8192, '''
        import signal, time
        from benchmarks.faults.disk import SCHEDULE, _start_reachd, _submit_and_wait
        from benchmarks.faults.disk import _wait_for_queue_file
        from reach_receiver.daemon.client import DaemonClient
        root = DISK.parent
        (root / "state").symlink_to(DISK)  # the state directory (and its runs) on the disk
        schedule = root / "diskfill.yaml"
        schedule.write_text(SCHEDULE)
        log = root / "reachd.log"
        daemon = _start_reachd(root, log)
        full(daemon.pid)
        with DaemonClient(root / "run" / "control.sock") as client:
            job = _submit_and_wait(client, schedule)
            status = client.request("status")
            room(daemon.pid)
            _wait_for_queue_file(DISK / "queue.json", int(job["id"]))
        daemon.send_signal(signal.SIGTERM)
        code = daemon.wait(timeout=60)
        print(json.dumps({"job": job, "state": status["state"], "code": code,
                          "log": log.read_text(), "mode": MODE}))
    ''')
    assert found["job"]["state"] == "failed"
    assert "the run did not start" in found["job"]["reason"]
    assert any(words in found["job"]["reason"] for words in NAMED), found["job"]["reason"]
    assert found["state"] == "faulted"  # up, answering, the queue held for an operator
    assert found["code"] == 0
    assert "Traceback" not in found["log"]
    if found["mode"] == "tmpfs":  # (under a file-size limit its log file is limited too)
        assert "not written, its previous state kept" in found["log"]  # the queue file


def test_reach_run_under_a_file_size_limit_names_it_and_keeps_every_part(tmp_path):
    # Each measurement fits under the limit; the merged run file (~3.3 MB) does not.
    found = run_scenario([], "reach_run_scenario", str(tmp_path), "", "2000")
    assert found["code"] == 1, found["stderr"]
    assert "Traceback" not in found["stderr"]
    assert "internal error" not in found["stderr"]
    (said,) = [line for line in found["stderr"].splitlines() if line.startswith("reach-run: run")]
    assert "file-size limit (ulimit -f) of 2000 kB" in said, said
    assert "the merged run file (run.h5) needs" in said
    assert "kept as part files" in said
    (numbers,) = found["stored"].values()
    assert len(numbers) >= 8  # the S11s, the Dicke cycles, the step events
    assert found["missing"] == ""  # all of them in run.h5 once merged without the limit
