"""What ``reach-cal`` prints names the model used, every warning, and works on any run file.

Runs are small simulations (205-410 channels, a few calibrators); an "import" is such a
run written as the importer writes one: calibrators only, ``power_spectra = placeholder``.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from calibration.checks.temperature_sanity import CELSIUS_SLIP_K as ENGINE_SLIP_K
from calibration.choice.model_fit import DEFAULT_MAX_ORDERS, OrderChoice
from calibration.cli import main
from calibration.cli.args import AUTO_BOX_START, AUTO_BOX_STEP, CELSIUS_SLIP_K
from calibration.cli.main import build_parser
from calibration.io.hdf5_io import read_run, write_run
from calibration.io.solution_file import read_solution, write_solution
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ
from calibration.report.model_used import model_used_line

WIDTH = str(16 * ITPM_CHANNEL_WIDTH_HZ)
FOUR = "cold,hot,c10open,c10short"


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two simulated runs of different seeds and bands."""
    out = {}
    for seed, band in ((3, "50,130"), (8, "60,110")):
        path = tmp_path_factory.mktemp("run") / f"run{seed}.h5"
        assert main(["simulate", "-o", str(path), "--seed", str(seed), "--band", band,
                     "--channel-width-hz", WIDTH]) == 0
        out[seed] = path
    return out


def _run(capsys, argv):
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_parser_constants_are_the_engines():
    assert DEFAULT_MAX_ORDERS[0] == AUTO_BOX_START
    assert len(set(DEFAULT_MAX_ORDERS)) == 1
    assert OrderChoice().extend_step == AUTO_BOX_STEP
    assert CELSIUS_SLIP_K == ENGINE_SLIP_K


@pytest.mark.parametrize("seed", [3, 8])
def test_the_model_used_is_named_where_the_evidence_best_is_another(runs, tmp_path, capsys, seed):
    """A B18-like solution: the average sits on (8,8,8,8,8), the evidence-best is smaller."""
    run, sol, edited = runs[seed], tmp_path / "sol.h5", tmp_path / "edited.h5"
    code, out, _ = _run(capsys, ["solve", run, "-o", sol, "--calibrators", FOUR])
    assert code == 0
    solution = read_solution(sol)
    used = ",".join(map(str, solution.orders_used))
    assert f"model used, orders (unc, cos, sin, NS, L): {used} (" in out
    # The same solution, recorded as B18's was: the evidence-best single model is not
    # the one that carries the weight.
    best = tuple(max(n - 1, 1) for n in solution.orders_used)
    meta = {**solution.metadata, "best_orders": list(best), "averaged": True,
            "orders_used": [8, 8, 8, 8, 8], "orders_used_weight": 0.997,
            "model_weights": [{"orders": list(best), "weight": 0.0}] * 3
            + [{"orders": [8, 8, 8, 8, 8], "weight": 0.997}]}
    write_solution(edited, dataclasses.replace(solution, metadata=meta))
    code, out, _ = _run(capsys, ["summary", edited])
    assert code == 0
    line = next(x for x in out.splitlines() if x.startswith("model used"))
    assert "8,8,8,8,8 (weight 0.997 in the average" in line
    assert f"evidence-best single model {','.join(map(str, best))} carries less weight" in line
    assert "40 coefficients" in line
    assert "(8,8,8,8,8) 0.997" in out.split("averaged over models")[1].splitlines()[0]


def test_validate_names_each_solves_model_and_warns_on_fixed_orders(runs, capsys):
    code, out, _ = _run(capsys, ["validate", runs[3], "--leave-one-out", "--orders",
                                 "3,3,3,3,3", "--calibrators", "cold,hot,r25,c10open,c10short"])
    assert code == 0
    names = ("c10open", "c10short", "r25")
    rows = [x.split() for x in out.splitlines() if x.strip().startswith(names)]
    solved = [r for r in rows if r[1] != "refused:"]
    assert len(rows) == 3
    assert solved
    assert all(r[-1] == "3,3,3,3,3" for r in solved)
    s2 = float(re.search(r"noise scale s\^2: ([\d.]+)", out).group(1))
    assert s2 > 1.25  # three terms cannot hold the receiver: the fit says so
    assert f"warning: noise scale s^2 = {s2:.2f} (orders 3,3,3,3,3)" in out


def test_every_warning_is_printed_by_solve_and_summary(runs, tmp_path, capsys):
    sol = tmp_path / "sol.h5"
    code, solved, _ = _run(capsys, ["solve", runs[8], "-o", sol, "--max-orders", "3,3,3,3,3"])
    assert code == 0
    solution = read_solution(sol)
    sentences = solution.metadata["warnings"]
    assert len(sentences) >= 2  # a box of three terms: s^2 far from 1, parameters at the limit
    code, summary, _ = _run(capsys, ["summary", sol])
    for sentence in sentences:
        assert f"warning: {sentence}" in solved
        assert f"warning: {sentence}" in summary
    # A file written before metadata held warnings: the order limit is still said.
    old = tmp_path / "old.h5"
    meta = {k: v for k, v in solution.metadata.items() if k != "warnings"}
    write_solution(old, dataclasses.replace(solution, metadata=meta))
    code, out, _ = _run(capsys, ["summary", old])
    assert code == 0
    limited = ", ".join(solution.metadata["orders_at_ceiling"])
    assert f"warning: {limited} ended at the order limit [3, 3, 3, 3, 3]" in out


