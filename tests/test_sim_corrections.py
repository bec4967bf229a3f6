"""The corrections recover the truth on the simulated receiver with its effects on (issue 14).

Engine-level path (:func:`reach_receiver.sim.engine_run.engine_run`): the simulator's
physics with every effect of :mod:`reach_receiver.sim.effects` on, straight into the
engine's data with radiometer noise only, every eighth channel of the band (about 0.7 s
a seed). And once through the run layer and every transport (one seed, 20 s); the
benchmark's ``--path run`` takes several.
"""

from dataclasses import replace

import numpy as np
import pytest

from benchmarks.sim_corrections import SCHEDULE, engine_once
from calibration.model.simulate import REACH_CALIBRATORS
from reach_receiver.run.session import RunSession
from reach_receiver.sim.effects import SimEffects
from reach_receiver.sim.physics import PhysicsConfig
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings

SEEDS = (11, 12, 13)
#: A single run's error / floor scatters (few independent modes; 0.18-1.13 over seeds
#: 1-8, median 0.57); its RMS over seeds is the issue's 1.1.
SINGLE_RUN_BOUND = 1.6
RMS_BOUND = 1.1
#: Through the run layer the data themselves vary from run to run (the iTPM simulator
#: skips spectra when the machine is busy: floors of 0.9-1.8 K for one seed). Twelve runs
#: of this test's seed gave error/floor 0.41-1.93, RMS 1.03: sqrt(chi2_k / k) of about
#: k = 2 modes, whose tail is exp(-B^2) for a bound B. At B = 2 that is 1.8 % of runs
#: (CI saw 2.42 once); at 3, 1e-4. The uncorrected path reads 18-21x.
RUN_PATH_BOUND = 3.0
#: Uncorrected: 18-21x the floor over seeds 1-8 (the cables' 4 K gradient alone is tens).
UNCORRECTED_AT_LEAST = 8.0


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    return [engine_once(seed, tmp_path_factory.mktemp(f"seed{seed}"), stride=8) for seed in SEEDS]


def test_corrected_antenna_error_reaches_its_floor(outcomes):
    ratios = np.array([o.corrected for o in outcomes])
    assert np.all(ratios < SINGLE_RUN_BOUND), ratios
    assert np.sqrt(np.mean(ratios**2)) < RMS_BOUND, ratios


def test_uncorrected_antenna_error_is_far_above_its_floor(outcomes):
    for o in outcomes:
        assert o.uncorrected > UNCORRECTED_AT_LEAST, o
        assert o.uncorrected > 5 * o.corrected, o


def test_every_rfi_line_is_flagged(outcomes):
    for o in outcomes:
        assert o.rfi_channels >= 4, o


def test_the_run_layer_calibrates_through_the_effects_to_its_floor(tmp_path):
    """The whole loop, one seed (the engine-level tests above cover seeds): a schedule
    through the run layer and every transport with every effect on; the calibrate step
    corrects and solves, and the antenna is judged at the sources' plane. Seeds 1-3 of
    ``python -m benchmarks.sim_corrections --path run`` gave 0.64-1.10x the floor; before
    the S11s' trace noise was in the run file and the summary judged the receiver the
    sources see, this path read 1.9-7x."""
    schedule = tmp_path / "corrections.yaml"
    schedule.write_text(SCHEDULE.format(sources=", ".join(REACH_CALIBRATORS), seconds=120))
    settings = SimulationSettings(
        compression=3000.0, spectrum_period_s=120.0, seed=4, vna_drift_per_hour=0.0,
        physics=replace(PhysicsConfig(seed=4), effects=SimEffects.all()),
    )
    with SimulatedReceiver(settings, workdir=tmp_path) as sim:
        session = RunSession.prepare(schedule, sim.site(), sim.clock, tmp_path / "runs")
        outcome = session.run().calibration
        assert outcome is not None
        assert outcome.handover.corrections.get("mts_sources")
        actual = sim.physics.calibration_error_k(
            outcome.solution, outcome.data, outcome.validation
        )
    assert actual / outcome.floor_k < RUN_PATH_BOUND, (actual, outcome.floor_k)
    assert 0.8 < outcome.predicted_k / outcome.floor_k < 1.25
