"""Adaptive calibration (issue 40): predictions, decisions, stops, contributions, a plan.

Small and seeded, on a family of random truths (random orders and term sizes) at coarse
channels (205: the calibration error depends on the band's information, not on its
channelisation); the ensembles are ``python -m benchmarks.adaptive``.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from calibration.choice.model_fit import OrderChoice
from calibration.core.constants import ITPM_CHANNEL_WIDTH_HZ, REACH_CALIBRATORS
from calibration.design.adaptive import FIXED_PRIOR, AdaptivePlanner, AdaptiveSettings
from calibration.design.contributions import contributions, plan
from calibration.design.information import antenna_information
from calibration.design.simulated import SimulatedReceiver
from calibration.model.basis import PolynomialBasis
from calibration.model.simulate import SimulationConfig, default_truth_coefficients
from calibration.solve.radiometric_solver import solve_radiometric

WIDTH = ITPM_CHANNEL_WIDTH_HZ * 32


def random_truth(rng: np.random.Generator) -> dict[str, list[float]]:
    """The REACH-like levels with 1-5 random terms of 0.05-5 K beyond them."""
    base = default_truth_coefficients(PolynomialBasis("legendre", 50e6, 130e6))
    truth = {}
    for name, coefficients in base.items():
        n = int(rng.integers(1, 6))
        terms = np.exp(rng.uniform(np.log(0.05), np.log(5.0), size=n - 1))
        truth[name] = [coefficients[0], *(rng.choice([-1.0, 1.0], size=n - 1) * terms)]
    return truth


def receiver(seed: int, calibrators: tuple[str, ...] = REACH_CALIBRATORS) -> SimulatedReceiver:
    rng = np.random.default_rng(seed)
    config = SimulationConfig(
        channel_width_hz=WIDTH, calibrators=calibrators, truth_coefficients=random_truth(rng)
    )
    return SimulatedReceiver(config, rng)


def first_pass(rx: SimulatedReceiver, planner: AdaptivePlanner) -> float:
    elapsed = 0.0
    for name, seconds in planner.first_pass(rx.config.calibrators):
        rx.measure(name, seconds)
        elapsed += planner.settings.cost_s(seconds)
    return elapsed


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_predicted_error_after_more_time_is_what_a_refit_finds(seed):
    """``V'_i(t)`` from the Gram update against the refit after measuring it (same model)."""
    rx = receiver(seed)
    planner = AdaptivePlanner(AdaptiveSettings(), rx.antenna_s11)
    first_pass(rx, planner)
    info, _ = planner.information(rx.data())
    rng = np.random.default_rng(seed)
    for i in rng.choice(len(info.names), size=2, replace=False):
        name, more = info.names[i], float(rng.choice([60.0, 300.0, 900.0]))
        predicted = info.after(int(i), more)
        assert predicted < info.variance()
        trial = copy.copy(rx)
        trial.sources = dict(rx.sources)
        trial.measure(name, more)
        refit = solve_radiometric(
            trial.data(), OrderChoice.fixed(info.orders), prior=FIXED_PRIOR, average=False,
            delay_terms=False,
        )
        actual = antenna_information(refit, trial.data(), rx.antenna_s11).variance()
        # s^2 and the linearisation point move with the new noise: a few per cent
        assert predicted == pytest.approx(actual, rel=0.05), name


def test_the_planner_stops_at_its_target_with_every_decision_logged():
    rx = receiver(4)
    settings = AdaptiveSettings(budget_s=40_000.0, refresh_every=3)
    planner = AdaptivePlanner(settings, rx.antenna_s11)
    elapsed = first_pass(rx, planner)
    target = 0.75 * planner.predict_mk(rx.data())
    planner = AdaptivePlanner(AdaptiveSettings(**{**settings.__dict__, "target_mk": target}),
                              rx.antenna_s11)
    while (decision := planner.decide(rx.data(), elapsed)).choice is not None:
        best = max(decision.candidates, key=lambda c: c.gain_per_s)
        assert decision.choice == best
        assert best.predicted_mk < decision.predicted_mk
        assert len(decision.candidates) == len(REACH_CALIBRATORS) * len(settings.durations_s)
        rx.measure(decision.choice.source, decision.choice.seconds)
        elapsed += settings.cost_s(decision.choice.seconds)
    assert decision.stop_reason == "target"
    assert decision.predicted_mk <= target < planner.decisions[0].predicted_mk
    assert [d.refreshed for d in planner.decisions][::3] == [True] * len(planner.decisions[::3])
    record = json.loads(json.dumps([d.as_record() for d in planner.decisions]))
    assert [r["step"] for r in record] == list(range(len(planner.decisions)))
    assert record[0]["choice"]["source"] in REACH_CALIBRATORS
    # the greedy choice spent its time unevenly: some calibrators earned more
    seconds = [s.integration.source_s for s in rx.sources.values()]
    assert max(seconds) > 2 * min(seconds)


