"""Per-parameter prior scales set by the data (calibration.choice.scale_fit)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import minimize

from calibration.choice.averaging import (
    mixture_posterior,
    select_components,
    with_smooth_hypothesis,
)
from calibration.choice.hypotheses import hypotheses_with_own_widths
from calibration.choice.model_fit import OrderChoice
from calibration.choice.parameter_scales import (
    evidence_gradient,
    maximise,
    maximise_each,
    width_log_prior,
)
from calibration.choice.scale_fit import (
    ParameterScales,
    fit_largest,
    fit_scales,
    log_occam,
    width_scale,
)
from calibration.model.basis import PolynomialBasis
from calibration.model.noise_waves import PARAMETERS
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run
from calibration.regression.conjugate import ScalePrior, solve
from calibration.regression.normal_equations import build_normal_equations
from calibration.regression.shrinkage import ShrinkagePrior, log_scale_density
from calibration.solve.radiometric_solver import RadiometricPrior, linearise, solve_radiometric

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


@pytest.fixture(scope="module")
def eight_cal_normal():
    """Normal equations of an 8-calibrator run with random structure, at (6, 6, 6, 6, 6)."""
    rng = np.random.default_rng(11)
    truth = {
        name: [level, *(rng.choice([-1.0, 1.0], 3) * 10 ** rng.uniform(-2, 1, 3))]
        for name, level in LEVELS.items()
    }
    config = SimulationConfig(
        channel_width_hz=32 * ITPM_CHANNEL_WIDTH_HZ, truth_coefficients=truth,
        calibrators=SimulationConfig().calibrators[:8],
    )
    run = simulate_run(config, rng=11)
    data, orders = run.data, (6, 6, 6, 6, 6)
    temps, q, var_q = data.stacked()
    problem = linearise(data.terms(), temps, q, var_q, run.truth.theta(data.freq_hz))
    basis = PolynomialBasis.for_frequencies(data.freq_hz, "legendre")
    return build_normal_equations(
        problem.features, problem.weights, problem.response, basis.matrix(data.freq_hz, 6),
        orders, ridge=1.0 / ShrinkagePrior().widest_variances(orders),
    )


@pytest.mark.parametrize("scale_prior", [None, ScalePrior(1.0, 2.0)])
def test_the_batched_evidence_is_the_conjugate_solvers(eight_cal_normal, scale_prior):
    """Every model's log evidence, batched by size, equals one conjugate solve's."""
    normal = eight_cal_normal
    scales = ParameterScales((3.0, 0.05, 0.8, 20.0, 1e-3), 0.5, 3000.0)
    rng = np.random.default_rng(2)
    models = [tuple(int(n) for n in rng.integers(1, 7, 5)) for _ in range(40)]
    models += [(1, 1, 1, 1, 1), (6, 6, 6, 6, 6)]
    fast = scales.log_evidences(normal, models, scale_prior)
    for orders, value in zip(models, fast, strict=True):
        variances = scales.variances(orders)[0]
        post = solve(normal, orders, np.zeros(variances.size), variances, scale_prior)
        assert value == pytest.approx(post.log_evidence, abs=1e-6)


def _objective(normal, prior, orders, held, free):
    """The widths' log posterior (or log evidence, without their prior) over ``free``."""
    log_prior = width_log_prior(prior, orders)

    def value(log_tau, decay):
        full = np.array(held, dtype=float)
        full[free] = log_tau
        scales = ParameterScales(tuple(np.exp(full)), decay, prior.constant_sd_k)
        out = scales.log_evidences(normal, [orders], None)[0]
        return out if log_prior is None else out + log_prior(full[None])[0][0]

    return value


@pytest.mark.parametrize("width_prior_k", [None, 10.0])
def test_the_fitted_scales_maximise_the_largest_models_evidence(eight_cal_normal, width_prior_k):
    """Against an independent search (every decay, derivative-free, from the middle of the
    range and from the fitted point): the fit is at least as good, so neither the decays
    it skips nor its start leave a better maximum behind. Type-II maximum likelihood, or
    the mode of the widths' posterior under their half-Cauchy prior."""
    normal = eight_cal_normal
    prior = ShrinkagePrior(per_parameter=True, width_hyperprior_k=width_prior_k)
    orders = normal.max_orders
    fitted = fit_scales(normal, prior, None)
    log_z = _objective(normal, prior, orders, np.zeros(5), list(range(5)))

    best = log_z(np.log(fitted.tau_k), fitted.decay)
    lo, hi = np.log(prior.tau_min_k), np.log(prior.tau_max_k)
    for decay in prior.decays:
        for start in (np.full(5, 0.5 * (lo + hi)), np.log(fitted.tau_k)):
            found = minimize(
                lambda x, decay=decay: -log_z(np.clip(x, lo, hi), decay), start,
                method="Nelder-Mead", options={"maxfev": 3000, "xatol": 1e-4, "fatol": 1e-6},
            )
            assert -found.fun <= best + 1e-3, (decay, -found.fun - best)


