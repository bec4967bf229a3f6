"""The reflections' errors in the calibrators' rows (calibration.regression.errors_in_variables)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.choice.model_fit import OrderChoice
from calibration.model.basis import PolynomialBasis
from calibration.model.noise_waves import design_terms
from calibration.model.reflection_noise import reflection_variance
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run
from calibration.regression.errors_in_variables import (
    MU_MAX,
    Identified,
    corrected,
    error_moments,
    identified_orders,
    row_errors,
    unidentified_share,
)
from calibration.regression.normal_equations import build_normal_equations, evaluate_coefficients
from calibration.solve.identifiability import CHOICE_SHARE
from calibration.solve.noise_floor import noise_floor
from calibration.solve.radiometric_solver import linearise, solve_radiometric

WIDTH = 8 * ITPM_CHANNEL_WIDTH_HZ  # 820 channels
VNA_SIGMA = 1e-3
#: Four calibrators, two of them reflective at |Gamma| ~ 0.3 only: one combination of the
#: five parameters is free in every channel, held by the polynomials' smoothness alone.
WEAK_SET = ("cold", "hot", "r25", "c2r91")
#: A truth of the model-choice benchmark's random set-ups (its structure drawn at 0.3-30
#: posterior sd of this weak set: T_cos's cubic term 157 K, T_sin's linear 245 K).
WEAK_TRUTH = {
    "unc": [250.0],
    "cos": [190.0, 35.87, 3.189, 156.7],
    "sin": [90.0, 245.3, 130.7],
    "NS": [1116.0, 23.63, 1.168, -0.4212],
    "L": [300.0, 0.0163, 0.2921, 0.1390, 0.02356],
}
BOX = (8, 8, 8, 8, 8)


def _weak_run(seed: int, vna_sigma: float = VNA_SIGMA):
    config = SimulationConfig(
        channel_width_hz=WIDTH, integration_s=135.0, calibrators=WEAK_SET,
        vna_sigma=vna_sigma, truth_coefficients=WEAK_TRUTH,
    )
    return simulate_run(config, rng=np.random.default_rng(seed))


@pytest.fixture(scope="module")
def rows_at_truth():
    """The solver's rows about the truth, their errors and normal equations at BOX."""
    run = _weak_run(0)
    data = run.data
    temps, q, var_q = data.stacked()
    theta = run.truth.theta(data.freq_hz)
    gammas = np.stack([s.gamma for s in data.sources.values()])
    extra = reflection_variance(
        theta[:, None, :], gammas, data.gamma_rec, q, data.reflection_errors(), data.gamma_rec_std
    )
    problem = linearise(data.terms(), temps, q, var_q, theta, extra)

    def rows(g, g_rec):
        p = linearise(design_terms(g, g_rec[None, :]), temps, q, var_q, theta)
        return p.features, p.response

    errors = row_errors(rows, gammas, data.gamma_rec, data.reflection_errors(), data.gamma_rec_std)
    basis = PolynomialBasis.for_frequencies(data.freq_hz, "legendre").matrix(data.freq_hz, 8)
    normal = build_normal_equations(
        problem.features, problem.weights, problem.response, basis, BOX,
        ridge=np.full(sum(BOX), 1e-8),
    )
    return run, rows, gammas, problem, errors, basis, normal, theta


def test_the_rows_error_variance_is_the_spread_under_drawn_reflection_errors(rows_at_truth):
    """``v(c)``, from the derivatives, against the rows' spread over 400 drawn reflection
    errors (every source's and the receiver's), at the truth and at a point 50 K away along
    T_cos and T_sin: the variance the least-squares fit can trade. 400 draws know a row's
    variance to 7 %; the weighted sum over 3280 rows, far better."""
    run, rows, gammas, problem, errors, _, _, theta = rows_at_truth
    data = run.data
    rng = np.random.default_rng(5)
    away = theta.copy()
    away[1] += 50.0
    away[2] -= 50.0
    for point in (theta, away):
        residuals = []
        for _ in range(400):
            def noise(shape):
                return VNA_SIGMA * (rng.standard_normal(shape) + 1j * rng.standard_normal(shape))
            g = gammas + noise(gammas.shape) / np.sqrt(2)
            g_rec = data.gamma_rec + noise(data.gamma_rec.shape) / np.sqrt(2)
            x, y = rows(g, g_rec)
            residuals.append(y - np.einsum("mnp,pn->mn", x, point))
        drawn = float(np.sum(problem.weights * np.var(residuals, axis=0)))
        assert errors.variance(problem.weights, point) == pytest.approx(drawn, rel=0.03)


