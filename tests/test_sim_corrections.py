"""The corrections recover the truth on the simulated receiver with its effects on (issue 14).

Engine-level path (:func:`reach_receiver.sim.engine_run.engine_run`): the simulator's
physics with every effect of :mod:`reach_receiver.sim.effects` on, straight into the
engine's data with radiometer noise only, every eighth channel of the band (about 0.7 s
a seed). The run layer's path, whose error also holds the VNA's trace noise and the
thermocouples' (which the floor does not), is ``python -m benchmarks.sim_corrections
--path run``.
"""

import numpy as np
import pytest

from benchmarks.sim_corrections import engine_once

SEEDS = (11, 12, 13)
#: A single run's error / floor scatters (few independent modes; 0.18-1.13 over seeds
#: 1-8, median 0.57); its RMS over seeds is the issue's 1.1.
SINGLE_RUN_BOUND = 1.6
RMS_BOUND = 1.1
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
