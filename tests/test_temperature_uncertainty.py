"""Uncertain calibrator temperatures: marginalised exactly, and honest posteriors result."""

from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from calibration import OrderChoice, solve_radiometric
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run
from calibration.regression.normal_equations import build_normal_equations
from calibration.solve.noise_floor import noise_floor


@pytest.mark.parametrize("orders", [(2, 1, 2, 1, 2), (3, 0, 4, 1, 2), (1, 1, 1, 1, 1)])
def test_rank_one_corrections_equal_the_full_covariance(orders):
    """Moments with marginalised offsets match a brute-force GLS with D + s^2 11^T."""
    rng = np.random.default_rng(0)
    m, n = 3, 40
    features = rng.normal(size=(m, n, 5))
    weights = rng.uniform(0.5, 2.0, size=(m, n))
    response = rng.normal(size=(m, n))
    basis = np.asfortranarray(np.polynomial.legendre.legvander(np.linspace(-1, 1, n), 4))
    variances = np.array([0.3, 0.0, 2.0])
    ref = rng.normal(size=sum(orders))
    fast = build_normal_equations(
        features, weights, response, basis, orders, reference=ref, offset_variance=variances
    )
    # Brute force: the design matrix, the residual about ref, the block covariance.
    columns = []
    for k, order in enumerate(orders):
        for j in range(order):
            columns.append((features[..., k] * basis[:, j]).reshape(-1))
    x = np.stack(columns, axis=1)
    r = response.reshape(-1) - x @ ref
    cov = np.zeros((m * n, m * n))
    for i in range(m):
        block = slice(i * n, (i + 1) * n)
        cov[block, block] = np.diag(1 / weights[i]) + variances[i]
    inv = np.linalg.inv(cov)
    np.testing.assert_allclose(fast.gram, x.T @ inv @ x, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(fast.cross, x.T @ inv @ r, rtol=1e-10, atol=1e-10)
    assert fast.chi2_ref == pytest.approx(float(r @ inv @ r), rel=1e-10)
    assert fast.sum_log_weights == pytest.approx(-np.linalg.slogdet(cov)[1], rel=1e-10)


CONFIG = SimulationConfig(channel_width_hz=ITPM_CHANNEL_WIDTH_HZ * 8)
SIGMA_K = 0.05  # a thermocouple's statistical error on a 10-minute mean


def offset_run(seed: int, declared: float):
    run = simulate_run(CONFIG, rng=seed)
    rng = np.random.default_rng(seed + 500)
    sources = {
        name: replace(
            s,
            temperature_k=s.temperature_k + SIGMA_K * rng.standard_normal(),
            temperature_std_k=declared,
        )
        for name, s in run.data.sources.items()
    }
    return run, replace(run.data, sources=sources)


def chi2_of_truth(run, data, delay_terms=True):
    truth = run.truth.parameters
    sol = solve_radiometric(data, OrderChoice.fixed(truth.orders), delay_terms=delay_terms)
    d = sol.posterior.mean - truth.coefficients
    return d @ np.linalg.solve(sol.posterior.covariance, d), d.size


def test_declared_uncertainty_makes_the_posterior_hold_the_truth():
    results = [chi2_of_truth(*offset_run(seed, SIGMA_K)) for seed in range(6)]
    chi2s, dof = [r[0] for r in results], [r[1] for r in results]
    # The chi^2 of the truth under the posterior follows chi^2(dof): its mean is dof.
    assert np.mean(chi2s) == pytest.approx(dof[0], rel=0.35)
    assert max(chi2s) < stats.chi2.ppf(0.999, dof[0])


def test_ignoring_it_makes_the_posterior_overconfident():
    """Undeclared offsets: the posterior is overconfident. The misfit check (binned
    residuals) is off: it sees the offsets as structure and widens the error bars for one
    seed of three; the test isolates the marginalisation."""
    results = [chi2_of_truth(*offset_run(seed, 0.0), delay_terms=False) for seed in range(3)]
    chi2s, dof = [r[0] for r in results], [r[1] for r in results]
    assert min(chi2s) > stats.chi2.ppf(0.999, dof[0])


def test_uncertainty_is_checked_and_survives_the_run_file(tmp_path):
    from calibration.core.errors import InvalidDataError
    from calibration.io.hdf5_io import read_run, write_run

    _, data = offset_run(0, SIGMA_K)
    write_run(tmp_path / "run.h5", data)
    back, _ = read_run(tmp_path / "run.h5")
    assert {s.temperature_std_k for s in back.sources.values()} == {SIGMA_K}
    bad = replace(data.sources["hot"], temperature_std_k=-1.0)
    with pytest.raises(InvalidDataError, match="temperature uncertainty"):
        bad.checked(data.freq_hz.size)


def test_the_noise_floor_counts_the_declared_temperature_errors():
    """Thermometer offsets are noise of the data: the Cramer-Rao floor marginalises them as
    the solver does, and the true-orders solution's error sits at that floor; a floor that
    ignored them is smaller (7x here). The error of one run rests on its twelve offsets,
    so error / floor scatters from 0.3 to 2.4 between runs: its RMS over 16 seeded runs is
    known to about 11 %, and the tolerance is two of that."""
    ratios = []
    for seed in range(16):
        run, data = offset_run(seed, SIGMA_K)
        truth = run.truth.parameters
        source = run.validation_noiseless
        floor = noise_floor(data, source, truth)
        bare = noise_floor(run.data, source, truth)  # the same run, no offsets declared
        assert floor.rms > 1.5 * bare.rms
        sol = solve_radiometric(data, OrderChoice.fixed(truth.orders))
        calibrated = sol.calibrate(data.freq_hz, data.gamma_rec, source)
        error = calibrated.mean - run.validation_temperature_k
        ratios.append(np.sqrt(np.mean(error**2)) / floor.rms)
    assert float(np.sqrt(np.mean(np.square(ratios)))) == pytest.approx(1.0, abs=0.22)
