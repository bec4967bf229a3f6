"""VNA accuracy (thesis table 2.3, eq. 2.2) and the noise diode's ENR check (table 2.1, eq. 2.1)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.core.errors import InvalidDataError
from calibration.model.measurement_uncertainty import (
    AccuracyBand,
    VnaAccuracy,
    check_noise_source,
    expected_t_ns,
    measurement_spread,
    sample_reflections,
)

FREQ = np.linspace(50e6, 130e6, 401)


def reading(db, phase=0.3):
    return 10 ** (np.asarray(db, dtype=float) / 20) * np.exp(1j * phase)


def test_table_2_3_per_band_with_the_larger_error_on_shared_edges():
    acc = VnaAccuracy()
    np.testing.assert_array_equal(acc.error_db(reading([-5, -10, 0.3, -15, -20, -25, -30, -35])),
                                  [0.4, 0.4, 0.4, 1.5, 1.5, 4.0, 4.0, 4.0])
    assert np.isnan(acc.error_db(reading(-45.0)))


def test_halfwidth_is_relative_in_the_table_and_absolute_below_it():
    acc = VnaAccuracy()
    np.testing.assert_allclose(acc.halfwidth(reading(-10.0)),
                               10 ** (-0.5) * (10 ** 0.02 - 10 ** -0.02) / 2, rtol=1e-14)
    floor = 10 ** (-35 / 20) * (10 ** 0.2 - 10 ** -0.2) / 2
    np.testing.assert_allclose(acc.halfwidth(reading([-40.0, -50.0, -80.0])), floor, rtol=1e-14)
    assert floor == pytest.approx(0.00848, abs=1e-5)
    np.testing.assert_allclose(acc.sigma_magnitude(reading(-10.0)),
                               acc.halfwidth(reading(-10.0)) / 2, rtol=1e-15)
    assert VnaAccuracy(coverage=1.0).sigma_magnitude(reading(-20.0)) == pytest.approx(
        acc.halfwidth(reading(-20.0)))


def test_phase_uncertainty_follows_the_error_disk_and_saturates():
    acc = VnaAccuracy()
    g = reading([-3.0, -20.0, -60.0])
    expected = acc.sigma_magnitude(g)[:2] / np.abs(g[:2])
    np.testing.assert_allclose(acc.sigma_phase_rad(g)[:2], expected, rtol=1e-15)
    assert acc.sigma_phase_rad(g)[2] == pytest.approx(np.pi / np.sqrt(3))
    assert acc.sigma_phase_rad(np.zeros(1))[0] == pytest.approx(np.pi / np.sqrt(3))


def test_eq_2_2_spread():
    np.testing.assert_allclose(measurement_spread(-15.0, 1.5), 10 ** -1.35 - 10 ** -1.65)
    np.testing.assert_allclose(measurement_spread([0.0, -25.0], [0.4, 4.0]),
                               [0.184467, 0.0066844], rtol=2e-5)


@pytest.mark.parametrize("seed", range(5))
def test_monte_carlo_draws_have_the_stated_spread(seed):
    """|G| from -2 to -55 dB: the draws' std of |G| and of arg G match sigma to 3 %."""
    rng = np.random.default_rng(seed)
    g = reading(rng.uniform(-55, -2, 40), rng.uniform(-np.pi, np.pi, 40))
    acc = VnaAccuracy()
    draws = sample_reflections(g, rng, 20000, acc)
    np.testing.assert_allclose(np.mean(draws, axis=0), g, rtol=0,
                               atol=5 * np.max(acc.sigma_magnitude(g)) / np.sqrt(20000) * 2)
    sigma = acc.sigma_magnitude(g)
    np.testing.assert_allclose(np.std(draws.real, axis=0), sigma, rtol=0.03)
    np.testing.assert_allclose(np.std(draws.imag, axis=0), sigma, rtol=0.03)
    big = np.abs(g) > 20 * sigma  # where the small-error forms hold
    assert np.count_nonzero(big) > 5
    np.testing.assert_allclose(np.std(np.abs(draws), axis=0)[big], sigma[big], rtol=0.03)
    phase = np.angle(draws / g)
    np.testing.assert_allclose(np.std(phase, axis=0)[big], acc.sigma_phase_rad(g)[big], rtol=0.03)


