"""Per-parameter prior scales set by the data (calibration.scale_fit)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.basis import PolynomialBasis
from calibration.model_fit import OrderChoice
from calibration.noise_waves import PARAMETERS
from calibration.normal_equations import build_normal_equations
from calibration.radiometric_solver import RadiometricPrior, linearise, solve_radiometric
from calibration.scale_fit import ParameterScales, fit_scales
from calibration.shrinkage import ShrinkagePrior
from calibration.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run

LEVELS = {"unc": 250.0, "cos": 190.0, "sin": 90.0, "NS": 1116.0, "L": 300.0}


def _truth(big: str, small: str, rng: np.random.Generator) -> dict[str, list[float]]:
    """Three terms each: ``big`` with tens of K of structure, ``small`` with tens of mK."""
    truth = {}
    for name, level in LEVELS.items():
        size = 30.0 if name == big else 0.03 if name == small else 1.0
        truth[name] = [level, *(size * rng.choice([-1.0, 1.0], 2) * rng.uniform(0.5, 1.0, 2))]
    return truth


def test_variances_follow_scale_and_decay():
    scales = ParameterScales((1.0, 2.0, 3.0, 4.0, 5.0), 0.1, 3000.0)
    v = scales.variances((1, 3, 1, 1, 2))
    assert v.shape == (1, 8)
    np.testing.assert_allclose(v[0], [3000.0**2, 3000.0**2, 4.0, 0.04, 3000.0**2,
                                      3000.0**2, 3000.0**2, 25.0])


@pytest.mark.parametrize(("big", "small", "seed"), [("NS", "cos", 1), ("unc", "sin", 2)])
def test_each_parameter_gets_the_scale_of_its_own_structure(big, small, seed):
    """Fitted at the truth's own linearisation, the scales follow each structure's size."""
    rng = np.random.default_rng(seed)
    config = SimulationConfig(
        channel_width_hz=32 * ITPM_CHANNEL_WIDTH_HZ, truth_coefficients=_truth(big, small, rng)
    )
    run = simulate_run(config, rng=seed)
    data, orders, prior = run.data, (4, 4, 4, 4, 4), ShrinkagePrior(per_parameter=True)
    temps, q, var_q = data.stacked()
    problem = linearise(data.terms(), temps, q, var_q, run.truth.theta(data.freq_hz))
    basis = PolynomialBasis.for_frequencies(data.freq_hz, "legendre")
    normal = build_normal_equations(
        problem.features, problem.weights, problem.response, basis.matrix(data.freq_hz, 4),
        orders, ridge=1.0 / prior.widest_variances(orders),
    )
    tau = dict(zip(PARAMETERS, fit_scales(normal, prior, None).tau_k, strict=True))
    assert tau[big] > 10.0 * tau[small]
    assert tau[big] > 3.0  # tens of K of structure against about 1 K elsewhere


def test_the_solver_takes_the_per_parameter_prior():
    """The option reaches the solve: a solution, averaged, with finite evidence."""
    config = SimulationConfig(channel_width_hz=64 * ITPM_CHANNEL_WIDTH_HZ)
    data = simulate_run(config, rng=3).data
    prior = RadiometricPrior(coefficients=ShrinkagePrior(per_parameter=True))
    solution = solve_radiometric(data, OrderChoice(max_orders=(5, 5, 5, 5, 5)), prior)
    assert np.isfinite(solution.posterior.log_evidence)
    assert solution.metadata["model_weights"]
