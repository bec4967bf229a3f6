"""What the drift check compares two solutions on when this run has not measured the antenna.

An observing run calibrates before its first antenna cycle, so its drift check takes the
antenna as the previous solution's run measured it (:func:`reach_receiver.run.drift.drift_source`):
an observing run's last calibrated cycle, its spectrum and S11 as its own hand-over names
them, on the channels of the solution's band. The calibrating run's path (the antenna in
its hand-over) is exercised end to end by ``tests/test_drift_monitor.py``.
"""

import numpy as np

from calibration.model.reflections import reach_source_reflection
from calibration.solve.solvers import band_hz
from reach_receiver.run.drift import Previous, antenna_of_run, drift_source
from reach_receiver.store import read_run_file
from tests.test_season import cycles, make_night, night_times, sky_k, write_run


def _observing_run(tmp_path, n=3):
    night = make_night(5)
    freq = night.sim.data.freq_hz
    rng = np.random.default_rng(5)
    spectra = cycles(night, rng, n, 600.0, sky_k(freq))
    # each cycle's own powers: source, load and noise source give Q = 1 / (i + 2)
    path = write_run(tmp_path / "night", night, spectra, night_times(0, n),
                     powers=lambda i: {"source": 2.0, "load": 1.0, "ns": float(i + 3)})
    return night, path


def test_an_observing_run_gives_its_last_calibrated_antenna_cycle(tmp_path):
    night, path = _observing_run(tmp_path, n=3)
    contents = read_run_file(path)
    antenna, freq = antenna_of_run(contents, band_hz(night.solution))
    assert antenna is not None
    assert freq is not None
    assert antenna.name == "ant"
    np.testing.assert_allclose(freq, night.sim.data.freq_hz)
    np.testing.assert_allclose(antenna.q, 1.0 / 4.0)  # the third cycle's, not the first's
    np.testing.assert_allclose(antenna.gamma, reach_source_reflection("ant", freq))


def test_the_previous_antenna_is_used_only_on_the_same_channels(tmp_path):
    night, path = _observing_run(tmp_path)
    previous = Previous(night.solution, None, "run night", read_run_file(path))
    data = night.sim.data
    cold = data.sources["cold"]
    used = drift_source(cold, previous, data)
    assert used.name == "ant"
    np.testing.assert_allclose(used.q, 1.0 / 4.0)  # the previous run's last antenna cycle
    fewer = data.select(np.arange(data.freq_hz.size) % 2 == 0)
    assert drift_source(cold, previous, fewer) is cold  # another grid: the validation source
    assert drift_source(cold, Previous(night.solution, None, "x"), data) is cold
