"""A prior term by term (``TermPrior``): its widths, and every model of the box averaged.

* the widths follow the table, the last repeating, levels and parameters not named
  keeping the wide width; a bad table is refused;
* every model between the order limits is scored, each as the conjugate solver scores it
  alone (eq. 3.35), and the mixture weighs them by that evidence;
* truths drawn from the prior itself (random orders and term sizes): the averaged
  posterior, being then the exact Bayesian answer, covers them at the nominal rate.
"""

import itertools

import numpy as np
import pytest

from calibration.choice.averaging import MixturePosterior
from calibration.choice.model_fit import OrderChoice, fit
from calibration.model.noise_waves import PARAMETERS
from calibration.model.simulate import SimulationConfig, simulate_run
from calibration.regression.conjugate import CoefficientPrior, ScalePrior, TermPrior, solve
from calibration.solve.radiometric_solver import RadiometricPrior, solve_radiometric
from tests.test_model_choice import COARSE, normal_equations_of


def test_the_widths_follow_the_table_and_the_last_repeats():
    prior = TermPrior(sd_k=3000.0, term_sd_k={"NS": [2.0, 1.0], "unc": [5.0]})
    mean, var = prior.vectors((3, 1, 1, 4, 2))
    np.testing.assert_array_equal(mean, np.zeros(11))
    wide = 3000.0**2
    np.testing.assert_array_equal(
        var, [wide, 25.0, 25.0, wide, wide, wide, 4.0, 1.0, 1.0, wide, wide]
    )
    assert CoefficientPrior().vectors((3, 1, 1, 4, 2))[1].tolist() == [wide] * 11


@pytest.mark.parametrize(("bad", "says"), [
    ({"mean_k": {"NS": [1000.0]}}, "zero prior means"),
    ({"term_sd_k": {"T_NS": [1.0]}}, "unknown parameter 'T_NS'"),
    ({"term_sd_k": {"NS": []}}, "term widths of NS"),
    ({"term_sd_k": {"NS": [1.0, 0.0]}}, "term widths of NS"),
])
def test_a_bad_table_is_refused(bad, says):
    with pytest.raises(ValueError, match=says):
        TermPrior(**bad)


def test_every_model_of_the_box_is_scored_and_weighed_by_its_evidence():
    """Quadratic terms near the noise (2-minute positions), so that several models weigh."""
    truth = {"unc": [250, -2.0, 0.05], "cos": [190, 3.0], "sin": [90, -1.5, 0.05],
             "NS": [1116, -8.0, 0.1], "L": [300, 0.5]}
    config = SimulationConfig(channel_width_hz=COARSE, integration_s=120.0,
                              truth_coefficients=truth)
    run = simulate_run(config, rng=np.random.default_rng(8))
    largest = (3, 2, 3, 3, 2)
    normal = normal_equations_of(run.data, largest)
    prior = TermPrior(term_sd_k={k: [10.0, 0.3] for k in PARAMETERS})
    scale = ScalePrior()
    posterior, table = fit(normal, OrderChoice(max_orders=largest), prior, 1.0, scale)
    box = {tuple(m) for m in itertools.product(*(range(1, n + 1) for n in largest))}
    assert set(table) == box
    for orders in [(1, 1, 1, 1, 1), (3, 2, 3, 3, 2), (2, 1, 3, 2, 2)]:
        mean, var = prior.vectors(orders)
        alone = solve(normal, orders, mean, var, scale).log_evidence
        assert table[orders] == pytest.approx(alone, abs=1e-6)
    assert isinstance(posterior, MixturePosterior)
    weights = posterior.model_weights()
    assert len(weights) >= 3
    first = max(table, key=table.__getitem__)
    assert next(iter(weights)) == first
    for orders, weight in list(weights.items())[1:]:
        assert np.log(weights[first] / weight) == pytest.approx(
            table[first] - table[orders], abs=1e-6
        )
    best, _ = fit(normal, OrderChoice(max_orders=largest), prior, 1.0, scale, average=False)
    assert best.orders == first
    with pytest.raises(ValueError, match="59049 models between the order limits: at most 32768"):
        fit(normal, OrderChoice(max_orders=(9,) * 5), prior, 1.0, scale)  # refused before scoring


def test_truths_drawn_from_the_prior_are_covered_at_the_nominal_rate():
    """80 seeded runs whose orders (1-4 terms) and term sizes are drawn from the prior.

    Each higher term is Gaussian with an sd of 0.5 K to 3 K (falling with order), so some
    terms sit well below the data's reach and some far above; the averaged posterior is
    the Bayesian answer for such truths and should cover them at 68/95 % (8 channels a
    run). Measured over 150 runs at two other seeds: 68.3/94.2 % and 68.3/95.7 %,
    actual/predicted error 1.03 and 0.98, the 68 % coverage's sd over runs 0.021 (so
    0.03 at 80 runs: the tolerances are about 2.3 of it, and of the 95 %'s).
    """
    sds = {"unc": [3.0, 2.0, 1.0], "cos": [3.0, 1.5, 0.5], "sin": [2.0, 1.0, 0.5],
           "NS": [3.0, 2.0, 1.0], "L": [1.0, 0.5, 0.5]}
    levels = {"unc": 250.0, "cos": 190.0, "sin": 90.0, "NS": 1116.0, "L": 300.0}
    prior = RadiometricPrior(coefficients=TermPrior(term_sd_k=sds))
    box = OrderChoice(max_orders=(4,) * 5, ceiling=4)
    rng = np.random.default_rng(44)
    hits, ratios = [], []
    for _ in range(80):
        truth = {}
        for k, level in levels.items():
            n = int(rng.integers(1, 5))
            truth[k] = [level, *(rng.normal(size=n - 1) * np.asarray(sds[k][: n - 1]))]
        config = SimulationConfig(
            channel_width_hz=COARSE * 4, integration_s=120.0, truth_coefficients=truth
        )
        run = simulate_run(config, rng=rng)
        f, gr = run.data.freq_hz, run.data.gamma_rec
        calibrated = solve_radiometric(run.data, box, prior).calibrate(
            f, gr, run.validation_noiseless
        )
        channels = np.linspace(0, f.size - 1, 8).astype(int)
        error = calibrated.mean - run.validation_temperature_k
        hits.append([
            np.mean(calibrated.covers(
                run.validation_temperature_k, level, calibration_only=True
            )[channels])
            for level in (0.68, 0.95)
        ])
        ratios.append(np.mean(error**2) / np.mean(calibrated.std_calibration**2))
    covered, honesty = np.mean(hits, axis=0), float(np.sqrt(np.mean(ratios)))
    print(f"covered {covered}, actual/predicted {honesty:.3f}")
    assert abs(covered[0] - 0.68) <= 0.07, covered
    assert abs(covered[1] - 0.95) <= 0.03, covered
    assert 0.9 <= honesty <= 1.1, honesty
