"""Band masks, reflection smoothing (thesis 4.7.1) and weighted averaging of Dicke cycles."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.checks.preparation import (
    band_flags,
    excision_flags,
    smooth_reflection,
    smoothing_width_hz,
    weighted_average,
)
from calibration.core.errors import InvalidDataError

FREQ = np.linspace(50e6, 130e6, 801)  # 100 kHz channels
SEEDS = range(10)


def test_band_and_excision_flags():
    f = np.array([40e6, 50e6, 79e6, 100e6, 130e6, 131e6])
    np.testing.assert_array_equal(band_flags(f, (50e6, 130e6)), [1, 0, 0, 0, 0, 1])
    np.testing.assert_array_equal(excision_flags(f, [(78.5e6, 79.5e6), (100e6, 100e6)]),
                                  [0, 0, 1, 1, 0, 0])
    with pytest.raises(InvalidDataError, match="low < high"):
        band_flags(f, (130e6, 50e6))
    with pytest.raises(InvalidDataError, match="low <= high"):
        excision_flags(f, [(2.0, 1.0)])


def smooth_truth(rng):
    """A cable-like reflection: a slowly turning phase, a sloping magnitude."""
    delay, mag = rng.uniform(5e-9, 20e-9), rng.uniform(0.05, 0.9)
    return mag * (1 - 0.2 * (FREQ - 90e6) / 80e6) * np.exp(-2j * np.pi * FREQ * delay)


@pytest.mark.parametrize("seed", SEEDS)
def test_factor_one_is_no_smoothing(seed):
    rng = np.random.default_rng(seed)
    y = smooth_truth(rng) + 1e-3 * rng.standard_normal(FREQ.size)
    np.testing.assert_allclose(smooth_reflection(FREQ, y, 1.0), y, rtol=0, atol=1e-9)


@pytest.mark.parametrize("seed", SEEDS)
def test_smoothing_brings_noisy_reflections_nearer_the_truth(seed):
    """VNA noise 1e-3 per part per channel; a factor of 0.6 (width 0.5 MHz, x in MHz) cuts
    the error >= 3x (3.7x at worst over the seeds) and leaves a bias under a fifth of the
    noise; flagged channels are bridged, their data unused."""
    rng = np.random.default_rng(seed)
    truth = smooth_truth(rng)
    noise = 1e-3 * (rng.standard_normal(FREQ.size) + 1j * rng.standard_normal(FREQ.size))
    y = truth + noise
    flags = np.zeros(FREQ.size, bool)
    flags[400:410] = True
    y[400:410] += 0.5  # corrupted channels, flagged
    smoothed = smooth_reflection(FREQ, y, 0.6, flags)
    raw_rms = np.sqrt(np.mean(np.abs(noise) ** 2))
    err = np.abs(smoothed - truth)
    assert np.sqrt(np.mean(err**2)) < raw_rms / 3
    assert np.max(err[400:410]) < 2e-3
    bias = np.abs(smooth_reflection(FREQ, truth, 0.6) - truth)
    assert np.max(bias[20:-20]) < 3e-4


def test_smoothing_width_of_the_thesis_factor():
    f = np.linspace(50e6, 130e6, 4001)  # 20 kHz channels
    assert smoothing_width_hz(f, 0.99999999) == pytest.approx(3.76e3, rel=0.01)
    assert smoothing_width_hz(FREQ, 0.999) == pytest.approx(1e6 * (1.001e-3 / 10) ** 0.25,
                                                            rel=1e-3)
    with pytest.raises(InvalidDataError, match=r"\(0, 1\]"):
        smoothing_width_hz(f, 1.5)


N_TRIALS = 20000


@pytest.mark.parametrize("seed", SEEDS)
def test_inverse_variance_average_has_the_stated_variance(seed):
    rng = np.random.default_rng(seed)
    n_cycles = int(rng.integers(2, 12))
    v = rng.uniform(0.5, 5.0, (n_cycles, 1))
    x = 3.0 + np.sqrt(v) * rng.standard_normal((n_cycles, N_TRIALS))
    avg = weighted_average(x, variance=v)
    expected = 1 / np.sum(1 / v)
    np.testing.assert_allclose(avg.variance, expected, rtol=1e-12)
    assert np.var(avg.mean) == pytest.approx(expected, rel=0.05)  # 20000 trials: 1 % sd
    assert np.mean(avg.mean) == pytest.approx(3.0, abs=5 * np.sqrt(expected / N_TRIALS))
    assert np.var(np.mean(x, axis=0)) > np.var(avg.mean)  # equal weights do worse


@pytest.mark.parametrize("seed", SEEDS)
def test_integration_time_average_estimates_its_variance(seed):
    """Radiometer noise ``c / tau``: the estimated variance is unbiased and the spread of
    the means matches ``c / sum(tau)``."""
    rng = np.random.default_rng(seed)
    n_cycles = int(rng.integers(2, 12))
    tau, c = rng.uniform(60, 600, n_cycles), rng.uniform(10, 1000)
    x = 5.0 + np.sqrt(c / tau)[:, None] * rng.standard_normal((n_cycles, N_TRIALS))
    avg = weighted_average(x, integration_s=tau)
    truth = c / tau.sum()
    assert np.var(avg.mean) == pytest.approx(truth, rel=0.05)
    assert np.mean(avg.variance) == pytest.approx(truth, rel=0.05)


@pytest.mark.parametrize("seed", SEEDS)
def test_flagged_cycles_are_left_out(seed):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((6, 50))
    flags = rng.uniform(size=x.shape) < 0.3
    flags[:, 7] = True
    x_bad = np.where(flags, 1e9, x)
    avg = weighted_average(x_bad, variance=2.0, flags=flags)
    keep = ~flags[:, 8]
    assert avg.mean[8] == pytest.approx(np.mean(x[keep, 8]), rel=1e-12)
    assert avg.variance[8] == pytest.approx(2.0 / keep.sum(), rel=1e-12)
    assert avg.flags[7]
    assert np.isnan(avg.mean[7])
    assert avg.n_used[7] == 0
    np.testing.assert_array_equal(avg.n_used, np.sum(~flags, axis=0))


def test_averaging_refuses_ambiguous_or_bad_weights():
    with pytest.raises(InvalidDataError, match="not both"):
        weighted_average(np.ones((3, 4)), variance=1.0, integration_s=[1, 1, 1])
    with pytest.raises(InvalidDataError, match="> 0"):
        weighted_average(np.ones((3, 4)), variance=0.0)
    with pytest.raises(InvalidDataError, match="one time > 0 per cycle"):
        weighted_average(np.ones((3, 4)), integration_s=[1, 1])
    single = weighted_average(np.ones((1, 4)), integration_s=[10.0])
    assert np.all(np.isnan(single.variance))  # one cycle: no scatter to estimate from
