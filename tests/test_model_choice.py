"""Model choice: the hierarchical prior's evidence, the joint search, the averaged posterior.

* the evidence over the prior's grid by one eigendecomposition equals the conjugate
  solver's at every grid point (eq. 3.35);
* a batch of models scores as each model alone, one model under many priors solves as
  under each;
* the joint search ends where no single or paired move improves, and finds the
  evidence-best model of an exhaustive grid on simulated runs, from the smallest model
  and from where the solver starts it;
* the mixture's moments are the law of total variance, and its samples follow them;
* a term injected below the old prior's detection threshold: the averaged predictive
  covers the truth at the nominal rate where the old choice did not.
"""

import itertools

import numpy as np
import pytest

from calibration.choice.averaging import MixturePosterior, mixture_of, with_smooth_hypothesis
from calibration.choice.model_fit import OrderChoice
from calibration.choice.order_search import search_orders_jointly, significant_orders
from calibration.choice.parameter_scales import draw_scales, evidence_gradient
from calibration.core.errors import IllPosedError
from calibration.model.polynomial_model import full_indices
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run
from calibration.regression.conjugate import (
    CoefficientPrior,
    LinearPosterior,
    ScalePrior,
    solve,
    solve_many,
)
from calibration.regression.shrinkage import (
    EvidenceGrid,
    ShrinkagePrior,
    log_evidence_scales,
    log_scale_density,
    marginal_log_evidence,
)
from calibration.solve.noise_floor import noise_floor
from calibration.solve.radiometric_solver import RadiometricPrior, solve_radiometric

COARSE = ITPM_CHANNEL_WIDTH_HZ * 8  # 820 channels: the same physics, faster runs
RANDOM_RUNS = 30


def normal_equations_of(data, largest=(6, 6, 6, 6, 6)):
    """The radiometric solver's normal equations for ``data`` (its own ``build``)."""
    from calibration.model.basis import PolynomialBasis
    from calibration.regression.normal_equations import evaluate_coefficients
    from calibration.solve.radiometric_solver import LinearisedProblem, _normal_equations, linearise

    basis = PolynomialBasis.for_frequencies(data.freq_hz, "legendre")
    b = basis.matrix(data.freq_hz, max(largest))
    terms, (temps, q, var_q) = data.terms(), data.stacked()
    ridge = 1.0 / ShrinkagePrior().widest_variances(largest)
    start = LinearisedProblem(terms.matrix(q), 1.0 / (terms.x_l**2 * 1e6 * var_q), temps)
    normal = _normal_equations(start, b, largest, ridge)
    for _ in range(2):
        theta = evaluate_coefficients(normal.reference, b, largest)
        normal = _normal_equations(linearise(terms, temps, q, var_q, theta), b, largest, ridge)
    return normal


@pytest.fixture(scope="module")
def normal():
    run = simulate_run(SimulationConfig(channel_width_hz=COARSE), rng=np.random.default_rng(3))
    return normal_equations_of(run.data)


@pytest.mark.parametrize("seed", range(4))
def test_the_grid_evidence_is_the_conjugate_evidence_at_every_width(normal, seed):
    rng = np.random.default_rng(seed)
    orders = tuple(int(n) for n in rng.integers(1, 7, size=5))
    prior = ShrinkagePrior(decays=(1.0, 0.2), n_scales=7)
    scale = ScalePrior(1.0, 2.0) if seed % 2 else None
    fast = log_evidence_scales(normal, orders, prior, scale)

    def conjugate(variances):
        try:
            return solve(normal, orders, np.zeros(variances.size), variances, scale).log_evidence
        except IllPosedError:
            return -np.inf

    direct = np.array([conjugate(v) for v in prior.variances(orders)])
    finite = np.isfinite(direct)
    assert finite.sum() >= len(direct) - 2
    np.testing.assert_allclose(fast[finite], direct[finite], rtol=1e-12, atol=1e-4)


