"""The report's figures and tables say what the solution is: the faults of issue 37.

* the model named in titles and the evidence panel is the one carrying the weight;
* an import's placeholder powers are not drawn as measurements;
* leave-one-out beside the in-sample residuals, its numbers those of ``validate``;
* the T_cos / T_sin bands' pinches are where the reflective loads measure one alone.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import argrelmin

from calibration.checks.validation import leave_one_out
from calibration.io.edges_import import load_edges3_run
from calibration.io.hdf5_io import write_run
from calibration.io.solution_file import write_solution
from calibration.model.simulate import SimulationConfig, simulate_run
from calibration.report.figures import dicke_powers, evidence_landscape, noise_wave_parameters
from calibration.report.figures.parameters import ranked_models, single_phase_frequencies
from calibration.report.figures.run import NO_POWERS
from calibration.report.loo import same_procedure
from calibration.report.writer import load_inputs, write_report
from calibration.solve.radiometric_solver import solve_radiometric

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "edges3-2022-316"
FOUR = ("cold", "hot", "c10open", "c10short")


@pytest.fixture(scope="module")
def sims():
    """Two small simulated runs: four loads, and six calibrators at another width."""
    out = {}
    for seed, width, cals in ((11, 400e3, FOUR), (12, 300e3, (*FOUR, "r25", "r100"))):
        config = SimulationConfig(channel_width_hz=width, calibrators=cals)
        run = simulate_run(config, rng=seed)
        out[seed] = (run, solve_radiometric(run.data))
    return out


def _b18_like(solution):
    """``solution`` recorded as B18's was: the heaviest model is not the evidence-best."""
    table = sorted(solution.evidence_table.items(), key=lambda kv: -kv[1])
    heavy = table[-1][0]  # the table's worst: the smooth hypothesis enters with its own prior
    weights = [{"orders": list(o), "weight": 0.0} for o, _ in table[:12]]
    meta = {**solution.metadata, "averaged": True, "orders_used": list(heavy),
            "orders_used_weight": 0.997,
            "model_weights": [{"orders": list(heavy), "weight": 0.997}, *weights[:9]]}
    return dataclasses.replace(solution, metadata=meta), heavy


@pytest.mark.parametrize("seed", [11, 12])
def test_the_evidence_panel_and_titles_name_the_models_carrying_the_weight(sims, seed):
    solution, heavy = _b18_like(sims[seed][1])
    rows = ranked_models(solution)
    assert rows[0][:2] == (heavy, 0.997)
    assert len(rows) == 12
    fig = evidence_landscape(solution)
    top = fig.axes[1]
    labels = [t.get_text() for t in top.get_yticklabels()]
    assert labels[0] == ",".join(map(str, heavy))
    assert labels[0] not in labels[1:]
    assert "0.997" in [t.get_text() for t in top.texts]
    assert "weight" in top.get_title()
    title = noise_wave_parameters(solution)._suptitle.get_text()
    assert f"orders {','.join(map(str, heavy))}, weight 0.997 of the average" in title
    best = ",".join(map(str, solution.best_orders))
    assert best not in title


def test_a_single_model_is_named_by_its_orders(sims):
    _, solution = sims[11]
    single = dataclasses.replace(solution, metadata={**solution.metadata, "averaged": False})
    title = noise_wave_parameters(single)._suptitle.get_text()
    assert title.endswith(f"orders {','.join(map(str, single.orders_used))})")