@pytest.mark.parametrize("width_prior_k", [None, 10.0])
def test_the_refit_maximises_the_chosen_models_evidence(eight_cal_normal, width_prior_k):
    """Refitted at a smaller model, the widths of its parameters with higher terms are at
    least as good as an independent search's (every decay, derivative-free); a parameter
    with one term there keeps the width fitted at the largest model."""
    normal = eight_cal_normal
    prior = ShrinkagePrior(per_parameter=True, width_hyperprior_k=width_prior_k)
    orders = (3, 1, 4, 2, 1)
    first = fit_scales(normal, prior, None)
    refitted = fit_scales(normal, prior, None, orders=orders, start=first)
    held = [k for k, n in enumerate(orders) if n == 1]
    free = [k for k, n in enumerate(orders) if n > 1]
    assert [refitted.tau_k[k] for k in held] == [first.tau_k[k] for k in held]
    log_z = _objective(normal, prior, orders, np.log(np.asarray(first.tau_k)), free)

    best = log_z(np.log(np.asarray(refitted.tau_k))[free], refitted.decay)
    assert best > log_z(np.log(np.asarray(first.tau_k))[free], first.decay) + 0.1
    lo, hi = np.log(prior.tau_min_k), np.log(prior.tau_max_k)
    for decay in prior.decays:
        found = minimize(
            lambda x, decay=decay: -log_z(np.clip(x, lo, hi), decay),
            np.log(np.asarray(first.tau_k))[free],
            method="Nelder-Mead", options={"maxfev": 3000, "xatol": 1e-4, "fatol": 1e-6},
        )
        assert -found.fun <= best + 1e-3, (decay, -found.fun - best)


def test_own_widths_for_each_hypothesis_reduce_to_the_shared_pool(eight_cal_normal):
    """With the same widths for both hypotheses, the polynomials-and-smooth mixture built
    hypothesis by hypothesis is the one pool of :func:`with_smooth_hypothesis`: the same
    weights, mean and covariance (to the share noted below). The polynomials' evidences
    are set near the largest model's (its own as the smooth component is solved): the
    smooth functions have one model's prior (averaging.smooth_prior_share), so that both
    hypotheses and several orders carry weight."""
    normal = eight_cal_normal
    scales = ParameterScales((3.0, 0.05, 0.8, 20.0, 1e-3), 0.5, 3000.0)
    full, box = normal.max_orders, 6**5
    lifts = {(2, 1, 2, 3, 1): 0.4, (2, 2, 2, 3, 1): 0.0, (3, 1, 2, 3, 2): 1.0,
             (4, 2, 3, 3, 1): -0.4, full: 0.0}
    variances = scales.variances(full)[0]  # as the smooth component is solved
    z_full = solve(normal, full, np.zeros_like(variances), variances, None).log_evidence
    grids = {m: np.array([z_full + lift]) for m, lift in lifts.items()}
    joined = hypotheses_with_own_widths(normal, grids, full, box, (scales, scales), None, 0.0)
    pooled = mixture_posterior(
        normal, select_components(with_smooth_hypothesis(grids, full, box)), scales, None, 0.0
    )
    # Equal to about 1 / box: the two ways count the largest model's own polynomial share
    # alike (one model's prior), up to the components averaging.MASS leaves out.
    assert pooled.model_weights() == pytest.approx(joined.model_weights(), abs=1e-4)
    assert min(pooled.model_weights().values()) > 0.01  # every model carries weight
    np.testing.assert_allclose(joined.mean, pooled.mean, rtol=1e-3)
    sd = np.sqrt(np.diag(pooled.scale))
    assert np.max(np.abs(joined.scale - pooled.scale) / np.outer(sd, sd)) < 1e-3


