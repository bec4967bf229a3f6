"""reach-cal report: its numbers, parsed back from the summary, are the solution's."""

import json
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import h5py
import numpy as np
import pytest

from calibration.cli import main
from calibration.io.hdf5_io import read_run, software_version, write_run
from calibration.io.solution_file import read_solution, write_solution, write_solution_group
from calibration.model.simulate import SimulationConfig, simulate_run
from calibration.report.writer import load_inputs, write_report
from calibration.solve.noise_floor import noise_floor
from calibration.solve.radiometric_solver import solve_radiometric

CONFIG = SimulationConfig(
    channel_width_hz=400e3, calibrators=("cold", "hot", "r25", "r100", "c10open", "c10short")
)
RECEIVER_RUN = "receiver-run.h5"
FIGURES_WITH_RUN = {"parameters", "evidence", "sources", "reflections", "dicke", "flags",
                    "temperatures", "leave_one_out"}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("report")
    run = simulate_run(CONFIG, rng=5)
    write_run(tmp / "run.h5", run.data, {"ant": run.validation}, truth=run.truth)
    write_solution(tmp / "solution.h5", solve_radiometric(run.data))
    _receiver_run(tmp)
    return tmp


@pytest.fixture(scope="module")
def report(files):
    """The one full report of these tests: the solution file with the receiver's run file."""
    return write_report(
        files / "solution.h5", files / "out", files / RECEIVER_RUN, leave_one_out=True
    )