def test_the_constant_terms_width_does_not_move_a_bayes_factor(normal):
    """Every model has the constants: their prior cancels between models."""
    a, b = (3, 3, 3, 3, 3), (4, 3, 4, 4, 3)
    factors = []
    for width in (300.0, 3000.0, 30000.0):
        prior = ShrinkagePrior(constant_sd_k=width)
        za, zb = (log_evidence_scales(normal, o, prior, None) for o in (a, b))
        factors.append(marginal_log_evidence(zb) - marginal_log_evidence(za))
    assert max(factors) - min(factors) < 0.01


def test_a_joint_move_gets_past_a_ridge_that_stops_single_moves():
    """The stall of the issue: (2,3,3,3,3) beaten only by (3,3,3,2,3), two moves away."""

    def landscape(orders):
        o = np.asarray(orders, dtype=float)
        ridge = -10.0 * (o[0] + o[3] - 5.0) ** 2
        return float(ridge - (o[0] - 3) ** 2 - (o[3] - 2) ** 2 - np.sum((o[[1, 2, 4]] - 3) ** 2))

    stall = (2, 3, 3, 3, 3)
    singles = [(*stall[:k], stall[k] + d, *stall[k + 1:]) for k in range(5) for d in (-2, -1, 1, 2)]
    assert all(landscape(s) < landscape(stall) for s in singles)
    found = search_orders_jointly(landscape, (1,) * 5, (6,) * 5, starts=[stall])
    grid = itertools.product(range(1, 7), repeat=5)
    assert found.best == max(grid, key=landscape) == (3, 3, 3, 2, 3)


@pytest.mark.parametrize("seed", range(3))
def test_the_search_finds_the_exhaustive_best_on_simulated_runs(seed):
    rng = np.random.default_rng(40 + seed)
    coefficients = {
        "unc": [250, -12, rng.normal(0, 2)], "cos": [190, 25, rng.normal(0, 2), 1.0],
        "sin": [90, -15], "NS": [1116, -28, rng.normal(0, 1)], "L": [300, 1.5],
    }
    config = SimulationConfig(
        channel_width_hz=COARSE, integration_s=120.0, truth_coefficients=coefficients
    )
    normal = normal_equations_of(simulate_run(config, rng=rng).data)
    prior = ShrinkagePrior()
    batch = EvidenceGrid(normal, prior, ScalePrior())

    def many(models):
        return [marginal_log_evidence(row) for row in batch.of(models)]

    def evidence(orders):
        return many([orders])[0]

    models = list(itertools.product(range(1, 6), repeat=5))
    exhaustive = dict(zip(models, many(models), strict=True))
    best = max(exhaustive, key=exhaustive.__getitem__)
    # From the smallest model, as the thesis's climb starts, and from where the solver
    # starts (order_search.significant_orders), one model at a time or a step's at once.
    start = significant_orders(normal, prior, (1,) * 5, (6,) * 5)
    for starts, scorer in (([], None), ([start], None), ([start], many)):
        found = search_orders_jointly(evidence, (1,) * 5, (6,) * 5, starts=starts, many=scorer)
        box = itertools.product(*(range(max(1, n - 1), min(6, n + 2)) for n in found.best))
        assert found.best == best or exhaustive[best] <= found.log_evidence + 1e-9
        assert all(evidence(o) <= found.log_evidence + 1e-9 for o in box)


def test_a_batch_of_models_scores_as_each_model_alone(normal):
    """Models grouped by their constants and sizes get the rows they get one at a time."""
    rng = np.random.default_rng(8)
    models = [tuple(int(n) for n in rng.integers(0, 7, size=5)) for _ in range(40)]
    models += [(1, 1, 1, 1, 1), (6, 6, 6, 6, 6), (0, 2, 0, 3, 1)]
    prior = ShrinkagePrior()
    together = EvidenceGrid(normal, prior, ScalePrior()).of(models)
    alone = np.array([log_evidence_scales(normal, o, prior, ScalePrior()) for o in models])
    assert np.array_equal(np.isfinite(together), np.isfinite(alone))
    finite = np.isfinite(alone)
    np.testing.assert_allclose(together[finite], alone[finite], rtol=1e-12, atol=1e-6)