@pytest.mark.parametrize("seed", [11, 12])
def test_placeholder_powers_are_not_drawn(sims, tmp_path, seed):
    run, solution = sims[seed]
    fig = dicke_powers(run.data, placeholder=True)
    powers, q_axes = fig.axes[:3], fig.axes[3]
    for ax in powers:
        assert not ax.lines
        assert NO_POWERS in [t.get_text() for t in ax.texts]
    assert len(q_axes.lines) == len(run.data.names)
    measured = dicke_powers(run.data)
    assert all(len(ax.lines) == len(run.data.names) for ax in measured.axes[:3])
    # Through the report: the run file's attribute decides.
    write_run(tmp_path / "import.h5", run.data, {}, attrs={"power_spectra": "placeholder"})
    write_solution(tmp_path / "sol.h5", solution)
    assert load_inputs(tmp_path / "sol.h5", tmp_path / "import.h5").placeholder_powers
    write_run(tmp_path / "sim.h5", run.data, {}, attrs={})
    assert not load_inputs(tmp_path / "sol.h5", tmp_path / "sim.h5").placeholder_powers


def test_leave_one_out_beside_the_in_sample_residuals(sims, tmp_path):
    run, solution = sims[12]
    write_run(tmp_path / "run.h5", run.data, {"ant": run.validation}, truth=run.truth)
    write_solution(tmp_path / "sol.h5", solution)
    report = write_report(tmp_path / "sol.h5", tmp_path / "out", tmp_path / "run.h5",
                          leave_one_out=True)
    assert "leave_one_out" in {p.stem for p in report.figures}
    text = report.markdown.read_text()
    table = text.split("## Leave-one-out")[1].split("## ")[0]
    rows = {
        cells[0]: cells
        for line in table.splitlines()[4:]
        if line.startswith("| ") and (cells := [c.strip() for c in line.strip("|").split("|")])
    }
    expected = leave_one_out(run.data, same_procedure(solution)[0])
    assert set(rows) == set(run.data.names)
    solved = 0
    for held in expected.results:
        row = rows[held.name]
        assert float(row[2]) == pytest.approx(1.0, abs=0.35)  # in-sample: at the noise
        if held.refused is not None:
            assert row[3].startswith("refused: ")
            continue
        solved += 1
        assert float(row[3]) == pytest.approx(held.rms_error_k, rel=1e-3)
        assert float(row[4]) == pytest.approx(held.rms_predicted_k, rel=1e-3)
        assert float(row[5]) == pytest.approx(held.ratio, abs=1e-3)
        assert row[8] == ",".join(map(str, held.orders))
    assert solved >= 3  # the open, the short, the resistors: T_NS stays determined
    without = write_report(tmp_path / "sol.h5", tmp_path / "out2", tmp_path / "run.h5")
    assert "leave_one_out" not in {p.stem for p in without.figures}
    assert "not computed" in without.markdown.read_text()


def test_no_single_phase_marks_where_the_reflective_loads_differ(sims):
    run, _ = sims[12]
    twelve = simulate_run(SimulationConfig(channel_width_hz=2e6), rng=1).data
    assert single_phase_frequencies(twelve) is None  # REACH's cables: phases differ
    marks = single_phase_frequencies(run.data.subset(FOUR))
    assert marks is not None
    assert marks["cos"].size > 3
    assert marks["sin"].size > 3


@pytest.mark.skipif(not DATA.is_dir(), reason=f"no EDGES-3 data beside the checkout ({DATA})")
def test_edges3_bands_pinch_where_the_reflective_loads_measure_one_parameter():
    """EDGES-3's four loads: T_cos's sd has its minima where X_sin = 0 (T_sin: X_cos = 0)."""
    data = load_edges3_run(DATA)
    solution = solve_radiometric(data)
    marks = single_phase_frequencies(data)
    assert marks is not None
    sd = solution.parameter_std(data.freq_hz)
    for k, name in ((1, "cos"), (2, "sin")):
        minima = data.freq_hz[argrelmin(sd[k], order=20)[0]]
        inner = minima[(minima > data.freq_hz[0] + 5e6) & (minima < data.freq_hz[-1] - 5e6)]
        assert inner.size >= 4
        distance = np.min(np.abs(inner[:, None] - marks[name][None, :]), axis=1)
        assert np.all(distance < 1e6), (name, inner / 1e6, marks[name] / 1e6)
        pinched = np.interp(inner, data.freq_hz, sd[k])
        assert np.all(pinched < 0.2 * np.median(sd[k]))
