"""The thesis's own self-consistency checks (section 4.2) on the thesis solver."""

import itertools

import numpy as np
import pytest
from scipy import stats
from simulations import (
    CONSTANT_TRUTH,
    SECOND_ORDER_TRUTH,
    TABLE_4_1_ORDER,
    thesis_style_run,
)

from calibration import OrderChoice, solve_thesis
from calibration.model.noise_waves import INDEX

CONSTANT = OrderChoice.fixed((1, 1, 1, 1, 1))


def _block(solution, names):
    idx = [INDEX[n] for n in names]  # one coefficient per parameter at constant orders
    return solution.posterior.mean[idx], solution.posterior.covariance[np.ix_(idx, idx)]


def test_cold_and_hot_in_tandem_recover_t_l_and_t_ns():
    """Section 4.2.1 / fig. 4.3: the two-load posterior of (T_L, T_NS) holds the truth."""
    data, _ = thesis_style_run(CONSTANT_TRUTH, ("cold", "hot"), seed=11)
    both = solve_thesis(data, CONSTANT)
    mean, cov = _block(both, ("L", "NS"))
    d = mean - np.array([298.0, 1200.0])
    # Joint 99% credible region of a 2-D Gaussian posterior.
    assert d @ np.linalg.solve(cov, d) < stats.chi2.ppf(0.99, 2)
    # Each load alone leaves the (T_L, T_NS) degeneracy of eqs. 3.23/3.26 open: its
    # posterior area is larger than the tandem's (fig. 4.3, grey and red vs blue).
    for single in ("cold", "hot"):
        alone = solve_thesis(data.subset([single]), CONSTANT, allow_prior_dominated=True)
        _, cov_alone = _block(alone, ("L", "NS"))
        assert np.linalg.det(cov_alone) > 10 * np.linalg.det(cov)


def test_more_calibrators_shrink_posteriors():
    """Section 4.2.2 / fig. 4.4: 4, 6, 8 calibrators give ever tighter posteriors."""
    data, _ = thesis_style_run(CONSTANT_TRUTH, TABLE_4_1_ORDER, seed=12)
    stds = []
    for n in (4, 6, 8):
        sol = solve_thesis(data.subset(TABLE_4_1_ORDER[:n]), CONSTANT)
        stds.append(np.sqrt(np.diag(sol.posterior.covariance)))
    stds = np.array(stds)
    assert np.all(stds[1] < stds[0])
    assert np.all(stds[2] < stds[1])
    # With all eight, the truth lies inside the joint 99% credible region of the five.
    sol = solve_thesis(data, CONSTANT)
    truth = np.array([CONSTANT_TRUTH[p][0] for p in ("unc", "cos", "sin", "NS", "L")])
    d = sol.posterior.mean - truth
    assert d @ np.linalg.solve(sol.posterior.covariance, d) < stats.chi2.ppf(0.99, 5)


@pytest.fixture(scope="module")
def second_order_data():
    return thesis_style_run(SECOND_ORDER_TRUTH, TABLE_4_1_ORDER, seed=13)


def test_evidence_peaks_at_second_order(second_order_data):
    """Section 4.2.3 / fig. 4.5: Occam's cliff peaks at the truth's three terms."""
    data, _ = second_order_data
    uniform = {
        n: solve_thesis(data, OrderChoice.fixed((n,) * 5)).posterior.log_evidence
        for n in range(1, 6)
    }
    assert max(uniform, key=uniform.get) == 3
    # The cliff: steep rise up to the truth, gentle fall after it.
    assert uniform[3] - uniform[2] > 10 * (uniform[3] - uniform[4])


def test_order_search_finds_global_maximum(second_order_data):
    """The per-parameter search reaches the best model of an exhaustive grid.

    T_cos has a zero linear term: a one-step climb from one term stalls on that plateau.
    The truth's quadratic terms of T_cos, T_sin and T_L are many sigma above the noise, so
    the evidence must find three terms there; those of T_unc and T_NS are near 1 sigma at
    this noise level, so the data may rightly prefer fewer.
    """
    data, _ = second_order_data
    sol = solve_thesis(data, OrderChoice(max_orders=(4, 4, 4, 4, 4)))
    grid = itertools.product(range(1, 5), repeat=5)
    exhaustive = {o: solve_thesis(data, OrderChoice.fixed(o)).posterior.log_evidence for o in grid}
    assert sol.orders == max(exhaustive, key=exhaustive.get)
    assert sol.orders[INDEX["cos"]] == 3
    assert sol.orders[INDEX["sin"]] == 3
    assert sol.orders[INDEX["L"]] == 3


def test_calibrated_ambient_load_within_one_sigma(second_order_data):
    """Section 4.2.4 / fig. 4.7: the calibrated ambient load lands within 1 sigma."""
    data, _ = second_order_data
    sol = solve_thesis(data)
    cold = data.sources["cold"]
    spectrum = sol.calibrate(data.freq_hz, data.gamma_rec, cold)
    # Band average against the predictive sigma of a band average (the homoscedastic noise
    # averages down; the calibration error does not).
    err = np.mean(spectrum.mean) - 298.0
    rows = spectrum.rows.mean(axis=0)
    sigma_mean = np.sqrt(
        rows @ sol.posterior.covariance @ rows + sol.posterior.noise_variance / data.n_channels
    )
    assert abs(err) < sigma_mean
    # The thesis's sigma (eq. 4.3) recovers the 1 K noise put on the temperatures.
    assert np.sqrt(sol.posterior.noise_variance) == pytest.approx(1.0, rel=0.03)