def test_one_model_under_many_priors_solves_as_under_each(normal):
    orders = (4, 3, 4, 4, 3)
    variances = ShrinkagePrior().variances(orders)[::17]
    means = np.zeros_like(variances)
    for scale in (None, ScalePrior()):
        together = solve_many(normal, orders, means, variances, scale)
        for post, v in zip(together, variances, strict=True):
            alone = solve(normal, orders, np.zeros(v.size), v, scale)
            np.testing.assert_allclose(post.mean, alone.mean, rtol=1e-10, atol=1e-9)
            np.testing.assert_allclose(post.covariance, alone.covariance, rtol=1e-8, atol=1e-14)
            assert post.log_evidence == pytest.approx(alone.log_evidence, abs=1e-6)


def test_the_climb_starts_at_the_evidence_choice_when_every_term_is_clear():
    """The simulator's REACH-like receiver: every term far above the noise."""
    run = simulate_run(SimulationConfig(channel_width_hz=COARSE), rng=np.random.default_rng(5))
    normal = normal_equations_of(run.data, (8,) * 5)
    start = significant_orders(normal, ShrinkagePrior(), (1,) * 5, (8,) * 5)
    assert start == run.truth.parameters.orders == (4, 3, 4, 4, 3)
    assert significant_orders(normal, ShrinkagePrior(), (1,) * 5, (2,) * 5) == (2,) * 5