def test_the_corrected_quadratic_form_is_the_chi2_less_the_traded_variance(rows_at_truth):
    """The corrected normal equations give ``chi2(c) - v(c) + v(c0)`` for any ``c``: the
    moment algebra (module docstring) checked at random coefficients."""
    _, _, _, problem, errors, basis, normal, theta = rows_at_truth
    moments = error_moments(errors, problem.weights, basis, BOX)
    fixed = corrected(normal, moments, errors, problem.weights, basis, theta)
    rng = np.random.default_rng(1)

    def quadratic(n, c):
        d = n.reference - c
        return n.chi2_ref + 2 * d @ n.cross + d @ n.gram @ d

    for _ in range(5):
        c = normal.reference + rng.normal(0.0, 0.3, normal.reference.size)
        curves = evaluate_coefficients(c, basis, BOX)
        expected = (
            quadratic(normal, c)
            - errors.variance(problem.weights, curves)
            + errors.variance(problem.weights, theta)
        )
        assert quadratic(fixed, c) == pytest.approx(expected, rel=1e-8)


def test_the_weak_set_identifies_its_true_orders_but_not_the_box(rows_at_truth):
    """``mu``, the errors' share of the apparent information, is small at the truth's
    orders, near one at the box, never larger in a sub-model (interlacing), and the cut
    box is identified and contains the truth's orders."""
    run, _, _, problem, errors, basis, normal, _ = rows_at_truth
    moments = error_moments(errors, problem.weights, basis, BOX).gram
    truth = run.truth.parameters.orders
    assert unidentified_share(normal.gram, moments, truth, BOX) < 0.01
    assert unidentified_share(normal.gram, moments, BOX, BOX) > 0.9
    rng = np.random.default_rng(2)
    for _ in range(10):
        big = tuple(int(n) for n in rng.integers(1, 9, 5))
        small = tuple(int(rng.integers(1, n + 1)) for n in big)
        assert unidentified_share(normal.gram, moments, small, BOX) <= (
            unidentified_share(normal.gram, moments, big, BOX) + 1e-9
        )
    cut, mu = identified_orders(normal.gram, moments, BOX, (1,) * 5)
    assert mu == unidentified_share(normal.gram, moments, cut, BOX) <= MU_MAX
    assert all(t <= c for t, c in zip(truth, cut, strict=True)), cut
    assert max(cut) - min(cut) <= 1  # shrunk from the top, evenly


def test_the_identified_models_reach_beyond_the_cut_box(rows_at_truth):
    """The identified models are a down-set, not a box: the weak set's cut box is
    (5, 5, 4, 5, 5), but the truth's orders with T_cos and T_sin raised to eight terms
    carry ``mu`` 5e-4. ``Identified`` admits those and every model of the box, not the
    whole box (8, 8, 8, 8, 8)."""
    _, _, _, problem, errors, basis, normal, _ = rows_at_truth
    moments = error_moments(errors, problem.weights, basis, BOX).gram
    cut, _ = identified_orders(normal.gram, moments, BOX, (1,) * 5)
    identified = Identified(cut, normal.gram, moments, BOX)
    beyond = (1, 8, 8, 4, 5)
    assert not all(n <= m for n, m in zip(beyond, cut, strict=True))
    assert identified.admits(beyond)
    assert identified.share(beyond) < 0.01
    assert not identified.admits(BOX)
    assert identified.admits(cut)