@pytest.mark.parametrize("orders", [(6, 6, 6, 6, 6), (3, 1, 4, 2, 1)])
def test_one_batched_search_finds_each_decays_maximum(eight_cal_normal, orders):
    """The stacked search over every decay ends where a search per decay does: to 0.01
    nats at each decay (its shared stopping rule, with evidences from -4e6 to 3e3 nats
    here), and the fit, which polishes the best decay alone, to 1e-4 of their best. The
    objective is the widths' log posterior (the log evidence plus their prior)."""
    normal, prior = eight_cal_normal, ShrinkagePrior(per_parameter=True, width_hyperprior_k=10.0)
    bounds = (float(np.log(prior.tau_min_k)), float(np.log(prior.tau_max_k)))
    start = ParameterScales((1.0, 0.1, 3.0, 10.0, 0.01), 0.5, prior.constant_sd_k)
    starts = np.log(np.tile(start.tau_k, (len(prior.decays), 1)))
    log_prior = width_log_prior(prior, orders)
    batched = maximise_each(normal, orders, prior.decays, prior, None, starts, bounds, log_prior)
    alone = [
        maximise(normal, orders, decay, prior, None, x0, bounds, log_prior)
        for decay, x0 in zip(prior.decays, starts, strict=True)
    ]
    for decay, found, one in zip(prior.decays, batched, alone, strict=True):
        assert found is not None
        assert one is not None
        assert found[1] == pytest.approx(one[1], abs=0.01), decay
    fitted = fit_scales(normal, prior, None, orders=orders, start=start)
    held = np.log(np.asarray(fitted.tau_k))
    value = _objective(normal, prior, orders, held, [])([], fitted.decay)
    assert value >= max(one[1] for one in alone if one is not None) - 1e-4


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_parameter_without_structure_keeps_a_width_the_data_can_test(seed):
    """T_NS flat, the others with 0.5-2 K terms, 12 calibrators. Type-II maximum likelihood
    puts T_NS's width on the range's floor (1 mK: the data cannot tell any width below
    their reach from none, and the Occam factor keeps falling), where its higher terms
    cost nothing and carry no variance. Under the half-Cauchy prior whose scale the other
    widths set (the default), the mode of ``log tau`` is where the evidence starts to fall
    (the prior's density in ``log tau`` grows as ``tau``): between 1 and 20 posterior sd
    of T_NS's first-order term (measured 3.6-5.8; 3.6-6.1 under a fixed 10 K scale), while
    the structured parameters' widths move by under 20 % (measured up to 10 %; 16 %).
    The scale the widths set: 5.6-6.8 K."""
    rng = np.random.default_rng(seed)
    truth = {n: [v, *(rng.choice([-1.0, 1.0], 2) * rng.uniform(0.5, 2.0, 2))]
             for n, v in LEVELS.items()}
    truth["NS"] = [LEVELS["NS"]]
    config = SimulationConfig(channel_width_hz=32 * ITPM_CHANNEL_WIDTH_HZ, truth_coefficients=truth)
    run = simulate_run(config, rng=seed)
    data, orders = run.data, (6, 6, 6, 6, 6)
    temps, q, var_q = data.stacked()
    problem = linearise(data.terms(), temps, q, var_q, run.truth.theta(data.freq_hz))
    basis = PolynomialBasis.for_frequencies(data.freq_hz, "legendre")
    widest = ShrinkagePrior().widest_variances(orders)
    normal = build_normal_equations(
        problem.features, problem.weights, problem.response, basis.matrix(data.freq_hz, 6),
        orders, ridge=1.0 / widest,
    )
    ns = PARAMETERS.index("NS")
    type_ii = fit_scales(normal, ShrinkagePrior(width_scale_from_data=False), None)
    reference = solve(normal, orders, np.zeros_like(widest), widest, None)
    sd_first = np.sqrt(reference.covariance[6 * ns + 1, 6 * ns + 1])
    assert type_ii.tau_k[ns] == pytest.approx(ShrinkagePrior().tau_min_k)
    data_set, prior = fit_largest(normal, ShrinkagePrior(), None)
    fixed = fit_scales(normal, ShrinkagePrior(width_hyperprior_k=10.0), None)
    assert prior.width_hyperprior_k == pytest.approx(width_scale(type_ii, prior))
    for mode in (data_set, fixed):
        assert sd_first < mode.tau_k[ns] < 20 * sd_first
        for k in set(range(5)) - {ns}:
            assert mode.tau_k[k] == pytest.approx(type_ii.tau_k[k], rel=0.2)


