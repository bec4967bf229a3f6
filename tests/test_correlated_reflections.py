"""Reflection errors shared between rows, in the posterior (calibration.correlated_reflections).

The simulated VNA reads every reflection at sweep points ``L`` channels apart and splines
them onto the channels (``SimulationConfig.vna_step_channels``), as the hand-over does;
the receiver's reflection is one reading in every calibrator's row. Over seeded truths,
the calibrated antenna's error against the simulator's truth (its true reflection, no
radiometer noise of its own: the solution's error alone) must match the posterior's
calibration error, and must not without the correction.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calibration import simulate_run, solve_radiometric
from calibration.errors import InvalidDataError
from calibration.hdf5_io import read_run, write_run
from calibration.model_fit import OrderChoice
from calibration.simulate import SimulationConfig

#: 1640 channels of 48.8 kHz: REACH's band at a quarter of its resolution, so that a
#: sweep step of 8 channels is 390 kHz.
WIDTH_HZ = 4 * 12207.03125


def _ensemble(step, sigma, seconds, seeds, declared=True, orders="truth"):
    """RMS over runs of actual / predicted error, and the pooled share of |z| < 1."""
    config = SimulationConfig(
        channel_width_hz=WIDTH_HZ, integration_s=seconds, vna_sigma=sigma, vna_step_channels=step
    )
    ratios, z = [], []
    for seed in seeds:
        run = simulate_run(config, rng=seed)
        data = run.data
        if not declared:
            data = dataclasses.replace(data, reflection_correlation_channels=1.0)
        if orders == "truth":
            choice = OrderChoice.fixed(run.truth.parameters.orders)
            solution = solve_radiometric(data, choice, average=False)
        else:
            solution = solve_radiometric(data)
        spectrum = solution.calibrate(data.freq_hz, run.gamma_rec_true, run.validation_noiseless)
        error = spectrum.mean - run.validation_temperature_k
        ratios.append(np.mean(error**2) / np.mean(spectrum.std_calibration**2))
        z.append(error / spectrum.std_calibration)
    return float(np.sqrt(np.mean(ratios))), float(np.mean(np.abs(np.concatenate(z)) < 1))


@pytest.mark.parametrize(
    ("step", "sigma", "seconds"),
    [(8, 4e-4, 600.0), (1, 1e-3, 3600.0), (4, 1e-3, 600.0)],
)
def test_the_posterior_holds_errors_shared_over_channels_and_calibrators(step, sigma, seconds):
    """16 truths each: REACH-like trace noise (7-20 % of the rows' variance) shared over 8
    channels; trace noise dominating the rows with the receiver's error in every row;
    between the two. Measured 1.03, 0.92, 0.96 actual / predicted, 66, 75, 72 % within
    1 sigma; a run's error has few independent modes, so 16 runs know the ratio to about
    15 %."""
    ratio, within = _ensemble(step, sigma, seconds, range(16))
    assert 0.8 < ratio < 1.25
    assert 0.58 < within < 0.78


def test_without_the_correlation_the_error_bars_are_too_small():
    """The same errors with the channels' sharing left out: 2.38x, 32 % within 1 sigma."""
    ratio, within = _ensemble(8, 4e-4, 600.0, range(8), declared=False)
    assert ratio > 1.6
    assert within < 0.5


def test_the_model_average_is_widened_too():
    """The default solver (evidence search, averaged over models), 6 truths: 1.16."""
    ratio, _ = _ensemble(8, 4e-4, 600.0, range(6), orders="search")
    assert 0.7 < ratio < 1.35


def test_the_sharing_is_kept_in_run_files_and_checked(tmp_path):
    run = simulate_run(
        SimulationConfig(channel_width_hz=0.4e6, vna_sigma=1e-3, vna_step_channels=3), rng=1
    )
    assert run.data.reflection_correlation_channels == 3.0
    write_run(tmp_path / "run.h5", run.data)
    data, _ = read_run(tmp_path / "run.h5")
    assert data.reflection_correlation_channels == 3.0
    with pytest.raises(InvalidDataError, match="reflection_correlation_channels must be >= 1"):
        dataclasses.replace(run.data, reflection_correlation_channels=0.5)