@pytest.mark.parametrize("corr", [3.0, 10.0])
def test_correlated_draws_have_the_stated_correlation_and_variance(corr):
    rng = np.random.default_rng(7)
    g = np.full(200, reading(-10.0))
    draws = sample_reflections(g, rng, 4000, correlation_channels=corr)
    x = (draws.real - g.real) / VnaAccuracy().sigma_magnitude(g)
    np.testing.assert_allclose(np.std(x, axis=0), 1.0, atol=0.06)  # edges included
    for lag in (1, 2, 5, 10):
        c = np.mean(x[:, 50:150] * x[:, 50 + lag:150 + lag])
        assert c == pytest.approx(np.exp(-lag**2 / (2 * corr**2)), abs=0.04)


def test_a_correlation_longer_than_the_band_gives_smooth_draws_of_the_stated_variance():
    """Kernel wider than the sweep (40 channels, c = 60): a broadcasting error before."""
    rng = np.random.default_rng(8)
    g = np.full(40, reading(-10.0))
    draws = sample_reflections(g, rng, 4000, correlation_channels=60.0)
    x = (draws.real - g.real) / VnaAccuracy().sigma_magnitude(g)
    np.testing.assert_allclose(np.std(x, axis=0), 1.0, atol=0.06)
    assert np.mean(x[:, 0] * x[:, -1]) == pytest.approx(np.exp(-(39**2) / (2 * 60.0**2)), abs=0.05)


def test_expected_t_ns_from_the_enr_table():
    np.testing.assert_allclose(expected_t_ns([50e6, 100e6]),
                               290 * 10 ** (np.array([6.00, 5.79]) / 10), rtol=1e-12)
    assert expected_t_ns([100e6])[0] == pytest.approx(1100.0, abs=1.0)  # thesis: "around 1100 K"
    np.testing.assert_allclose(expected_t_ns([75e6], t_ambient_k=298.0),
                               290 * 10 ** (5.89 / 10) - 8.0, rtol=1e-12)
    with pytest.raises(InvalidDataError, match="30-200 MHz"):
        expected_t_ns([20e6])


@pytest.mark.parametrize("seed", range(10))
def test_a_fit_near_the_table_passes_and_one_a_decibel_low_fails(seed):
    rng = np.random.default_rng(seed)
    truth = expected_t_ns(FREQ)
    sigma = rng.uniform(2, 10) * np.ones(FREQ.size)
    fitted = truth * 10 ** (rng.uniform(-0.15, 0.15) / 10) + sigma * rng.standard_normal(FREQ.size)
    fitted[rng.choice(FREQ.size, 8, replace=False)] += 500.0  # 2 % of channels: RFI artefacts
    good = check_noise_source(fitted, FREQ, sigma)
    assert good.passed, str(good)
    assert "PASS" in str(good)
    low = check_noise_source(fitted * 10 ** -0.1, FREQ, sigma)
    assert not low.passed
    assert low.offset_db == pytest.approx(-1.0, abs=0.2)
    assert "FAIL" in str(low)
    assert check_noise_source(fitted * 10 ** -0.1, FREQ, sigma, path_loss_db=1.2).passed


def test_noise_source_check_refuses_mismatched_input():
    with pytest.raises(InvalidDataError, match="same length"):
        check_noise_source(np.ones(3), FREQ)
    with pytest.raises(InvalidDataError, match="dB >= 0"):
        check_noise_source(expected_t_ns(FREQ), FREQ, path_loss_db=-1)
    with pytest.raises(InvalidDataError, match="at least one band"):
        VnaAccuracy(bands=())
    assert VnaAccuracy(bands=(AccuracyBand(-20, 0, 1.0),)).error_db(reading(-10.0)) == 1.0