def test_the_width_scale_is_the_half_cauchy_maximum_likelihood():
    """Two widths give their geometric mean; more, the root of the score equation (checked
    against a direct maximisation of the half-Cauchy log likelihood); one, itself; widths
    on the floor are left out, and with every width there, there is no scale."""
    prior = ShrinkagePrior()

    def scales(*tau):
        return ParameterScales(tuple(tau), 0.5, prior.constant_sd_k)

    floor = prior.tau_min_k
    assert width_scale(scales(0.1, 10.0, floor, floor, floor), prior) == pytest.approx(1.0)
    assert width_scale(scales(floor, floor, floor, floor, floor), prior) is None
    assert width_scale(scales(floor, 0.3, floor, floor, floor), prior) == pytest.approx(0.3)
    tau = np.array([0.03, 0.4, 2.0, 7.0, 30.0])

    def negative_log_likelihood(log_s):
        r2 = (tau / np.exp(log_s[0])) ** 2
        return float(np.sum(log_s[0] + np.log1p(r2)))

    best = minimize(negative_log_likelihood, [0.0], method="Nelder-Mead",
                    options={"xatol": 1e-10, "fatol": 1e-12})
    assert width_scale(scales(*tau), prior) == pytest.approx(np.exp(best.x[0]), rel=1e-6)


def _log_integral(normal, orders, widths, prior, points):
    """``log int Z(u) p(u) du`` over the structured parameters' ``log tau`` by quadrature."""
    structured = np.flatnonzero([n > 1 for n in orders])
    mode = np.log(np.asarray(widths.tau_k))
    lo, hi = np.log(prior.tau_min_k), np.log(prior.tau_max_k)
    axes = [np.linspace(max(lo, mode[k] - 6.0), min(hi, mode[k] + 6.0), points) for k in structured]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, structured.size)
    rows = np.repeat(mode[None, :], grid.shape[0], axis=0)
    rows[:, structured] = grid
    _, log_z, _ = evidence_gradient(normal, orders, rows, widths.decay, prior, None)
    log_p = np.sum(log_scale_density(grid, prior, prior.width_hyperprior_k), axis=1)
    f = (log_z + log_p).reshape([points] * structured.size)
    top = float(np.max(f))
    integral = np.exp(f - top)
    for axis in axes[::-1]:
        integral = np.trapezoid(integral, axis, axis=-1)
    return top + float(np.log(integral))


@pytest.mark.parametrize(
    ("orders", "points"), [((1, 1, 1, 4, 1), 601), ((3, 1, 1, 4, 1), 121), ((1, 4, 1, 3, 1), 121)]
)
def test_the_occam_factor_integrates_the_evidence_over_the_widths(eight_cal_normal, orders, points):
    """The widths' mode plus Laplace's Occam factor is the evidence with the widths
    marginalised under their half-Cauchy prior, as quadrature over log tau gives it."""
    normal = eight_cal_normal
    prior = replace(ShrinkagePrior(), width_hyperprior_k=1.0)
    widths = fit_scales(normal, prior, None, orders=orders)
    at_mode = widths.log_evidences(normal, [orders], None)[0]
    laplace = at_mode + log_occam(normal, orders, widths, prior, None)
    exact = _log_integral(normal, orders, widths, prior, points)
    # Measured 0.04-0.10 nats apart (the evidence is skewed in log tau), where the factor
    # itself is 3.4-8 nats: without its determinant the sum would be off by several.
    assert laplace == pytest.approx(exact, abs=0.2)


def test_each_hypothesis_takes_its_own_occam_factor(eight_cal_normal):
    """The widths' Occam factors move the odds between the hypotheses by their difference
    and leave the weights within the polynomials as they were."""
    normal = eight_cal_normal
    scales = ParameterScales((3.0, 0.05, 0.8, 20.0, 1e-3), 0.5, 3000.0)
    full, box = normal.max_orders, 6**5
    variances = scales.variances(full)[0]
    z_full = solve(normal, full, np.zeros_like(variances), variances, None).log_evidence
    grids = {(2, 1, 2, 3, 1): np.array([z_full + 9.0]), (3, 1, 2, 3, 2): np.array([z_full + 9.5])}

    def weights(occam):
        joined = hypotheses_with_own_widths(
            normal, grids, full, box, (scales, scales), None, 0.0, occam
        )
        return joined.model_weights()

    plain, moved = weights((0.0, 0.0)), weights((-1.0, -3.0))
    smooth_odds = [w[full] / (1.0 - w[full]) for w in (plain, moved)]
    assert smooth_odds[1] / smooth_odds[0] == pytest.approx(np.exp(-2.0), rel=1e-6)
    polynomial = [(2, 1, 2, 3, 1), (3, 1, 2, 3, 2)]
    ratios = [w[polynomial[1]] / w[polynomial[0]] for w in (plain, moved)]
    assert ratios[1] == pytest.approx(ratios[0], rel=1e-9)