def test_distance_to_floor_gives_the_actual_beside_the_predicted(runs, tmp_path, capsys):
    sol = tmp_path / "sol.h5"
    assert main(["solve", str(runs[3]), "-o", str(sol)]) == 0
    code, out, _ = _run(capsys, ["summary", sol, "--run", runs[3]])
    assert code == 0
    assert "source 'ant': the run's non-calibrator source" in out
    predicted = float(re.search(r"distance to floor: predicted ([\d.]+)", out).group(1))
    actual = float(re.search(r"predicted [\d.]+, actual ([\d.]+)", out).group(1))
    assert 0 < predicted < 2
    assert 0 < actual < 3


def _import_like(run, path, temperature=None, edges_like=False):
    """``run``'s calibrators alone, marked as an import's (optionally one load's T changed).

    ``edges_like``: as EDGES' importer writes them, frequencies rounded to 1 Hz and a
    channel width (the noise bandwidth of its smoothing) 1.5 times the channel spacing.
    """
    data, _ = read_run(run)
    if edges_like:
        width = 1.5 * data.channel_width_hz
        data = dataclasses.replace(
            data, freq_hz=np.round(data.freq_hz + 0.37), channel_width_hz=width
        )
    if temperature is not None:
        name, t_k = temperature
        src = dataclasses.replace(
            data.sources[name], temperature_k=np.full(data.n_channels, t_k)
        )
        data = dataclasses.replace(data, sources={**data.sources, name: src})
    write_run(path, data, {}, attrs={"power_spectra": "placeholder"})
    return path


@pytest.mark.parametrize(("seed", "edges_like"), [(3, False), (8, True)])
def test_summary_on_an_import_reports_its_calibrators(runs, tmp_path, capsys, seed, edges_like):
    run = _import_like(runs[seed], tmp_path / "import.h5", edges_like=edges_like)
    sol = tmp_path / "sol.h5"
    assert main(["solve", str(run), "-o", str(sol), "--calibrators", FOUR]) == 0
    code, out, err = _run(capsys, ["summary", sol, "--run", run])
    assert code == 0, err
    assert "has no non-calibrator source (e.g. an import)" in out
    assert "in-sample" in out
    table = out.split("res/pred")[1].splitlines()[1:5]
    rows = {x.split()[0]: x.split() for x in table}
    assert set(rows) == set(FOUR.split(","))
    for row in rows.values():
        assert 0.3 < float(row[-1]) < 3  # residual / predicted: the noise model holds
    assert main(["apply", str(sol), str(run), "--source", "cold"]) == 0  # the grid is its own
    code, _, err = _run(capsys, ["summary", sol, "--run", run, "--source", "ant"])
    assert code == 2
    assert "has no source 'ant'" in err


@pytest.mark.parametrize(("load", "celsius"), [("cold", 22.85), ("c10open", 25.0)])
def test_a_celsius_temperature_is_refused_with_the_way_out(runs, tmp_path, capsys, load, celsius):
    run = _import_like(runs[8], tmp_path / "celsius.h5", (load, celsius))
    sol = tmp_path / "sol.h5"
    code, _, err = _run(capsys, ["solve", run, "-o", sol, "--calibrators", FOUR])
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 2
    assert f"{load} at {celsius:.4g} K ({celsius + 273.15:.5g} K if" in lines[0]
    assert "kelvin" in lines[1]
    assert "--cryogenic" in lines[1]
    assert not sol.exists()
    code, out, _ = _run(capsys, ["solve", run, "-o", sol, "--calibrators", FOUR,
                                 "--cryogenic", "--max-orders", "3,3,3,3,3"])
    assert f"cryogenic calibrators accepted (--cryogenic): {load}" in out


def test_a_refusal_says_what_to_do_on_the_command_line(runs, tmp_path, capsys):
    code, _, err = _run(capsys, ["solve", runs[3], "-o", tmp_path / "s.h5",
                                 "--calibrators", "cold,c10open,c10short,r25"])
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 2
    assert "T_NS is not determined" in lines[0]
    assert lines[1].startswith("reach-cal: what to do:")
    assert "--calibrators" in lines[1]


def test_one_band_syntax_and_the_older_form(tmp_path, capsys):
    new, old = tmp_path / "new.h5", tmp_path / "old.h5"
    for path, band in ((new, ["60,90"]), (old, ["60", "90"])):
        assert main(["simulate", "-o", str(path), "--band", *band, "--channel-width-hz",
                     "200000"]) == 0
    a, b = read_run(new)[0], read_run(old)[0]
    np.testing.assert_array_equal(a.freq_hz, b.freq_hz)
    assert a.freq_hz[0] == 60e6
    assert a.freq_hz[-1] <= 90e6
    capsys.readouterr()
    assert main(["simulate", "-o", str(tmp_path / "x.h5"), "--band", "90,60"]) == 2
    assert "LO < HI" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["simulate", "solve", "apply", "summary", "validate",
                                     "report"])
def test_every_option_says_its_default(command, capsys):
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    parser = sub.choices[command]
    for action in parser._actions:
        if action.dest in ("help", "output") or action.required or not action.option_strings:
            continue
        said = action.help or ""
        assert "default" in said or "(required)" in said, (command, action.option_strings, said)
    if command == "solve":
        assert main([command, "--help"]) == 0
        text = re.sub(r"\s+", " ", capsys.readouterr().out)
        assert f"box starts at {AUTO_BOX_START} terms" in text
        assert "above 16 is refused" in text


def test_model_used_line_of_a_fixed_solution(runs, tmp_path):
    sol = tmp_path / "fixed.h5"
    assert main(["solve", str(runs[3]), "-o", str(sol), "--orders", "3,4,3,4,3"]) == 0
    assert model_used_line(read_solution(sol)) == "3,4,3,4,3 (fixed; 17 coefficients)"