def test_the_budget_stops_it_with_no_measurement_past_it():
    rx = receiver(5, ("cold", "hot", "c10open", "c10short", "r25", "c2r36"))
    settings = AdaptiveSettings(budget_s=2000.0, target_mk=1e-6)
    planner = AdaptivePlanner(settings, rx.antenna_s11)
    elapsed = first_pass(rx, planner)
    while (decision := planner.decide(rx.data(), elapsed)).choice is not None:
        assert all(elapsed + settings.cost_s(c.seconds) <= 2000.0 for c in decision.candidates)
        rx.measure(decision.choice.source, decision.choice.seconds)
        elapsed += settings.cost_s(decision.choice.seconds)
    assert decision.stop_reason == "budget"
    assert decision.candidates == ()
    assert 2000.0 - settings.cost_s(min(settings.durations_s)) < elapsed <= 2000.0


@pytest.mark.parametrize("seed", [6, 7])
def test_contributions_add_up_and_the_plan_beats_the_round_robin(seed):
    rx = receiver(seed)
    planner = AdaptivePlanner(AdaptiveSettings(), rx.antenna_s11)
    first_pass(rx, planner)
    info, _ = planner.information(rx.data())
    now = 1e3 * planner.kappa * np.sqrt(info.variance())
    parts = contributions(info, planner.kappa)
    assert sum(c.share for c in parts) == pytest.approx(1.0)
    assert all(c.share > 0 and c.without_mk > now for c in parts)
    result = plan(info, 0.5 * now, AdaptiveSettings(budget_s=1e6), planner.kappa)
    assert result.reached
    assert result.predicted_mk <= 0.5 * now
    assert result.instrument_s < result.round_robin_instrument_s
    assert min(result.seconds.values()) == 60.0


def test_a_band_of_interest_is_judged_on_its_channels_alone():
    rx = receiver(8)
    planner = AdaptivePlanner(AdaptiveSettings(), rx.antenna_s11)
    first_pass(rx, planner)
    data = rx.data()
    solution = solve_radiometric(data)
    whole = antenna_information(solution, data, rx.antenna_s11)
    edge = antenna_information(solution, data, rx.antenna_s11, band_hz=(50e6, 60e6))
    cal = solution.calibrate(data.freq_hz, data.gamma_rec, rx.antenna(298.0))
    inside = data.freq_hz <= 60e6
    for info, mask in ((whole, slice(None)), (edge, inside)):
        assert info.variance() == pytest.approx(np.mean(cal.std_calibration[mask] ** 2), rel=1e-3)
    with pytest.raises(ValueError, match="holds none"):
        antenna_information(solution, data, rx.antenna_s11, band_hz=(200e6, 300e6))


@pytest.mark.parametrize("seed", [9, 10])
def test_a_sky_antenna_is_predicted_at_its_own_temperatures_and_leans_on_the_hot_load(seed):
    """The sky (2500 K at 75 MHz, index -2.5) against a load at 298 K, on the same data.

    Its predicted variance is that of its calibrated spectrum (as for any antenna), and
    far larger: it lies some 3000-6000 K beyond calibrators within 100 K of ambient but
    the hot load, whose share of the information is then most of it (0.71-0.85 over
    seeds 9-12) where the 298 K load's was a few per cent (0.007-0.06).
    """
    rx = receiver(seed)
    planner = AdaptivePlanner(AdaptiveSettings(), rx.antenna_s11)
    first_pass(rx, planner)
    data = rx.data()
    solution = solve_radiometric(data)
    sky = AdaptiveSettings(antenna_temperature_k=2500.0, antenna_index=-2.5)
    temps = sky.antenna_temperatures(data.freq_hz)
    assert temps[np.argmin(abs(data.freq_hz - 75e6))] == pytest.approx(2500.0, rel=0.01)
    on_sky = antenna_information(solution, data, rx.antenna_s11, temps)
    on_load = antenna_information(solution, data, rx.antenna_s11)
    cal = solution.calibrate(data.freq_hz, data.gamma_rec, rx.antenna(temps))
    assert on_sky.variance() == pytest.approx(np.mean(cal.std_calibration**2), rel=1e-3)
    assert on_sky.variance() > 100 * on_load.variance()
    hot = data.names.index("hot")
    assert on_sky.shares()[hot] > 0.5 > 0.2 > on_load.shares()[hot]
    with pytest.raises(ValueError, match="index finite"):
        AdaptiveSettings(antenna_index=float("nan"))
