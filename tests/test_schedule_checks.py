"""The run's checks on their own: test load, benchmark solution, RFI flags."""

import numpy as np
import pytest

from calibration import OrderChoice, solve_radiometric
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run
from reach_receiver.run.checks import compare_test_load, compare_with_benchmark

FREQ = np.linspace(40e6, 180e6, 1401)
LOAD = 0.008 * np.exp(1j * FREQ / 30e6)  # a -42 dB test load


def noisy(sigma, seed):
    rng = np.random.default_rng(seed)
    return LOAD + sigma * (rng.standard_normal(FREQ.size) + 1j * rng.standard_normal(FREQ.size))


def test_trace_noise_alone_passes_and_a_calibration_error_fails():
    # 2e-4 of noise (REACH's 1 kHz IFBW, 20 averages) is 2.5 % of this load per point.
    assert compare_test_load(noisy(2e-4, 1), LOAD, FREQ, 0.05).passed
    assert not compare_test_load(noisy(2e-4, 1), LOAD, FREQ, 0.05, smoothing=1).passed
    drifted = noisy(2e-4, 2) + 8e-4 * np.exp(1j * FREQ / 50e6)  # 10 % calibration error
    verdict = compare_test_load(drifted, LOAD, FREQ, 0.05)
    assert not verdict.passed
    assert verdict.value == pytest.approx(0.10, abs=0.03)


def test_statistics_order():
    values = {s: compare_test_load(noisy(2e-4, 3), LOAD, FREQ, 0.05, s).value
              for s in ("rms", "p95", "max")}
    assert values["rms"] < values["p95"] < values["max"]


@pytest.fixture(scope="module")
def two_solutions():
    config = SimulationConfig(channel_width_hz=ITPM_CHANNEL_WIDTH_HZ * 16)
    runs = [simulate_run(config, rng=seed) for seed in (1, 2)]
    orders = OrderChoice.fixed(runs[0].truth.parameters.orders)
    return runs[0].data.freq_hz, [solve_radiometric(r.data, orders) for r in runs]


def test_same_receiver_twice_agrees_within_five_percent(two_solutions):
    freq, (first, second) = two_solutions
    verdict = compare_with_benchmark(second, first, freq, 0.05)
    assert verdict.passed
    assert max(verdict.differences.values()) < 0.01


def test_changed_receiver_is_caught(two_solutions):
    freq, (first, _) = two_solutions
    config = SimulationConfig(
        channel_width_hz=ITPM_CHANNEL_WIDTH_HZ * 16,
        truth_coefficients={"unc": [250.0], "cos": [190.0], "sin": [90.0],
                            "NS": [1100.0], "L": [330.0]},  # T_L 10 % warmer
    )
    changed = solve_radiometric(simulate_run(config, rng=3).data)
    verdict = compare_with_benchmark(changed, first, freq, 0.05)
    assert not verdict.passed
    assert verdict.differences["L"] == pytest.approx(0.10, abs=0.02)
