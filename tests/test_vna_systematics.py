"""The VNA's data-sheet error (table 2.3) carried into the calibrated error bars.

The check of the propagation is the one that matters: readings off from the simulator's
true reflections by a draw of the same error model give calibrated temperatures whose
error against the simulator's truth the Monte-Carlo spread predicts, over an ensemble of
truths, calibrator sets and correlation lengths. Radiometer noise is off, so the
reflections' error is the only one.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calibration import simulate_run, solve_radiometric
from calibration.checks.vna_systematics import reflection_systematics
from calibration.choice.model_fit import OrderChoice
from calibration.core.errors import InvalidDataError
from calibration.model.measurement_uncertainty import VnaAccuracy, sample_reflections
from calibration.model.simulate import SimulationConfig
from calibration.solve.per_frequency import solve_least_squares_per_channel
from calibration.solve.solvers import refit
from calibration.solve.thesis_solver import solve_thesis

EIGHT = ("cold", "hot", "r25", "r100", "c2r27", "c2r69", "c10open", "c10r250")


def _config(calibrators: tuple[str, ...] | None = None) -> SimulationConfig:
    base = SimulationConfig(channel_width_hz=0.4e6, radiometer_noise=False)
    return base if calibrators is None else dataclasses.replace(base, calibrators=calibrators)


def _read_with_error(run, rng, correlation_hz):
    """The run as a VNA with the data sheet's error would have read it, and its antenna."""
    step = float(np.median(np.diff(run.data.freq_hz)))

    def draw(gamma):
        return sample_reflections(gamma, rng, 1, VnaAccuracy(), correlation_hz / step)[0]

    sources = {n: dataclasses.replace(s, gamma=draw(s.gamma)) for n, s in run.data.sources.items()}
    data = dataclasses.replace(run.data, sources=sources, gamma_rec=draw(run.data.gamma_rec))
    return data, dataclasses.replace(run.validation, gamma=draw(run.validation.gamma))


@pytest.mark.parametrize(
    ("calibrators", "correlation_hz"), [(None, 5e6), (EIGHT, 0.0), (None, 20e6)]
)
def test_the_spread_predicts_the_error_of_readings_off_by_the_data_sheet(
    calibrators, correlation_hz
):
    """Pooled over 6 truths: error / predicted has unit spread and 68 % of it inside 1.

    Tolerances: the channels are correlated over the correlation length, so 6 runs hold
    about 6 x 16 independent values at 5 MHz (fewer at 20 MHz): the spread of z is known
    to about 12 %, and 24 draws estimate each predicted std to 15 %.
    """
    z, ratio = [], []
    for seed in range(6):
        run = simulate_run(_config(calibrators), rng=seed)
        data, antenna = _read_with_error(run, np.random.default_rng(100 + seed), correlation_hz)
        orders = OrderChoice.fixed(run.truth.parameters.orders)
        solution = solve_radiometric(data, orders, average=False, allow_prior_dominated=True)
        error = (
            solution.calibrate(data.freq_hz, data.gamma_rec, antenna).mean
            - run.validation_temperature_k
        )
        spread = reflection_systematics(
            data, {"ant": antenna}, refit(solution), seed, 24, correlation_hz=correlation_hz
        )
        predicted = spread.std_k("ant")
        z.append(error / predicted)
        ratio.append(np.sqrt(np.mean(error**2) / np.mean(predicted**2)))
    pooled = np.concatenate(z)
    assert 0.8 < np.std(pooled) < 1.25
    assert 0.58 < np.mean(np.abs(pooled) < 1) < 0.78
    assert 0.7 < np.median(ratio) < 1.3


def test_the_spread_scales_with_the_data_sheet_bound():
    """Reading the bound as 4 sigma instead of 2 halves the systematic error (linear regime)."""
    run = simulate_run(_config(), rng=3)
    solution = solve_radiometric(run.data)
    resolve = refit(solution)
    targets = {"ant": run.validation}
    two = reflection_systematics(run.data, targets, resolve, 5, 24, VnaAccuracy(coverage=2.0))
    four = reflection_systematics(run.data, targets, resolve, 5, 24, VnaAccuracy(coverage=4.0))
    # same seed, same draws scaled by 1/2: the error halves up to the model's curvature
    np.testing.assert_allclose(two.std_k("ant") / four.std_k("ant"), 2.0, rtol=0.03)
    assert np.all(np.abs(two.bias_k("ant")) < two.std_k("ant"))
    assert "table 2.3" in two.describe()
    assert "24 draws" in two.describe()


@pytest.mark.parametrize("solver", ["thesis", "least_squares"])
def test_every_solver_refits_its_own_model(solver):
    run = simulate_run(_config(), rng=4)
    if solver == "thesis":
        solution = solve_thesis(run.data, OrderChoice.fixed((3, 3, 3, 3, 3)))
    else:
        solution = solve_least_squares_per_channel(run.data)
    spread = reflection_systematics(
        run.data, {"ant": run.validation}, refit(solution), 1, 8
    )
    std = spread.std_k("ant")
    assert std.shape == run.data.freq_hz.shape
    # the data sheet's 0.4-4 dB on every reflection moves the antenna by 0.1-20 K
    assert np.all(np.isfinite(std))
    assert 0.1 < np.sqrt(np.mean(std**2)) < 20


def test_a_spectrum_carries_the_draws_into_its_std_intervals_and_samples():
    run = simulate_run(_config(), rng=5)
    solution = solve_radiometric(run.data)
    spectrum = solution.calibrate(run.data.freq_hz, run.data.gamma_rec, run.validation)
    spread = reflection_systematics(run.data, {"ant": run.validation}, refit(solution), 2, 16)
    with_sys = spectrum.with_systematics(spread.deviations["ant"])
    np.testing.assert_allclose(with_sys.std_systematic, spread.std_k("ant"))
    np.testing.assert_allclose(
        with_sys.std**2, spectrum.std**2 + spread.std_k("ant") ** 2, rtol=1e-12
    )
    lo, hi = with_sys.interval(0.68, calibration_only=True)
    half = np.sqrt(spectrum.std_calibration**2 + spread.std_k("ant") ** 2)
    np.testing.assert_allclose((hi - lo) / 2, half * (hi - lo)[0] / 2 / half[0], rtol=1e-9)
    samples = with_sys.samples(4000, np.random.default_rng(0), calibration_only=True)
    # about the calibrated spectrum: the systematic draws carry their bias with them
    spread_of_samples = np.sqrt(np.mean((samples - with_sys.mean) ** 2, axis=0))
    np.testing.assert_allclose(spread_of_samples, half, rtol=0.1)
    with pytest.raises(InvalidDataError, match="systematic draws"):
        spectrum.with_systematics(np.zeros((1, run.data.n_channels)))


def test_bad_settings_are_refused():
    run = simulate_run(_config(), rng=6)
    resolve = refit(solve_radiometric(run.data))
    with pytest.raises(InvalidDataError, match="at least 2 draws"):
        reflection_systematics(run.data, {"ant": run.validation}, resolve, 0, 1)
    with pytest.raises(InvalidDataError, match="correlation length"):
        reflection_systematics(run.data, {"ant": run.validation}, resolve, 0, 4, correlation_hz=-1)
