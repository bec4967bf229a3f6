"""A device fault mid-run leaves the simulated front-end safe and the data taken intact."""

import pytest

from reach_receiver.config.site import replace_devices
from reach_receiver.run import compile_text
from reach_receiver.run.context import NoProgress
from reach_receiver.run.session import RunFailed, RunSession
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings
from reach_receiver.store import read_run_file

SCHEDULE = """
schedule: fault
steps:
  - initialise: {}
  - s11: {targets: [hot]}
  - dicke: {sources: [cold], seconds: 240}
  - dicke: {sources: [hot], seconds: 240}
  - dicke: {sources: [r25], seconds: 240}
"""


class FaultOnStep(NoProgress):
    """A progress observer that breaks the spectrometer's stream when step ``n`` starts."""

    def __init__(self, sim: SimulatedReceiver, n: int) -> None:
        self.sim = sim
        self.n = n

    def step(self, index, total, step, text, left_s):
        if index == self.n:
            self.sim.itpm.set_faults(stall=True)


@pytest.fixture
def sim():
    with SimulatedReceiver(SimulationSettings(compression=3000.0, spectrum_period_s=60.0)) as s:
        yield s


def make_runner(sim, tmp_path, progress):
    site = replace_devices(sim.site(), spectrometer={"timeout_s": 1.0})
    schedule = compile_text(SCHEDULE, "fault.yaml", site=site)
    return RunSession(schedule, site, sim.clock, tmp_path, progress=progress)


def test_stalled_spectrometer_mid_run_goes_safe_and_keeps_the_data(sim, tmp_path):
    runner = make_runner(sim, tmp_path, FaultOnStep(sim, 4))
    with pytest.raises(RunFailed, match=r"spectrometer|itpm") as failure:
        runner.run()
    assert failure.value.status == "failed"
    assert "fault.yaml:7" in str(failure.value)  # the hot load's dicke step
    pins = sim.teensy.state
    assert pins["ns"] == "0"
    assert pins["6v"] == "0"
    assert pins["ms1"] == "0"
    contents = read_run_file(failure.value.run_file)
    assert contents.status == "failed"
    names = [(m.kind, m.name) for m in contents.measurements]
    assert ("s11", "hot") in names
    assert ("dicke", "cold") in names
    assert ("dicke", "hot") not in names


def test_interruption_is_recorded_as_such(sim, tmp_path):
    class Interrupt(NoProgress):
        def step(self, index, total, step, text, left_s):
            if index == 3:
                raise KeyboardInterrupt

    runner = make_runner(sim, tmp_path, Interrupt())
    with pytest.raises(RunFailed) as failure:
        runner.run()
    assert failure.value.status == "interrupted"
    assert sim.teensy.state["ms1"] == "0"
