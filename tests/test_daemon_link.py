"""A front-end that disappears in the middle of a run and comes back (USB over fibre).

The site names the Teensy by a stable path, as udev's ``/dev/reach-teensy`` does on the
back-end; the test unplugs the board (its simulator ends, the pseudo-terminal is gone)
during a Dicke step and plugs it back in later on a new terminal behind the same name.
The daemon must fail the run safely, raise a link alarm in its status, try again with
a growing back-off, clear the alarm once the board answers, and (with the resume policy)
carry the schedule on.
"""

import dataclasses
import os
import threading
import time
from pathlib import Path

import pytest

from reach_receiver.config.daemon import DaemonSettings
from reach_receiver.config.site import replace_devices
from reach_receiver.daemon.service import Daemon, Directories
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings, spectrum_period_for
from reach_receiver.store import read_run_file

SCHEDULE = """\
schedule: unplugged
steps:
  - initialise: {rails: [12v, 24v, 6v]}
  - dicke: {sources: [cold, hot, r25, r100], seconds: 600}
  - safe
"""


def plug(link: Path, port: str) -> None:
    """Point the stable name at the board's current terminal (what udev does)."""
    partial = link.with_name(link.name + ".new")
    partial.unlink(missing_ok=True)
    partial.symlink_to(port)
    os.replace(partial, link)


def unplug(link: Path, board) -> None:
    """Close the board's terminal and remove its stable name, as udev does on unplugging.

    Left in place, the name would point at a pseudo-terminal number the kernel hands to
    the next one opened, here or in a test running beside this one: the daemon's retries
    would then find someone else's board.
    """
    board.close()
    link.unlink()


def until(predicate, timeout_s: float = 60.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = predicate()
        if found:
            return found
        time.sleep(0.02)
    raise AssertionError("timed out")


@pytest.fixture
def daemon(tmp_path):
    settings = SimulationSettings(compression=3000.0, spectrum_period_s=spectrum_period_for(3000.0))
    with SimulatedReceiver(settings) as sim:
        link = tmp_path / "reach-teensy"
        plug(link, sim.teensy.port)
        directories = Directories(tmp_path / "run", tmp_path / "state")
        site = replace_devices(sim.site(), teensy={"port": str(link)})
        site = dataclasses.replace(site, daemon=DaemonSettings(
            runtime_dir=directories.runtime, state_dir=directories.state, resume=True))
        reachd = Daemon(site, sim.clock, directories, tick_s=0.05)
        reachd.start()
        serving = threading.Thread(target=reachd.serve)
        serving.start()
        yield reachd, sim, link
        reachd.halt("test over")
        serving.join(timeout=60)
        reachd.close()


def test_an_unplugged_front_end_is_retried_with_back_off_and_the_run_carries_on(daemon):
    reachd, sim, link = daemon
    job = reachd.submit("unplugged.yaml", {"unplugged.yaml": SCHEDULE}, "test")
    until(lambda: reachd.progress is not None and "Dicke" in reachd.progress.step_text)
    time.sleep(0.5)  # inside the Dicke step
    unplug(link, sim.teensy)  # the terminal and its name are gone

    faulted = until(lambda: reachd.machine.state == "faulted" and reachd._status_reply())
    assert "alarm" in faulted["status"]
    assert any("teensy" in alarm.lower() for alarm in faulted["alarms"]), faulted["alarms"]
    failed = reachd.queue.get(job.id)
    assert failed.state == "failed"
    stored = read_run_file(Path(failed.run) / "run.h5")  # closed, readable, with the cause
    assert stored.status == "failed"

    time.sleep(4.0)  # attempts at 1 s and 3 s of back-off fail: still unplugged
    assert reachd.machine.state == "faulted"
    attempts = reachd._retries
    assert 2 <= attempts <= 3, attempts

    sim.teensy.start()  # plugged in again, on another terminal behind the same name
    plug(link, sim.teensy.port)
    until(lambda: reachd.machine.state != "faulted", timeout_s=30)
    assert not reachd._status_reply()["alarms"]
    resumed = until(lambda: [j for j in reachd.queue.jobs("completed")], timeout_s=90)
    assert resumed[0].origin == f"resumption of job {job.id}"
    contents = read_run_file(Path(resumed[0].run) / "run.h5")
    dicke = sorted(m.name for m in contents.measurements if m.kind == "dicke")
    assert dicke == ["cold", "hot", "r100", "r25"]