def tables(markdown: str) -> dict[str, list[list[str]]]:
    """Each section's table rows (header excluded), cells unescaped."""
    out: dict[str, list[list[str]]] = {}
    title = ""
    for line in markdown.splitlines():
        if line.startswith("## "):
            title = line[3:]
            out[title] = []
        elif line.startswith("| ") and title:
            cells = [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", line)[1:-1]]
            out[title].append(cells)
    return {k: rows[1:] for k, rows in out.items()}  # drop each header row


def section(parsed: dict[str, list[list[str]]], start: str) -> list[list[str]]:
    (key,) = [k for k in parsed if k.startswith(start)]
    return parsed[key]


def test_files_written(report):
    assert {p.stem for p in report.figures} == FIGURES_WITH_RUN
    for png in report.figures:
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert report.pdf is None
    assert (report.directory / "temperatures.png").stat().st_size > 10_000


def test_solution_numbers_equal_the_solution(files, report):
    solution = read_solution(files / "solution.h5")
    rows = dict(section(tables(report.markdown.read_text()), "Solution"))
    post = solution.posterior
    used = ",".join(map(str, solution.orders_used))
    assert rows["model used, orders (unc, cos, sin, NS, L)"].startswith(f"{used} (weight ")
    assert rows["evidence-best single model"] == ", ".join(map(str, solution.best_orders))
    assert rows["posterior layout orders"] == ", ".join(map(str, solution.orders))
    assert float(rows["log evidence (nats)"]) == pytest.approx(post.log_evidence, abs=1e-6)
    noise = rows["noise scale s^2 (1 = radiometer equation exact)"]
    assert float(noise) == pytest.approx(post.noise_variance, rel=1e-5)
    assert float(rows["chi2 per row"]) == pytest.approx(post.chi2 / post.n_rows, rel=1e-5)
    assert int(rows["models evaluated"]) == len(solution.evidence_table)
    assert rows["calibrators"].endswith(", ".join(solution.calibrators))
    models = re.findall(r"\(([\d,]+)\) ([\d.]+)", rows["averaged models (orders weight)"])
    expected = solution.metadata["model_weights"][: len(models)]
    assert len(models) >= 2
    for (orders, weight), model in zip(models, expected, strict=True):
        assert [int(n) for n in orders.split(",")] == model["orders"]
        assert float(weight) == pytest.approx(model["weight"], abs=5e-4)


def test_source_and_floor_numbers_equal_a_recomputation(files, report):
    solution = read_solution(files / "solution.h5")
    data, others = read_run(files / "run.h5")
    parsed = tables(report.markdown.read_text())
    sources = section(parsed, "Sources")
    assert [r[0] for r in sources] == data.names
    for name, residual, radiometer, calibration, ratio in sources:
        src = data.sources[name]
        spectrum = solution.calibrate(data.freq_hz, data.gamma_rec, src, data.channel_width_hz)
        error = spectrum.mean - src.temperature_k

        def rms(x):
            return float(np.sqrt(np.mean(np.square(x))))

        assert float(residual) == pytest.approx(1e3 * rms(error), rel=1e-3)
        assert float(radiometer) == pytest.approx(1e3 * rms(spectrum.std_measurement), rel=1e-3)
        assert float(calibration) == pytest.approx(1e3 * rms(spectrum.std_calibration), rel=1e-3)
        assert float(ratio) == pytest.approx(rms(error) / rms(spectrum.std), rel=1e-3)
        assert 0.7 < float(ratio) < 1.3  # honest noise model, in-sample
    ((name, floor, predicted, share, distance, actual, ratio),) = section(parsed, "Distance")
    assert name == "ant"
    antenna = solution.calibrate(data.freq_hz, data.gamma_rec, others["ant"])
    assert float(share) == pytest.approx(antenna.model_choice_share, abs=5e-4)
    used = solution.parameters.truncated(solution.orders_used)  # the model used, not the envelope
    expected = noise_floor(data, others["ant"], used).rms
    assert float(floor) == pytest.approx(1e3 * expected, rel=1e-3)
    assert float(distance) == pytest.approx(float(predicted) / float(floor), rel=2e-3)
    assert float(actual) > 0
    assert float(ratio) == pytest.approx(float(actual) / float(floor), rel=2e-3)


def test_checks_and_software(report):
    parsed = tables(report.markdown.read_text())
    checks = dict(section(parsed, "Checks"))
    assert checks["prior-dominated parameters"] == "none"
    assert checks["orders at the search ceiling"] == "none"
    software = dict(section(parsed, "Software"))
    assert software["this report"] == software_version()
    assert software["matplotlib"]


class _Cells(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.cells: list[str] = []
        self.images: list[str] = []
        self._in = False

    def handle_starttag(self, tag, attrs):
        self._in = tag in ("td", "th")
        if tag == "img":
            self.images.append(dict(attrs)["src"])

    def handle_data(self, data):
        if self._in:
            self.cells.append(data)

    def handle_endtag(self, tag):
        self._in = False


def test_html_holds_the_same_cells_and_every_figure(report):
    parser = _Cells()
    parser.feed(report.html.read_text())
    markdown_cells = [c for rows in tables(report.markdown.read_text()).values() for r in rows
                      for c in r]
    for cell in markdown_cells:
        assert cell in parser.cells
    assert parser.images == [p.name for p in report.figures]


def _receiver_run(files: Path) -> Path:
    """The simulated run as a receiver's run file (reach_receiver/store/merge.py layout)."""
    path = files / RECEIVER_RUN
    shutil.copy(files / "run.h5", path)
    solution = read_solution(files / "solution.h5")
    freq = read_run(path)[0].freq_hz
    with h5py.File(path, "r+") as f:
        f.attrs.update(format="reach-receiver-run", status="completed", reason="")
        f.attrs["software"] = json.dumps({"reach-receiver": "9.9", "numpy": "1"})
        write_solution_group(f.create_group("calibration/solution"), solution)
        log = f.create_group("observation_metadata/temperature_log")
        log["timestamps"] = 1.79e9 + 60.0 * np.arange(50)
        log["values"] = 25.0 + 0.01 * np.arange(100).reshape(50, 2)
        log.attrs["channels"] = ["MS1 switch", "low noise amplifier"]
        check = f.create_group("checks/000_test_load")
        check.attrs.update(name="test_load", passed=False, details="{}")
        events = f.create_group("events")
        events["timestamps"] = [1.0, 2.0]
        events["kinds"] = np.array(["step", "fault"], dtype=object)
        events["messages"] = np.array(["s11", "VNA timeout"], dtype=object)
        health = f.create_group("measurements/000009_monitoring_health")
        health["series"] = [0, 0, 1]
        health["status"] = [1, 2, 0]
        health.attrs.update(keys=["lna_current"], status_names=["nominal", "warn", "error"])
        health.attrs["keys"] = ["lna_current", "tec_temperature"]
        flags = f.create_group("calibration/calibrated/ant")
        flags["frequencies"] = freq
        flags["flags"] = np.arange(freq.size) % 50 == 0
    return path


def test_the_run_records_are_in_the_checks(report):
    parsed = tables(report.markdown.read_text())
    checks = dict(section(parsed, "Checks"))
    assert checks["run status"] == "completed"
    assert checks["run check: test_load"] == "FAILED"
    assert checks["alarms during the run"] == "lna_current: error (2 readings)"
    assert checks["events"] == "fault: VNA timeout"
    software = dict(section(parsed, "Software"))
    assert software["run file written by"] == "reach-receiver 9.9, numpy 1"


def test_a_receiver_run_file_is_solution_and_run(files):
    inputs = load_inputs(files / RECEIVER_RUN)
    assert inputs.run_path == str(files / RECEIVER_RUN)
    assert inputs.records.temperature_log is not None
    assert set(inputs.records.flags) == {"ant"}
    expected = read_solution(files / "solution.h5").posterior.mean
    np.testing.assert_array_equal(inputs.solution.posterior.mean, expected)


def test_without_a_run_only_the_solution_figures_and_a_pdf_of_them(files, capsys):
    out = files / "alone"
    assert main(["report", str(files / "solution.h5"), "-o", str(out), "--pdf"]) == 0
    assert "wrote" in capsys.readouterr().out
    assert sorted(p.stem for p in out.glob("*.png")) == ["evidence", "parameters"]
    pages = re.findall(rb"/Type\s*/Page[^s]", (out / "report.pdf").read_bytes())
    assert len(pages) == 2
    assert "no run given" in (out / "summary.md").read_text()


def test_a_missing_solution_is_an_operator_error(tmp_path, capsys):
    assert main(["report", str(tmp_path / "nope.h5"), "-o", str(tmp_path / "out")]) == 2
    assert "reach-cal: error:" in capsys.readouterr().err
