"""``safe`` is a schedule of its own: it needs no ``initialise`` before it."""

import time

import pytest

from reach_receiver.devices.teensy import Teensy
from reach_receiver.run import compile_text
from reach_receiver.run.context import NoProgress
from reach_receiver.run.session import RunSession
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings
from reach_receiver.store import read_run_file


@pytest.fixture
def sim():
    with SimulatedReceiver(SimulationSettings(compression=3000.0, spectrum_period_s=60.0)) as s:
        yield s


def test_a_schedule_of_just_safe_makes_a_powered_front_end_safe(sim, tmp_path):
    site = sim.site()
    teensy = Teensy(site.devices.teensy.port, timeout_s=site.devices.teensy.timeout_s)
    teensy.connect()
    try:
        teensy.set_rail("12v", True)
    finally:
        teensy.close()
    deadline = time.monotonic() + 5  # the simulator reads the pins on its own thread
    while sim.teensy.state.get("12v") != "1":
        assert time.monotonic() < deadline, sim.teensy.state
        time.sleep(0.01)
    schedule = compile_text("schedule: make-safe\nsteps: [safe]\n", "make-safe.yaml", site=site)
    session = RunSession(schedule, site, sim.clock, tmp_path, progress=NoProgress())
    session.run()
    assert sim.teensy.state["12v"] == "0"
    assert sim.teensy.state["ns"] == "0"
    assert read_run_file(session.directory / "run.h5").status == "completed"
