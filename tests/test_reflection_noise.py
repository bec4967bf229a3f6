"""The VNA's random reflection error, carried into calibrator rows and calibrated spectra."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from calibration.model.noise_waves import design_terms, source_temperature
from calibration.model.reflection_noise import (
    receiver_temperature_variance,
    temperature_variance,
    trace_noise,
)
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run
from calibration.solve.radiometric_solver import solve_radiometric

WIDTH = 8 * ITPM_CHANNEL_WIDTH_HZ  # 820 channels
VNA_SIGMA = 1e-3


@pytest.mark.parametrize("seed", [0, 1])
def test_first_order_variance_matches_monte_carlo(seed):
    """var_T from the derivatives equals the spread of T under drawn reflection errors."""
    run = simulate_run(SimulationConfig(channel_width_hz=WIDTH), rng=seed)
    rng = np.random.default_rng(seed)
    theta = run.truth.theta(run.data.freq_hz)
    for name in ("cold", "c10open", "r25"):
        src = run.data.sources[name]
        sigma = 10 ** rng.uniform(-4, -2)
        predicted = temperature_variance(theta, src.gamma, run.data.gamma_rec, src.q, sigma)
        draws = src.gamma + sigma * (
            rng.standard_normal((4000, src.gamma.size))
            + 1j * rng.standard_normal((4000, src.gamma.size))
        ) / np.sqrt(2)
        temps = source_temperature(theta, design_terms(draws, run.data.gamma_rec), src.q)
        ratio = np.var(temps, axis=0) / predicted
        # 4000 draws: a variance is known to sqrt(2/4000) = 2.2 %; the median of 820 is tighter
        assert abs(np.median(ratio) - 1.0) < 0.02, name
        assert np.all(np.abs(ratio - 1.0) < 0.15), name
        # The receiver's reflection, drawn instead of the source's.
        predicted = receiver_temperature_variance(
            theta, src.gamma, run.data.gamma_rec, src.q, sigma
        )
        rec_draws = run.data.gamma_rec + (draws - src.gamma)
        temps = source_temperature(theta, design_terms(src.gamma, rec_draws), src.q)
        ratio = np.var(temps, axis=0) / predicted
        assert abs(np.median(ratio) - 1.0) < 0.02, name
        assert np.all(np.abs(ratio - 1.0) < 0.15), name


def _stripped(source):
    return replace(source, gamma_std=None)


@pytest.mark.parametrize("integration_s", [120.0, 1800.0])
def test_reflection_error_makes_the_predictive_honest(integration_s):
    """With VNA noise comparable to the radiometer's, the predictive matches the actual
    error once the reflection errors (the sources' and the receiver's) are modelled, for the
    noisy antenna and for its noiseless twin, whose only per-channel error is then the
    receiver reflection's; the noise scale s^2 is 1, as the radiometer equation makes it.
    Ignored, s^2 absorbs the sources' errors and inflates the antenna's radiometer term."""
    ratios, clean_ratios, scales, ignored_scales = [], [], [], []
    for seed in range(10):
        config = SimulationConfig(
            channel_width_hz=WIDTH, integration_s=integration_s, vna_sigma=VNA_SIGMA
        )
        run = simulate_run(config, rng=100 + seed)
        data = run.data
        solution = solve_radiometric(data)
        spectrum = solution.calibrate(
            data.freq_hz, data.gamma_rec, run.validation, data.channel_width_hz,
            data.gamma_rec_std,
        )
        error = spectrum.mean - run.validation_temperature_k
        ratios.append(np.sqrt(np.mean(error**2) / np.mean(spectrum.std**2)))
        clean = solution.calibrate(
            data.freq_hz, data.gamma_rec, run.validation_noiseless,
            gamma_rec_std=data.gamma_rec_std,
        )
        error = clean.mean - run.validation_temperature_k
        clean_ratios.append(np.sqrt(np.mean(error**2) / np.mean(clean.std**2)))
        scales.append(solution.posterior.noise_variance)
        bare = replace(data, sources={n: _stripped(s) for n, s in data.sources.items()})
        ignored_scales.append(solve_radiometric(bare).posterior.noise_variance)
    rms_ratio = float(np.sqrt(np.mean(np.square(ratios))))
    # 10 runs x 820 channels; the channels are correlated through the calibration error,
    # so the ratio scatters by a few percent run to run.
    assert 0.9 < rms_ratio < 1.1
    assert 0.9 < float(np.sqrt(np.mean(np.square(clean_ratios)))) < 1.1
    assert 0.95 < np.median(scales) < 1.05  # 10 x ~10^4 rows: s^2 known to ~1 %
    assert np.median(ignored_scales) > 1.3 * np.median(scales)


@pytest.mark.parametrize("sigma", [3e-5, 3.6e-4, 3e-3])
def test_trace_noise_is_read_off_a_sweep_of_a_long_cable(sigma):
    """A 10 m cable's reflection (a full turn every ~10 MHz) on REACH's 1401-point sweep,
    with circular noise of rms sigma: the estimate is within 5 % over 20 seeds (its own
    scatter is ~2 %), and a sweep without noise, or one too coarse for the ripple, gives
    no estimate rather than a wrong one."""
    f = np.linspace(40e6, 180e6, 1401)
    cable = 0.9 * np.exp(-2j * np.pi * f * 95e-9) * (1 - 0.1 * (f / 180e6) ** 2)
    estimates = []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        noise = sigma * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
        estimates.append(trace_noise(cable + noise / np.sqrt(2)))
    assert np.mean(estimates) == pytest.approx(sigma, rel=0.05)
    assert trace_noise(cable) is None
    coarse = np.linspace(40e6, 180e6, 101)
    rng = np.random.default_rng(0)
    noisy = 0.9 * np.exp(-2j * np.pi * coarse * 95e-9) + sigma * rng.standard_normal(101)
    assert trace_noise(noisy) is None


@pytest.mark.parametrize("solver", ["radiometric", "least-squares"])
def test_the_radiometer_part_is_kept_apart_from_the_reflections_errors(solver):
    """``std_radiometer``: ``std_measurement`` as it is without the VNA's random errors."""
    from calibration.solve.solvers import solve

    config = SimulationConfig(channel_width_hz=4 * WIDTH, vna_sigma=VNA_SIGMA)
    run = simulate_run(config, rng=3)
    data, ant = run.data, run.validation
    solution = solve(data, solver)
    both = solution.calibrate(data.freq_hz, data.gamma_rec, ant, WIDTH * 4, data.gamma_rec_std)
    alone = solution.calibrate(data.freq_hz, data.gamma_rec, _stripped(ant), WIDTH * 4)
    np.testing.assert_allclose(both.std_radiometer, alone.std_measurement, rtol=1e-12)
    assert np.all(both.std_measurement > both.std_radiometer)  # the reflections' part joined
