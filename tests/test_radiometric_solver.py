"""The radiometric solver: truth recovery, honest posteriors, the floor, basis independence."""

import numpy as np
import pytest
from scipy import stats

from calibration import OrderChoice, RadiometricPrior, noise_floor, solve_radiometric, solve_thesis
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run
from calibration.regression.conjugate import CoefficientPrior

SMALL = SimulationConfig(channel_width_hz=ITPM_CHANNEL_WIDTH_HZ * 8)


@pytest.fixture(scope="module")
def run():
    return simulate_run(SMALL, rng=21)


def test_noiseless_run_recovered_exactly():
    run = simulate_run(SMALL, rng=None)
    truth = run.truth.parameters
    sol = solve_radiometric(run.data, OrderChoice.fixed(truth.orders))
    f = run.data.freq_hz
    np.testing.assert_allclose(sol.evaluate(f), run.truth.theta(f), rtol=1e-7, atol=1e-6)


def test_truth_inside_posterior_at_true_orders(run):
    truth = run.truth.parameters
    sol = solve_radiometric(run.data, OrderChoice.fixed(truth.orders))
    d = sol.posterior.mean - truth.coefficients
    chi2 = d @ np.linalg.solve(sol.posterior.covariance, d)
    assert chi2 < stats.chi2.ppf(0.999, d.size)
    # Radiometer noise is the only noise: the fitted scale s^2 is 1 within its
    # sampling spread (sqrt(2/N) ~ 0.5% for ~10k rows; 3% allows 6 sigma).
    assert sol.posterior.noise_variance == pytest.approx(1.0, abs=0.03)


def test_evidence_recovers_truth_orders(run):
    sol = solve_radiometric(run.data)
    assert sol.best_orders == run.truth.parameters.orders
    assert len(sol.evidence_table) > 20


def test_posterior_calibration_error_equals_floor(run):
    # With s^2 fixed at 1 and the true orders, the posterior covariance is the inverse
    # Fisher information at the estimate: the calibration error bar of a source must be
    # its Cramer-Rao floor to within the (tiny) shift of the linearisation point.
    truth = run.truth.parameters
    sol = solve_radiometric(run.data, OrderChoice.fixed(truth.orders), RadiometricPrior(scale=None))
    val = run.validation_noiseless
    spectrum = sol.calibrate(run.data.freq_hz, run.data.gamma_rec, val)
    floor = noise_floor(run.data, val, truth)
    np.testing.assert_allclose(spectrum.std_calibration, floor.std, rtol=0.01)


def test_beats_thesis_solver_on_average():
    cfg = SimulationConfig(channel_width_hz=ITPM_CHANNEL_WIDTH_HZ * 8)
    ratios = []
    for seed in range(8):
        run = simulate_run(cfg, rng=100 + seed)
        f, val = run.data.freq_hz, run.validation_noiseless
        errs = []
        for solver in (solve_radiometric, solve_thesis):
            cal = solver(run.data).calibrate(f, run.data.gamma_rec, val).mean
            errs.append(np.sqrt(np.mean((cal - run.validation_temperature_k) ** 2)))
        ratios.append(errs[0] / errs[1])
    assert np.median(ratios) < 1.0


def test_basis_choice_does_not_change_calibration(run):
    """The same model space in two bases: under the fixed wide prior the calibration is the
    same; the hierarchical prior's widths are set in each basis's own coefficients (its
    decay is smoothness in Legendre terms), so there it may differ, but by far less than
    the error bars (measured: 0.043 of the smallest sd)."""
    orders = OrderChoice.fixed(run.truth.parameters.orders)
    f, val = run.data.freq_hz, run.validation_noiseless
    for prior, tolerance in ((RadiometricPrior(coefficients=CoefficientPrior()), 0.01),
                             (RadiometricPrior(), 0.1)):
        legendre = solve_radiometric(run.data, orders, prior).calibrate(f, run.data.gamma_rec, val)
        power = solve_radiometric(run.data, orders, prior, basis_kind="power").calibrate(
            f, run.data.gamma_rec, val
        )
        np.testing.assert_allclose(
            power.mean, legendre.mean, atol=tolerance * legendre.std_calibration.min()
        )
        np.testing.assert_allclose(
            power.std_calibration, legendre.std_calibration, rtol=tolerance
        )


def test_underestimated_noise_inflates_error_bars(run):
    # Halve every integration time in the metadata: the data are twice as noisy as the
    # radiometer equation now claims, and the fitted s^2 must find that out (about 2).
    from dataclasses import replace

    from calibration import Integration

    doubled = Integration(2 * SMALL.integration_s, 2 * SMALL.integration_s, 2 * SMALL.integration_s)
    lying = replace(
        run.data,
        sources={n: replace(s, integration=doubled) for n, s in run.data.sources.items()},
    )
    sol = solve_radiometric(lying, OrderChoice.fixed(run.truth.parameters.orders))
    assert sol.posterior.noise_variance == pytest.approx(2.0, rel=0.05)
