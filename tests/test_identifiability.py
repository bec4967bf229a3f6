"""Honest degeneracy: what the calibrators cannot determine is refused or shown as the prior's.

Simulated four-load (EDGES-like) and matched-load runs, over seeds and integration times,
and the real EDGES-3 loads with one left out (skipped where that data set is absent).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calibration.choice.model_fit import OrderChoice
from calibration.io.edges_import import load_edges3_run
from calibration.model.data import CalibrationData, Integration
from calibration.model.simulate import SimulationConfig, simulate_run, simulate_source
from calibration.solve.identifiability import (
    PRIOR_DOMINATED,
    UndeterminedError,
    prior_dominated_line,
)
from calibration.solve.radiometric_solver import solve_radiometric
from calibration.solve.thesis_solver import solve_thesis

FOUR_LOADS = ("cold", "hot", "c10open", "c10short")
SOLVERS = {"radiometric": solve_radiometric, "thesis": solve_thesis}
EDGES3 = Path(__file__).resolve().parents[2] / "shared" / "data" / "edges3-2022-316"
needs_edges3 = pytest.mark.skipif(
    not EDGES3.is_dir(),
    reason=f"the shared EDGES-3 data set is not beside this checkout (looked for {EDGES3})",
)


def _four_loads(seed: int, integration_s: float) -> CalibrationData:
    config = SimulationConfig(
        calibrators=FOUR_LOADS, integration_s=integration_s, f_hi_hz=110e6
    )
    return simulate_run(config, rng=seed).data


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize(("seed", "integration_s"), [(1, 60.0), (2, 600.0), (3, 3600.0)])
def test_loads_at_one_temperature_are_refused_naming_t_ns(solver, seed, integration_s):
    """Without the hot load every calibrator is ambient: T_NS is refused, with the why."""
    data = _four_loads(seed, integration_s).subset(["cold", "c10open", "c10short"])
    with pytest.raises(UndeterminedError, match="T_NS is not determined") as err:
        SOLVERS[solver](data)
    assert err.value.parameter == "NS"
    assert "same temperature" in str(err.value)
    assert "cold 298.0 K" in str(err.value)


@pytest.mark.parametrize(("seed", "integration_s"), [(10, 600.0), (11, 60.0), (12, 3600.0)])
def test_one_matched_load_at_its_own_temperature_is_refused(seed, integration_s):
    """Hot load and two reflective cables: the contrast is seen only through reflection.

    Refused before the solve, not by the posterior's width, which can miss a wrong mode
    (test_validation.py's held-out ambient load); asked to, the solver still answers."""
    data = _four_loads(seed, integration_s).subset(["hot", "c10open", "c10short"])
    with pytest.raises(UndeterminedError, match="fewer than two matched") as err:
        solve_radiometric(data)
    assert err.value.parameter == "NS"
    assert "hot 370.0 K" in str(err.value)
    solve_radiometric(data, allow_prior_dominated=True)


def test_reach_set_without_its_ambient_load_keeps_matched_contrast():
    """REACH's resistors on short cables are matched at ambient: hot against them suffices."""
    names = ("hot", "c2r36", "c2r69", "c10open", "c10short", "r25", "r100")
    data = simulate_run(SimulationConfig(calibrators=names, f_hi_hz=110e6), rng=13).data
    solution = solve_radiometric(data)
    t_ns = solution.evaluate(data.freq_hz)[3]
    assert np.all((t_ns > 900.0) & (t_ns < 1500.0))


@pytest.mark.parametrize("orders", [None, (5, 5, 5, 5, 5)])
def test_temperatures_within_their_stated_error_count_as_one(orders):
    """Ambient loads 0.2 K apart, each read to 0.1 K: no contrast the data can use."""
    data = _four_loads(4, 600.0).subset(["cold", "c10open", "c10short"])
    sources = {
        name: replace(src, temperature_k=src.temperature_k + 0.1 * k, temperature_std_k=0.1)
        for k, (name, src) in enumerate(data.sources.items())
    }
    choice = None if orders is None else OrderChoice.fixed(orders)
    with pytest.raises(UndeterminedError) as err:
        solve_radiometric(replace(data, sources=sources), choice)
    assert err.value.parameter == "NS"


@pytest.mark.parametrize("seed", [5, 6])
def test_reflective_load_left_out_still_solves_at_its_floor(seed):
    """Open or short left out: the other three determine every parameter, nothing flagged."""
    data = _four_loads(seed, 600.0)
    for out in ("c10open", "c10short"):
        solution = solve_radiometric(data.subset([n for n in FOUR_LOADS if n != out]))
        assert solution.metadata["prior_dominated"] == {}
        assert prior_dominated_line(solution) == ""


def _matched_only(seed: int, integration_s: float) -> tuple[CalibrationData, object]:
    """Two perfectly matched loads (cold, hot) and a reflective antenna to calibrate."""
    run = simulate_run(SimulationConfig(calibrators=("cold", "hot"), f_hi_hz=110e6), rng=seed)
    rng = np.random.default_rng(seed)
    freq, truth = run.data.freq_hz, run.truth
    tau = Integration(integration_s, integration_s, integration_s)
    sources = {
        name: simulate_source(
            name, freq, np.zeros(freq.size, complex), run.gamma_rec_true, t, truth, tau,
            run.data.channel_width_hz, rng,
        )
        for name, t in (("cold", 298.0), ("hot", 370.0))
    }
    return replace(run.data, sources=sources), run


@pytest.mark.parametrize(("seed", "integration_s"), [(7, 120.0), (8, 1800.0)])
def test_noise_waves_without_reflective_loads_are_reported_with_prior_width(seed, integration_s):
    """Matched loads alone say nothing of T_unc, T_cos, T_sin: reported, and the error
    bars of a reflective antenna calibrated with them carry the prior's width."""
    data, run = _matched_only(seed, integration_s)
    solution = solve_radiometric(data)
    dominated = solution.metadata["prior_dominated"]
    assert set(dominated) == {"unc", "cos", "sin"}
    assert all(r >= PRIOR_DOMINATED for r in dominated.values())
    assert "T_cos" in prior_dominated_line(solution)
    ant = solution.calibrate(data.freq_hz, data.gamma_rec, run.validation)
    assert np.median(ant.std_calibration) > 100.0  # K: the prior's width, not a radiometer's
    error = np.abs(ant.mean - run.validation_temperature_k)
    assert np.mean(error < 2.0 * ant.std) > 0.9  # and still honest


@pytest.fixture(scope="module")
def edges3() -> CalibrationData:
    return load_edges3_run(EDGES3)


@needs_edges3
@pytest.mark.parametrize("left_out", ["amb", "hot"])
def test_real_edges3_without_a_temperature_load_is_refused(edges3, left_out):
    """EDGES-3 with amb or hot left out: T_NS is refused by name (both solvers)."""
    data = edges3.subset([n for n in edges3.names if n != left_out])
    for solver in SOLVERS.values():
        with pytest.raises(UndeterminedError, match="T_NS") as err:
            solver(data)
        assert err.value.parameter == "NS"


@needs_edges3
def test_real_edges3_without_the_open_load_searches_to_an_answer(edges3):
    """Open left out: the largest model's fit crosses T_NS = 0, the search must not fail."""
    solution = solve_radiometric(edges3.subset(["amb", "hot", "short"]))
    t_ns = solution.evaluate(edges3.freq_hz)[3]
    assert np.all((t_ns > 900.0) & (t_ns < 1500.0))
    assert solution.metadata["prior_dominated"] == {}


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_box_whose_top_terms_take_t_ns_through_zero_is_cut_not_refused(seed):
    """Four calibrators, two of them reflective at |Gamma| ~ 0.3 only, no VNA noise: the
    largest models' fits (8 terms each) take T_NS through zero in a quarter of the band,
    and so did the evidence's models fitted on the same equations, so the solve was
    refused (T_NS undetermined) in all four seeds, where the truth's own orders calibrate
    at the floor. Now the box loses its top terms until the fits keep T_NS positive, and
    the solve recovers the antenna within twice the floor, its error bars within 1.5 of
    the error."""
    from calibration.solve.noise_floor import noise_floor
    from tests.test_errors_in_variables import _weak_run

    run = _weak_run(seed, vna_sigma=0.0)
    data = run.data
    solution = solve_radiometric(data)
    cal = solution.calibrate(data.freq_hz, data.gamma_rec, run.validation_noiseless)
    error = float(np.sqrt(np.mean((cal.mean - run.validation_temperature_k) ** 2)))
    floor = noise_floor(data, run.validation_noiseless, run.truth.parameters).rms
    assert error / floor < 2.0
    assert error / float(np.sqrt(np.mean(cal.std**2))) < 1.5
    cuts = solution.metadata["order_box_cuts"]
    assert cuts[0]["asked"] == [8, 8, 8, 8, 8]
    assert cuts[0]["why"] == "their fits took T_NS through zero"


def test_a_summary_names_the_box_cut_and_why():
    """The cut of the test above is named where the orders are printed, with its reason."""
    from calibration.solve.identifiability import box_cut_line, caution_lines
    from tests.test_errors_in_variables import _weak_run

    solution = solve_radiometric(_weak_run(0, vna_sigma=0.0).data)
    line = box_cut_line(solution)
    assert "(8, 8, 8, 8, 8) to" in line
    assert "took T_NS through zero" in line
    assert line in caution_lines(solution)
    clean = solve_radiometric(simulate_run(SimulationConfig(channel_width_hz=97656.25), rng=0).data)
    assert box_cut_line(clean) == ""
    assert caution_lines(clean) == []


def test_a_summary_says_where_the_reflections_errors_leave_models_unidentified():
    """With VNA noise the same four calibrators identify every model of a smaller box and
    some beyond it: the note names both boxes, not a cut (``identified_line``). Fixed orders
    those errors decide, solved anyway with ``allow_prior_dominated``, are warned of with
    their share of the information (``uncorrected_line``)."""
    from calibration.solve.identifiability import (
        box_cut_line,
        caution_lines,
        identified_line,
        uncorrected_line,
    )
    from tests.test_errors_in_variables import _weak_run

    data = _weak_run(0).data
    solution = solve_radiometric(data)
    line = identified_line(solution)
    assert "not every model up to (8, 8, 8, 8, 8)" in line
    assert line in caution_lines(solution)
    assert box_cut_line(solution) == uncorrected_line(solution) == ""
    forced = solve_radiometric(
        data, orders=OrderChoice.fixed((8, 8, 8, 8, 8)), allow_prior_dominated=True
    )
    assert forced.metadata["reflection_errors_uncorrected"] > 0.5
    warning = uncorrected_line(forced)
    assert warning.startswith("warning: the reflections' errors carry")
    assert warning in caution_lines(forced)


def test_a_source_the_averaged_models_disagree_on_is_noted(tmp_path, capsys):
    """Four calibrators with VNA noise, the truth beyond the identified box (seed 6): the
    models that trade T_cos's structure into T_sin fit as well and calibrate the antenna
    4-17x the floor apart, and their spread is most of its calibration variance (0.81;
    0.39-0.83 over the eight seeds of the test in test_errors_in_variables). ``reach-cal
    apply`` says so; twelve calibrators (0.004-0.006) do not."""
    from calibration.cli import main
    from calibration.io.hdf5_io import write_run
    from calibration.io.solution_file import write_solution
    from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ
    from calibration.solve.identifiability import CHOICE_SHARE, model_choice_line
    from tests.test_errors_in_variables import beyond_run

    run = beyond_run(6)
    data = run.data
    solution = solve_radiometric(data)
    spectrum = solution.calibrate(
        data.freq_hz, data.gamma_rec, run.validation, data.channel_width_hz, data.gamma_rec_std
    )
    assert spectrum.model_choice_share > CHOICE_SHARE
    assert model_choice_line(spectrum.model_choice_share, "ant").startswith(
        "note: on 'ant' the averaged models disagree"
    )
    run_file, solution_file = tmp_path / "run.h5", tmp_path / "solution.h5"
    write_run(run_file, data, {run.validation.name: run.validation})
    write_solution(solution_file, solution)
    assert main(["apply", str(solution_file), str(run_file)]) == 0
    assert "the averaged models disagree" in capsys.readouterr().out

    twelve = simulate_run(SimulationConfig(channel_width_hz=32 * ITPM_CHANNEL_WIDTH_HZ), rng=0)
    spectrum = solve_radiometric(twelve.data).calibrate(
        twelve.data.freq_hz, twelve.data.gamma_rec, twelve.validation
    )
    assert spectrum.model_choice_share < 0.05
    assert model_choice_line(spectrum.model_choice_share, "ant") == ""
