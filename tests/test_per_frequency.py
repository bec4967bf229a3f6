"""Per-channel solvers (thesis 4.7 least squares, 4.8 Bayesian): calibration.solve.per_frequency.

All runs are seeded; the band is the REACH one at 16 iTPM channels per channel (410
channels), so the whole file runs in a few seconds.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from calibration.core.errors import IllPosedError
from calibration.model.data import CalibrationData, Integration
from calibration.model.reflections import lna_reflection, reach_source_reflection
from calibration.model.simulate import (
    ITPM_CHANNEL_WIDTH_HZ,
    SimulatedRun,
    SimulationConfig,
    simulate_run,
    simulate_source,
)
from calibration.solve.per_frequency import (
    ChannelSolution,
    solve_bayesian_per_channel,
    solve_least_squares_per_channel,
)
from calibration.solve.radiometric_solver import linearise

CONFIG = SimulationConfig(channel_width_hz=ITPM_CHANNEL_WIDTH_HZ * 16)
SEED = 20240611


@pytest.fixture(scope="module")
def run() -> SimulatedRun:
    return simulate_run(CONFIG, rng=SEED)


@pytest.fixture(scope="module")
def bayes(run: SimulatedRun) -> ChannelSolution:
    return solve_bayesian_per_channel(run.data)


@pytest.fixture(scope="module")
def least_squares(run: SimulatedRun) -> ChannelSolution:
    return solve_least_squares_per_channel(run.data)


def test_bayesian_posterior_covers_truth(run: SimulatedRun, bayes: ChannelSolution) -> None:
    freq = run.data.freq_hz
    z = (bayes.mean - run.truth.theta(freq)) / bayes.parameter_std(freq)
    assert z.shape == (5, 410)
    within_1 = float(np.mean(np.abs(z) < 1.0))
    within_3 = float(np.mean(np.abs(z) < 3.0))
    # 2050 values, correlated within a channel: 68.3% +- ~2%.
    assert 0.60 <= within_1 <= 0.76
    assert within_3 >= 0.99
    assert abs(float(z.mean())) < 0.15
    assert 0.9 < float(z.std()) < 1.1
    for k in range(5):  # every parameter on its own, wider band (410 values)
        assert 0.55 <= float(np.mean(np.abs(z[k]) < 1.0)) <= 0.80


def test_noiseless_run_recovered_exactly() -> None:
    clean = simulate_run(CONFIG, rng=None)
    truth = clean.truth.theta(clean.data.freq_hz)
    for solve in (solve_least_squares_per_channel, solve_bayesian_per_channel):
        solution = solve(clean.data)
        assert np.max(np.abs(solution.mean - truth) / np.abs(truth)) < 1e-6, solution.method


def _equal_weights(data: CalibrationData) -> CalibrationData:
    """Override var Q_i = c / X_L,i^2: the radiometer weights 1/((X_L T_NS)^2 var Q) are
    then equal across calibrators in every channel."""
    x_l = data.terms().x_l
    _, _, var_q = data.stacked()
    c = np.mean(var_q * x_l**2, axis=0)
    sources = {
        name: replace(src, q_variance_override=c / x_l[i] ** 2)
        for i, (name, src) in enumerate(data.sources.items())
    }
    return replace(data, sources=sources)


def test_least_squares_equals_bayesian_with_equal_weights(run: SimulatedRun) -> None:
    data = _equal_weights(run.data)
    ls = solve_least_squares_per_channel(data)
    bayes = solve_bayesian_per_channel(data)
    dz = np.abs(ls.mean - bayes.mean) / bayes.parameter_std(data.freq_hz)
    # Same estimator up to OLS's errors-in-variables term (measured Q in X_NS), second
    # order in the noise; it is visible only in nearly degenerate channels.
    assert float(np.median(dz)) < 0.01
    assert float(dz.max()) < 0.2


def test_least_squares_close_to_bayesian_in_general(
    run: SimulatedRun, bayes: ChannelSolution, least_squares: ChannelSolution
) -> None:
    std = bayes.parameter_std(run.data.freq_hz)
    dz = (least_squares.mean - bayes.mean) / std
    assert float(np.sqrt(np.mean(dz**2))) < 0.25
    assert float(np.abs(dz).max()) < 1.2
    # OLS error bars (residual variance, 7 dof) are the right size on average.
    ratio = np.median(least_squares.parameter_std(run.data.freq_hz) / std, axis=1)
    assert np.all((ratio > 0.6) & (ratio < 1.4))


def test_tight_prior_at_truth_shrinks_posterior(run: SimulatedRun, bayes: ChannelSolution) -> None:
    freq = run.data.freq_hz
    truth = run.truth.theta(freq)
    std0 = bayes.parameter_std(freq)
    tight = solve_bayesian_per_channel(run.data, prior_mean=truth, prior_sd=0.5 * std0)
    std = tight.parameter_std(freq)
    # A prior of half the likelihood width: the marginal std drops to <= 1/sqrt(5) of it.
    assert float(np.max(std / std0)) < 0.46
    err0 = np.sqrt(np.mean((bayes.mean - truth) ** 2, axis=1))
    err = np.sqrt(np.mean((tight.mean - truth) ** 2, axis=1))
    assert np.all(err < 0.5 * err0)


def test_vague_prior_far_from_truth_has_no_effect(
    run: SimulatedRun, bayes: ChannelSolution
) -> None:
    freq = run.data.freq_hz
    std0 = bayes.parameter_std(freq)
    far = solve_bayesian_per_channel(
        run.data, prior_mean=run.truth.theta(freq) + 1e4, prior_sd=np.full(5, 1e9)
    )
    assert float(np.max(np.abs(far.mean - bayes.mean) / std0)) < 1e-6
    assert float(np.max(np.abs(far.parameter_std(freq) / std0 - 1.0))) < 1e-9


def test_evidence_is_the_marginal_likelihood(
    run: SimulatedRun, least_squares: ChannelSolution
) -> None:
    """With one Gauss-Newton step from least squares, log Z must equal the Gaussian
    marginal log N(y; X m0, C + X V0 X^T) of the linearised rows (computed here densely)."""
    data = run.data
    truth = run.truth.theta(data.freq_hz)
    sd = np.array([50.0, 50.0, 50.0, 100.0, 20.0])
    solution = solve_bayesian_per_channel(data, prior_mean=truth, prior_sd=sd, iterations=1)
    assert solution.log_evidence is not None
    temps, q, var_q = data.stacked()
    rows = linearise(data.terms(), temps, q, var_q, least_squares.mean)
    for k in (0, 137, 409):
        x, y, w = rows.features[:, k], rows.response[:, k], rows.weights[:, k]
        marginal = stats.multivariate_normal(
            x @ truth[:, k], np.diag(1.0 / w) + x @ np.diag(sd**2) @ x.T
        )
        assert solution.log_evidence[k] == pytest.approx(marginal.logpdf(y), abs=1e-6)
        precision = x.T @ np.diag(w) @ x + np.diag(1.0 / sd**2)
        mean = np.linalg.solve(precision, x.T @ (w * y) + truth[:, k] / sd**2)
        np.testing.assert_allclose(solution.mean[:, k], mean, rtol=1e-9, atol=1e-9)


def test_uniform_prior_evidence_is_the_wide_prior_limit(
    run: SimulatedRun, bayes: ChannelSolution
) -> None:
    sd = np.full(5, 1e6)
    wide = solve_bayesian_per_channel(run.data, prior_sd=sd)
    assert bayes.log_evidence is not None
    assert wide.log_evidence is not None
    volume = float(np.sum(np.log(sd * np.sqrt(2 * np.pi))))
    np.testing.assert_allclose(wide.log_evidence, bayes.log_evidence - volume, atol=1e-4)


def test_noiseless_validation_source_calibrated_within_errors(
    run: SimulatedRun, bayes: ChannelSolution
) -> None:
    data = run.data
    cal = bayes.calibrate(data.freq_hz, data.gamma_rec, run.validation_noiseless)
    assert np.all(cal.std_measurement == 0.0)
    z = (cal.mean - run.validation_temperature_k) / cal.std_calibration
    assert float(np.mean(np.abs(z) < 4.0)) >= 0.99
    assert 0.6 <= float(np.mean(np.abs(z) < 1.0)) <= 0.76


def test_noisy_validation_source_total_error(run: SimulatedRun, bayes: ChannelSolution) -> None:
    data = run.data
    cal = bayes.calibrate(data.freq_hz, data.gamma_rec, run.validation, data.channel_width_hz)
    assert np.all(cal.std_measurement > 0.0)
    assert cal.dof == np.inf
    lo, hi = cal.interval(0.68)
    truth = run.validation_temperature_k
    inside = float(np.mean((lo <= truth) & (truth <= hi)))
    assert 0.6 <= inside <= 0.76


def test_calibration_between_channels_interpolates(
    run: SimulatedRun, bayes: ChannelSolution
) -> None:
    freq = run.data.freq_hz
    mid = 0.5 * (freq[:-1] + freq[1:])
    source = simulate_source(
        "ant",
        mid,
        reach_source_reflection("ant", mid),
        lna_reflection(mid, CONFIG.f_lo_hz, CONFIG.f_hi_hz),
        298.0,
        run.truth,
        Integration(600.0, 600.0, 600.0),
        CONFIG.channel_width_hz,
        None,
        known_temperature=False,
    )
    cal = bayes.calibrate(mid, lna_reflection(mid, CONFIG.f_lo_hz, CONFIG.f_hi_hz), source)
    z = (cal.mean - 298.0) / cal.std_calibration
    assert float(np.mean(np.abs(z) < 4.0)) >= 0.99
    # Averaging two independent channels: std ~ 1/sqrt(2) of a channel's.
    ratio = np.median(bayes.parameter_std(mid) / bayes.parameter_std(freq[:-1]), axis=1)
    np.testing.assert_allclose(ratio, np.sqrt(0.5), rtol=0.1)


def test_evaluate_interpolates_and_refuses_to_extrapolate(bayes: ChannelSolution) -> None:
    freq = bayes.freq_hz
    np.testing.assert_array_equal(bayes.evaluate(freq), bayes.mean)
    mid = bayes.evaluate(0.5 * (freq[3] + freq[4]))[:, 0]
    np.testing.assert_allclose(mid, 0.5 * (bayes.mean[:, 3] + bayes.mean[:, 4]), rtol=1e-12)
    with pytest.raises(ValueError, match=r"50\.000000-129\.882812 MHz"):
        bayes.evaluate(np.array([45e6, 90e6]))
    with pytest.raises(ValueError, match="outside"):
        bayes.parameter_std(131e6)


def test_samples_match_mean_and_std(run: SimulatedRun, bayes: ChannelSolution) -> None:
    rng = np.random.default_rng(SEED)
    freq = bayes.freq_hz[::41]
    draws = bayes.sample_parameters(freq, 4000, rng)
    assert draws.shape == (4000, 5, freq.size)
    std = bayes.parameter_std(freq)
    # 4000 draws: sample mean within 5 standard errors, sample std within 6%.
    assert np.all(np.abs(draws.mean(axis=0) - bayes.evaluate(freq)) < 5 * std / np.sqrt(4000))
    np.testing.assert_allclose(draws.std(axis=0), std, rtol=0.06)
    cal = bayes.calibrate(run.data.freq_hz, run.data.gamma_rec, run.validation_noiseless)
    spectra = cal.samples(4000, rng, calibration_only=True)
    assert spectra.shape == (4000, 410)
    np.testing.assert_allclose(spectra.std(axis=0), cal.std_calibration, rtol=0.06)


def test_fewer_than_five_calibrators_is_ill_posed(run: SimulatedRun) -> None:
    four = run.data.subset(["cold", "hot", "r25", "c10open"])
    with pytest.raises(IllPosedError, match="at least 5 calibrators"):
        solve_least_squares_per_channel(four)
    with pytest.raises(IllPosedError, match="got 4"):
        solve_bayesian_per_channel(four, prior_sd=np.full(5, 100.0))


def test_exactly_five_calibrators(run: SimulatedRun) -> None:
    five = run.data.subset(["cold", "hot", "r25", "c10open", "c10short"])
    ls = solve_least_squares_per_channel(five)
    assert np.all(np.isfinite(ls.mean))
    assert np.all(np.isinf(ls.parameter_std(five.freq_hz)))
    with pytest.raises(ValueError, match="undefined"):
        ls.sample_parameters(five.freq_hz, 2, np.random.default_rng(0))
    bayes = solve_bayesian_per_channel(five)
    np.testing.assert_allclose(bayes.mean, ls.mean, rtol=1e-6, atol=1e-6)
    assert np.all(np.isfinite(bayes.parameter_std(five.freq_hz)))
    assert bayes.log_evidence is not None
    assert np.all(np.isfinite(bayes.log_evidence))


def test_invalid_arguments(run: SimulatedRun) -> None:
    with pytest.raises(ValueError, match="iterations"):
        solve_bayesian_per_channel(run.data, iterations=0)
    with pytest.raises(ValueError, match="prior_sd"):
        solve_bayesian_per_channel(run.data, prior_mean=np.zeros(5))
    with pytest.raises(ValueError, match="shape"):
        solve_bayesian_per_channel(run.data, prior_sd=np.ones(4))
    with pytest.raises(ValueError, match="> 0"):
        solve_bayesian_per_channel(run.data, prior_sd=np.zeros(5))


def test_a_channel_whose_least_squares_t_ns_crosses_zero_still_gets_its_posterior():
    """6 calibrators, 10 ms a position: least squares puts T_NS <= 0 at a few channels
    (6 of 820 here), where the Gauss-Newton step cannot linearise; they start from the
    band's median T_NS instead, and the posterior still covers the truth (68 % +- 6)."""
    from calibration.model.noise_waves import INDEX
    from calibration.solve.per_frequency import solve_least_squares_per_channel

    config = SimulationConfig(
        calibrators=("cold", "hot", "r25", "r100", "c10open", "c10short"),
        integration_s=0.01,
        channel_width_hz=8 * 12207.03125,
    )
    run = simulate_run(config, rng=1)
    start = solve_least_squares_per_channel(run.data).mean[INDEX["NS"]]
    assert np.count_nonzero(start <= 0) >= 3
    solution = solve_bayesian_per_channel(run.data)
    sd = np.sqrt(np.diagonal(solution.covariance, axis1=1, axis2=2)).T
    z = (solution.mean - run.truth.theta(run.data.freq_hz)) / sd
    assert np.all(np.isfinite(z))
    assert np.all(np.abs(np.mean(np.abs(z) < 1, axis=1) - 0.68) < 0.06)