def test_the_mixture_has_the_moments_of_its_components_and_samples_them():
    run = simulate_run(
        SimulationConfig(channel_width_hz=COARSE, integration_s=120.0),
        rng=np.random.default_rng(7),
    )
    solution = solve_radiometric(run.data)
    post = solution.posterior
    assert isinstance(post, MixturePosterior)
    assert len(post.components) >= 2
    assert np.isclose(post.weights.sum(), 1.0)
    size = post.mean.size
    mean, second = np.zeros(size), np.zeros((size, size))
    means = np.zeros((len(post.components), size))
    variances = np.zeros_like(means)
    for i, (component, weight) in enumerate(zip(post.components, post.weights, strict=True)):
        idx = full_indices(component.orders, post.orders)
        m = np.zeros(size)
        m[idx] = component.mean
        means[i], variances[i, idx] = m, np.diag(component.covariance)
        mean += weight * m
        second += weight * np.outer(m, m)
        second[np.ix_(idx, idx)] += weight * component.covariance
    np.testing.assert_allclose(post.mean, mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(post.covariance, second - np.outer(mean, mean), atol=1e-9)
    draws = post.sample(200_000, np.random.default_rng(0))
    sd = np.sqrt(np.diag(post.covariance))
    assert np.all(np.abs(draws.mean(axis=0) - post.mean) <= 4 * sd / np.sqrt(len(draws)) + 1e-12)
    # A term only a light model has is a rare, heavy tail: its sample sd is as noisy as the
    # mixture's fourth central moment makes it, sd(s) ~ sqrt((m4 - var^2) / n) / (2 sd).
    d = means - post.mean
    m4 = post.weights @ (d**4 + 6.0 * d**2 * variances + 3.0 * variances**2)
    noise = np.sqrt(np.maximum(m4 - sd**4, 0.0) / len(draws)) / (2.0 * sd)
    assert np.all(np.abs(draws.std(axis=0) - sd) <= 5.0 * noise + 1e-12)
    assert tuple(solution.metadata["best_orders"]) == solution.best_orders
    weights = [w["weight"] for w in solution.metadata["model_weights"]]
    assert weights == sorted(weights, reverse=True)
    assert sum(weights) <= 1.0 + 1e-5


def test_the_mixture_covariance_keeps_small_variances_beside_large_levels():
    """Two components at a 1000 K level, 1 uK apart, each with a (1 uK)^2 variance: the
    mixture's variance is 1e-12 + w(1 - w) 1e-12 K^2. As ``E[c^2] - mean^2`` it cancels
    1e6 against 1e6 and comes out wrong by about 1e-10, even negative (a solve in CI
    then took the square root of a negative variance)."""
    levels = np.array([1000.0, 250.0])
    components = [
        LinearPosterior((1, 1, 0, 0, 0), levels + shift, np.eye(2) * 1e-12, np.inf, 0.0,
                        1.0, 0.0, 10)
        for shift in (np.array([0.0, 0.0]), np.array([1e-6, -1e-6]))
    ]
    mixed = mixture_of(components, np.array([0.3, 0.7]), 0.0, 10)
    expected = 1e-12 * (np.eye(2) + 0.21 * np.array([[1.0, -1.0], [-1.0, 1.0]]))
    np.testing.assert_allclose(mixed.covariance, expected, rtol=1e-6, atol=1e-18)


def test_a_term_below_the_old_threshold_is_covered_by_the_averaged_predictive():
    """T_NS's quadratic term at 3 posterior sigma: the fixed 3000 K prior drops it.

    With the 2-minute Dicke positions of the issue's simulator, the term's posterior sd
    is 0.25 K; the truth's term is 0.75 K (alternating in sign). Over 30 seeded runs, at
    8 channels each, the old choice's 68 % intervals cover the calibrated source's truth
    well below 68 % (57 %), the averaged predictive's at 68 % (69/93 %; the tolerances,
    6 and 3 points, are about 1.5 binomial sigma of the correlated channels at 30 runs:
    60 runs, which took twice the suite's time, gave the same verdicts).
    """
    base = {"unc": [250, -12, 6], "cos": [190, 25, -8], "sin": [90, -15, 10],
            "L": [300, 1.5, -0.8]}
    hits = {"old": [], "averaged": []}
    chosen = {"old": 0, "averaged": 0}
    for seed in range(30):
        term = 0.75 if seed % 2 else -0.75
        config = SimulationConfig(
            channel_width_hz=COARSE, integration_s=120.0,
            truth_coefficients={**base, "NS": [1116, -28, term]},
        )
        run = simulate_run(config, rng=np.random.default_rng(100 + seed))
        f, gr, truth = run.data.freq_hz, run.data.gamma_rec, run.validation_temperature_k
        solutions = {
            "old": solve_radiometric(
                run.data, prior=RadiometricPrior(coefficients=CoefficientPrior()), average=False
            ),
            "averaged": solve_radiometric(run.data),
        }
        channels = np.linspace(0, f.size - 1, 8).astype(int)
        for name, solution in solutions.items():
            calibrated = solution.calibrate(f, gr, run.validation_noiseless)
            hits[name].append([
                np.mean(calibrated.covers(truth, level, calibration_only=True)[channels])
                for level in (0.68, 0.95)
            ])
            chosen[name] += solution.best_orders[3] >= 3
    old, averaged = np.mean(hits["old"], axis=0), np.mean(hits["averaged"], axis=0)
    print(f"old {old}, averaged {averaged}, old kept the term {chosen['old']} times")
    assert chosen["old"] <= 5, chosen  # the old prior drops the term
    assert old[0] < 0.62, old
    assert abs(averaged[0] - 0.68) <= 0.06, averaged
    assert abs(averaged[1] - 0.95) <= 0.03, averaged


def test_fixed_orders_and_the_single_best_model_stay_available():
    run = simulate_run(SimulationConfig(channel_width_hz=COARSE), rng=np.random.default_rng(5))
    fixed = solve_radiometric(run.data, OrderChoice.fixed((4, 3, 4, 4, 3)))
    assert fixed.orders == fixed.best_orders == (4, 3, 4, 4, 3)
    single = solve_radiometric(run.data, average=False)
    assert single.orders == single.best_orders
    assert single.models_line() == ""


#: Four calibrators, 47 min a position, no VNA noise, and a truth of the suite's family
#: (``tests/test_coverage.py``, seed 2) whose T_cos has six terms.
STALL_CALIBRATORS = ("cold", "hot", "c2r36", "c2r91")
STALL_TRUTH = {
    "unc": [250.0, -0.1358],
    "cos": [190.0, 0.5549, -4.966, 80.07, -19.39, 46.90],
    "sin": [90.0, -0.4325],
    "NS": [1116.0, 3.512, 18.88, -2.878, 2.854],
    "L": [300.0, -0.0177, 0.0075, 0.6329, -0.0434, -0.1518],
}


@pytest.mark.parametrize("seed", range(6))
def test_a_climb_stalled_below_the_box_top_is_resumed_from_it(seed):
    """Four calibrators leave no term of the largest model's fit clear of zero, so the
    climb starts at the smallest model, and there every single or paired move is worse:
    it stopped at (1, 6, 5, 4, 1)-like models, thousands of nats below the box's top,
    and the single best model calibrated the antenna 780-1840 times the floor off in six
    seeds of six (the average was saved by the smooth hypothesis, its error bars 1.2-4.5x
    too wide). A climb whose best is below the box's top is resumed from the top: the
    best model is now within 1.0-2.8x the floor, the average within 1.0-2.1x and its error
    bars within 0.6-1.3x of its error."""
    config = SimulationConfig(
        channel_width_hz=32 * ITPM_CHANNEL_WIDTH_HZ, integration_s=2846.0,
        calibrators=STALL_CALIBRATORS, truth_coefficients=STALL_TRUTH,
    )
    run = simulate_run(config, rng=np.random.default_rng(seed))
    data = run.data
    floor = noise_floor(data, run.validation_noiseless, run.truth.parameters).rms
    for average, bound in ((False, 4.0), (True, 3.0)):
        cal = solve_radiometric(data, average=average).calibrate(
            data.freq_hz, data.gamma_rec, run.validation_noiseless
        )
        error = float(np.sqrt(np.mean((cal.mean - run.validation_temperature_k) ** 2)))
        assert error / floor < bound, average
        if average:
            assert 0.4 < error / float(np.sqrt(np.mean(cal.std**2))) < 2.0


def test_the_smooth_hypothesis_prior_splits_the_odds():
    """Polynomials share 1 - s over the box's models; the full model gets s more."""
    grids = {(1, 1, 1, 1, 1): np.zeros(3), (2, 2, 2, 2, 2): np.zeros(3)}
    priored = with_smooth_hypothesis(grids, (2, 2, 2, 2, 2), n_models=32, smooth_share=0.25)
    np.testing.assert_allclose(np.exp(priored[(1, 1, 1, 1, 1)]), 0.75 / 32)
    np.testing.assert_allclose(np.exp(priored[(2, 2, 2, 2, 2)]), 0.75 / 32 + 0.25)


def test_random_truths_with_weak_terms_are_covered_by_the_averaged_predictive():
    """An ensemble of truths: each parameter with 1-6 terms, each higher term's size
    log-uniform from 0.3 to 30 of its posterior sd, so that a third of them sit below two
    sigma, where the evidence of polynomials alone drops them (the single best model
    covered 54 %/82 % of its 68 %/95 % intervals over 40 such runs of the model-choice
    benchmark). Averaged, with the smooth-function hypothesis, the intervals cover near
    the nominal rates. 30 seeded runs at 205 channels, 8 channels each (60, at twice the
    suite's time, gave 59/90 % and 63/93 %; these 30 give 60/91 % and 64/94 %). Here, at
    60 runs, with a prior scale per parameter
    (the default), the best model covers 59/90 % and the average 65/93 % (its mixture's
    quantiles; 65/94 % read as mean +- z sd; with type-II
    widths 61/90 % and 65/95 %; with the widths fitted at the largest model alone 61/89 %
    and 66/94 %; the polynomials under widths refitted at their best, the smooth
    hypothesis too, 63/93 %; under one shared
    scale 59/88 % and 63/93 %; with the term sizes in the prior's shrunk sd, as the
    benchmark once drew them, the truths were weaker and the average covered 66/90 %).
    Since the smooth functions have one model's prior (1 / (n_models + 1), commit 6b527ee;
    bisected over the commits since, run by pytest in each one's own tree: the
    convergence and box-rule changes move nothing), the average covers 62.9/92.9 %; at
    the earlier even odds it covered 64.8/93.1 %, at odds of one to sqrt(n_models)
    63.3/92.9 %. Even odds gave the smooth functions 0.975-0.998 of the weight on exact
    quadratics (benchmarks/polynomial_truths.py), so the share stays and 68 % is held to
    6 points (2.4 binomial sigma at 60 runs, 1.7 at these 30; the model-choice benchmark's
    100 runs a family hold it tighter): the shortfall is the price of that choice.
    """
    from benchmarks.model_choice import Ensemble, draw_truth, pilot_sd

    # The benchmark's ensemble at a quarter of its channels (sizes in the sd of these).
    ensemble = Ensemble("random truths, 205 channels", channel_width_hz=COARSE * 4)
    sd = pilot_sd(ensemble)
    rng = np.random.default_rng(2026)
    hits = {"best": [], "averaged": []}
    for _ in range(RANDOM_RUNS):
        run = simulate_run(ensemble.config(draw_truth(ensemble, sd, rng)), rng=rng)
        f, gr, truth = run.data.freq_hz, run.data.gamma_rec, run.validation_temperature_k
        channels = np.linspace(0, f.size - 1, 8).astype(int)
        for name, average in (("best", False), ("averaged", True)):
            calibrated = solve_radiometric(run.data, average=average).calibrate(
                f, gr, run.validation_noiseless
            )
            hits[name].append([
                np.mean(calibrated.covers(truth, level, calibration_only=True)[channels])
                for level in (0.68, 0.95)
            ])
    best, averaged = np.mean(hits["best"], axis=0), np.mean(hits["averaged"], axis=0)
    print(f"best {best}, averaged {averaged}")
    assert best[0] < 0.62, best
    assert abs(averaged[0] - 0.68) <= 0.06, averaged
    assert averaged[1] >= 0.88, averaged
    assert averaged[1] - best[1] >= 0.02, (averaged, best)


def test_the_scale_prior_does_not_hang_on_the_grids_lower_end(normal):
    """Moving ``tau_min`` from 1 mK down 11 grid steps to 0.012 mK (the old points kept):
    under the half-Cauchy the marginal evidence of every model stays put (measured 5e-5
    nats); uniform in ``log tau`` it moves by at least the normalisation of the longer grid,
    log(49/38) = 0.254, and by more where the data do not bound ``tau`` from below (the
    bias that caused: shrinkage.py)."""
    default = ShrinkagePrior()
    step = (default.tau_max_k / default.tau_min_k) ** (1 / (default.n_scales - 1))
    models = [(1, 1, 1, 1, 1), (2, 1, 1, 1, 1), (3, 3, 3, 3, 3), (6, 6, 6, 6, 6)]

    def marginals(**fields):
        prior = ShrinkagePrior(**fields)
        rows = EvidenceGrid(normal, prior, ScalePrior()).of(models) + prior.log_grid_weights
        return np.array([marginal_log_evidence(row) for row in rows])

    for s in (10.0, None):
        near = marginals(scale_hyperprior_k=s)
        far = marginals(
            scale_hyperprior_k=s, tau_min_k=default.tau_min_k / step**11,
            n_scales=default.n_scales + 11,
        )
        moved = np.abs(far - near)[1:]  # the first has no higher term: nothing to move
        if s is None:
            # at least the longer grid's normalisation; exactly that where the data bound tau
            assert np.all(moved >= np.log(49 / 38) - 1e-9), moved
        else:
            assert np.all(moved < 0.02), moved


def test_the_grid_weights_are_the_scale_density(normal):
    """The grid's prior masses follow the density of ``log tau`` and sum to one per decay;
    uniform in ``log tau`` they are all equal (zero log weight)."""
    prior = ShrinkagePrior(scale_hyperprior_k=10.0)
    mass = np.exp(prior.log_grid_weights).reshape(len(prior.decays), prior.n_scales)
    np.testing.assert_allclose(mass.sum(axis=1), prior.n_scales)
    density = np.exp(log_scale_density(np.log(prior.scales_k), prior, prior.scale_hyperprior_k))
    np.testing.assert_allclose(mass[0] / mass[0].sum(), density / density.sum(), rtol=1e-12)
    assert np.argmax(density) == np.argmin(np.abs(prior.scales_k - 10.0))  # the mode at s
    np.testing.assert_array_equal(ShrinkagePrior().log_grid_weights, 0.0)


@pytest.mark.parametrize("scale_prior", [None, ScalePrior(1.0, 2.0)])
def test_the_evidence_gradient_in_the_parameter_scales_is_exact(normal, scale_prior):
    """MacKay's gradient of log Z in each parameter's log scale, against central differences."""
    orders, prior = normal.max_orders, ShrinkagePrior()
    x = np.log([0.5, 2.0, 0.1, 5.0, 1.0])
    _, _, grad = evidence_gradient(normal, orders, x[None], 0.5, prior, scale_prior)
    h = 1e-5
    steps = x[None] + h * np.vstack([np.eye(5), -np.eye(5)])
    _, log_z, _ = evidence_gradient(normal, orders, steps, 0.5, prior, scale_prior)
    np.testing.assert_allclose(grad[0], (log_z[:5] - log_z[5:]) / (2 * h), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("orders", [(3, 1, 3, 1, 1), (1, 4, 1, 2, 1)])
def test_the_drawn_scales_integrate_the_evidence_as_a_grid_does(normal, orders):
    """Two parameters with higher terms: the importance-sampled evidence with five scales
    marginalised equals a 60 x 60 quadrature over the two that matter (the other three
    scales move nothing and their prior integrates to one), summed over the decays."""
    prior, scale_prior = ShrinkagePrior(), ScalePrior(1.0, 2.0)
    shared = EvidenceGrid(normal, prior, scale_prior).of([orders])[0]
    draws = draw_scales(normal, orders, prior, scale_prior, shared, 0.0)
    assert draws is not None
    sampled = np.logaddexp.reduce(draws.log_weights)
    axis = np.linspace(np.log(prior.tau_min_k), np.log(prior.tau_max_k), 60)
    free = [k for k, n in enumerate(orders) if n > 1]
    a, b = np.meshgrid(axis, axis, indexing="ij")
    log_tau = np.zeros((a.size, 5))
    log_tau[:, free[0]], log_tau[:, free[1]] = a.ravel(), b.ravel()
    # The trapezoid rule in log tau, each node with tau's prior density there.
    trapezoid = np.r_[0.5, np.ones(58), 0.5] * (axis[1] - axis[0])
    along = np.log(trapezoid) + log_scale_density(axis, prior, prior.scale_hyperprior_k)
    log_weights = along[:, None] + along[None, :]
    per_decay = []
    for decay in prior.decays:
        _, log_z, _ = evidence_gradient(normal, orders, log_tau, decay, prior, scale_prior)
        grid = log_z.reshape(60, 60)
        per_decay.append(np.logaddexp.reduce((grid + log_weights).ravel()))
    quadrature = np.logaddexp.reduce(per_decay) - np.log(len(prior.decays))
    # The draws' effective sample size is 66-143 of 336 here, a standard error of about
    # 0.1 in log Z (measured -0.10 and -0.01 against the quadrature): three of them.
    assert abs(sampled - quadrature) < 0.3, (sampled, quadrature)
