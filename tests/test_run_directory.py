"""A run's directory comes from the schedule's name, and never leaves the runs directory."""

import pytest

from reach_receiver.run import compile_text
from reach_receiver.run.context import NoProgress
from reach_receiver.run.session import RunSession
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings


@pytest.fixture(scope="module")
def sim():
    with SimulatedReceiver(SimulationSettings(compression=3000.0, spectrum_period_s=60.0)) as s:
        yield s


@pytest.mark.parametrize("name", ["../../../../tmp/escape", "/tmp/escape", "..", ".hidden/x"])
def test_a_name_that_reads_as_a_path_stays_inside_the_runs_directory(sim, tmp_path, name):
    runs = tmp_path / "runs"
    text = f'schedule: "{name}"\nsteps: [safe]\n'
    schedule = compile_text(text, "named.yaml", site=sim.site())
    session = RunSession(schedule, sim.site(), sim.clock, runs, progress=NoProgress())
    session.run()
    assert session.directory.parent == runs
    assert (session.directory / "run.h5").is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["runs"]  # nothing written beside it
    assert "/" not in session.directory.name
    assert not session.directory.name.startswith(".")
