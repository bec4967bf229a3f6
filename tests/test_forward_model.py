"""The forward model: design terms, Dicke powers and the radiometer variance of Q."""

import numpy as np
import pytest

from calibration.model.noise_waves import (
    design_terms,
    dicke_powers,
    model_q,
    q_from_powers,
    q_variance,
    source_temperature,
)
from calibration.model.simulate import SimulationConfig, simulate_run


def test_matched_source_reduces_to_dicke_equation():
    # Gamma = 0: X_unc = X_cos = X_sin = 0 and X_L = 1, so T_cal = T_NS Q + T_L (eq. 3.8).
    terms = design_terms(np.zeros(3), np.full(3, 0.03 + 0.01j))
    np.testing.assert_allclose(terms.x_unc, 0.0, atol=0)
    np.testing.assert_allclose(terms.x_cos, 0.0, atol=0)
    np.testing.assert_allclose(terms.x_sin, 0.0, atol=0)
    np.testing.assert_allclose(terms.x_l, 1.0, rtol=1e-15)


def test_noiseless_run_satisfies_calibration_equation():
    run = simulate_run(SimulationConfig(channel_width_hz=400e6 / 32768 * 16), rng=None)
    temps, q, _ = run.data.stacked()
    theta = run.truth.theta(run.data.freq_hz)
    terms = run.data.terms()
    np.testing.assert_allclose(source_temperature(theta, terms, q), temps, rtol=1e-11)
    np.testing.assert_allclose(model_q(theta, terms, temps), q, rtol=1e-9, atol=1e-12)


def test_powers_follow_thesis_equations():
    # Hand-evaluate eqs. 3.12, 3.13 and 3.20 for one channel.
    theta = np.array([250.0, 190.0, 90.0, 1200.0, 298.0])
    g, gr, t, gain, t0 = 0.3 - 0.2j, 0.02 + 0.01j, 300.0, 2.0, 150.0
    p_src, p_load, p_ns = dicke_powers(theta, g, gr, t, gain, t0)
    f = np.sqrt(1 - abs(gr) ** 2) / (1 - g * gr)
    expected_src = gain * (
        t * (1 - abs(g) ** 2) * abs(f) ** 2
        + 250 * abs(g) ** 2 * abs(f) ** 2
        + 190 * (g * f).real
        + 90 * (g * f).imag
        + t0
    )
    assert p_src == pytest.approx(expected_src, rel=1e-14)
    assert p_load == pytest.approx(gain * (298 * (1 - abs(gr) ** 2) + t0), rel=1e-14)
    assert p_ns == pytest.approx(gain * (1498 * (1 - abs(gr) ** 2) + t0), rel=1e-14)


def test_q_variance_matches_monte_carlo():
    rng = np.random.default_rng(7)
    p = np.array([2.0, 1.0, 5.0])  # source, load, noise source
    samples = np.array([4000.0, 9000.0, 2500.0])
    draws = p + rng.standard_normal((200_000, 3)) * p / np.sqrt(samples)
    q = q_from_powers(draws[:, 0], draws[:, 1], draws[:, 2])
    predicted = q_variance(p[0], p[1], p[2], *samples)
    # 200k draws: the sample variance has ~0.3% relative standard error; the linearised
    # formula is good to O(sigma^2) ~ 1e-3. 2% covers both with margin.
    assert np.var(q) == pytest.approx(predicted, rel=0.02)


def test_radiometer_noise_level_in_simulation():
    cfg = SimulationConfig(channel_width_hz=400e6 / 32768 * 16)
    noisy = simulate_run(cfg, rng=3)
    clean = simulate_run(cfg, rng=None)
    for name in ("cold", "c10open"):
        p_noisy = noisy.data.sources[name].p_source
        p_clean = clean.data.sources[name].p_source
        rel = (p_noisy - p_clean) / p_clean * np.sqrt(cfg.channel_width_hz * cfg.integration_s)
        # 410 channels: the standard deviation of a unit normal sample is within ~10%.
        assert np.std(rel) == pytest.approx(1.0, rel=0.1)