def test_a_smaller_largest_model_keeps_every_sub_models_quadratic_form(rows_at_truth):
    """``NormalEquations.within`` re-references the moments: ``chi^2`` of any sub-model
    at any coefficients is unchanged (to 1e-9 of its size)."""
    normal = rows_at_truth[6]
    inner = normal.within((5, 4, 6, 5, 4))
    rng = np.random.default_rng(5)
    for orders in [(1, 1, 1, 1, 1), (5, 4, 6, 5, 4), (2, 4, 3, 1, 4), (5, 1, 6, 2, 2)]:
        idx = normal.indices(orders)
        c = normal.reference[idx] + rng.normal(0.0, 0.1, idx.size)
        expected = normal.chi2(c, idx)
        assert inner.chi2(c, inner.indices(orders)) == pytest.approx(expected, rel=1e-9)
        np.testing.assert_allclose(inner.rhs(inner.indices(orders)), normal.rhs(idx), rtol=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_four_calibrators_with_vna_noise_calibrate_an_antenna_within_its_error_bars(seed):
    """Before the correction and the cut, the evidence chose (7, 6, 8, 5, 5)-like models
    here and the antenna came out 300-380 times the noise floor off, 14-17 times its error
    bars (the module docstring). Now within both, as with the true orders fixed."""
    run = _weak_run(seed)
    data = run.data
    floor = noise_floor(data, run.validation_noiseless, run.truth.parameters).rms
    solution = solve_radiometric(data)
    cal = solution.calibrate(
        data.freq_hz, data.gamma_rec, run.validation_noiseless, gamma_rec_std=data.gamma_rec_std
    )
    error = float(np.sqrt(np.mean((cal.mean - run.validation_temperature_k) ** 2)))
    predicted = float(np.sqrt(np.mean(cal.std**2)))
    assert error / floor < 1.5
    assert error / predicted < 1.5
    cut = solution.metadata["order_box_cuts"]
    assert cut[0]["asked"] == [8, 8, 8, 8, 8]
    assert cut[0]["why"] == "the reflections' errors decided them"


#: A truth of the suite's family (tests/test_coverage.py, seed 2026) that its four
#: calibrators identify (``mu`` 0.005) beyond the box they identify whole, (6, 5, 5, 6, 6):
#: T_cos has six terms.
BEYOND_TRUTH = {
    "unc": [250.0],
    "cos": [190.0, -0.750, -93.20, -22.39, 1.300, 8.257],
    "sin": [90.0, 19.22, 63.29],
    "NS": [1116.0, 1.465, 13.83, 1.925, -1.949],
    "L": [300.0, -0.2567, 0.0995],
}


def beyond_run(seed: int):
    """:data:`BEYOND_TRUTH` seen by its four calibrators (cold, hot, c2r27, c2r69), 105 s a
    position, VNA noise, 205 channels."""
    config = SimulationConfig(
        channel_width_hz=32 * ITPM_CHANNEL_WIDTH_HZ, integration_s=105.0,
        calibrators=("cold", "hot", "c2r27", "c2r69"), vna_sigma=VNA_SIGMA,
        truth_coefficients=BEYOND_TRUTH,
    )
    return simulate_run(config, rng=np.random.default_rng(seed))


@pytest.mark.parametrize("seed", range(0, 8, 2))  # every other seed: 0 and 6 are the hard ones
def test_a_truth_beyond_the_identified_box_is_found(seed):
    """Searched in the cut box alone, this truth was out of reach: in eight seeds of eight
    the antenna came out 33-56 times the noise floor off, 4.5-8 times its error bars.
    Searching the identified models beyond the box, with the widths refitted at each
    climb's end until the best stays, the single best model is the truth's orders (or
    one or two terms more) at 0.67-1.26x the floor, its error bars right (0.68-1.25x);
    the average is 0.73-4.7x the floor, its error bars wider than its error (0.24-0.85x).

    The average is wide because the data leave a second kind of model in play: T_sin with
    one or more terms than the truth's three, alone or with T_cos's structure traded into
    it ((1, 4, 7, 4, x)). Each such component is 4-17x the floor off and carries 0.4-39 %
    of the weight (seed 6 the most); the truth's neighbours are 0.9-1.1x. In seed 6 with
    no VNA noise the truth leads (1, 4, 7, 4, 3) by 7 nats; with it, by 1.8 (and trails
    by 0.6 in seed 0): the reflections' errors take the information that told them apart.
    Solved alone over the eight seeds, (1, 6, 4, 5, 3) and (1, 6, 5, 5, 3) are 1-10x the
    floor with error bars right on average (actual / predicted RMS 0.92, 1.04; (1, 7, 4,
    5, 3) 1.54), so the width is mostly the choice's real uncertainty. The statements are
    over the eight seeds 0-7; the suite runs the even four (its time), the odd ones held
    the same bounds when last run (``range(8)``)."""
    run = beyond_run(seed)
    data = run.data
    floor = noise_floor(data, run.validation_noiseless, run.truth.parameters).rms
    for average in (False, True):
        cal = solve_radiometric(data, average=average).calibrate(
            data.freq_hz, data.gamma_rec, run.validation_noiseless,
            gamma_rec_std=data.gamma_rec_std,
        )
        error = float(np.sqrt(np.mean((cal.mean - run.validation_temperature_k) ** 2)))
        honesty = error / float(np.sqrt(np.mean(cal.std**2)))
        if average:
            assert error / floor < 6.0
            assert honesty < 1.2
            if error / floor > 2.0:  # seeds 0 and 6: the summary says the models disagree
                assert cal.model_choice_share >= CHOICE_SHARE
        else:
            assert error / floor < 1.6
            assert 0.5 < honesty < 1.5


def test_fixed_orders_the_calibrators_cannot_identify_are_refused():
    """Fixed orders the reflections' errors would decide raise, naming the share."""
    from calibration.core.errors import IllPosedError

    with pytest.raises(IllPosedError, match="above their reflections' errors"):
        solve_radiometric(_weak_run(0).data, orders=OrderChoice.fixed(BOX))


def test_without_reflection_errors_nothing_is_cut():
    """No VNA noise known: the normal equations are the plain ones (no cut, no entry)."""
    run = simulate_run(SimulationConfig(channel_width_hz=WIDTH), rng=np.random.default_rng(0))
    solution = solve_radiometric(run.data)
    assert "order_box_cuts" not in solution.metadata
