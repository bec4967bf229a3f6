"""The archive on Dask: the season and the recalibration of runs, on 1 and 2 workers, resumed.

Runs are written by the receiver's own store with Dicke cycles of real simulated powers
(the engine's simulation of the antenna through the receiver) and calibrated as the
observe step calibrates them: through the store's hand-over (``RunStore.engine_view``),
the solution, the engine's flagger and the night's. Clusters are ``distributed`` ones:
thread workers in this process (0.1 s to start) for the graph's properties, and worker
processes once, through the command line.
"""

from __future__ import annotations

import dataclasses
import io
import itertools
import os
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from distributed import Client, LocalCluster
from test_season import SITE_YAML, make_night, night_times, sky_k

from calibration.checks.rfi import flag_sky
from calibration.checks.rfi_night import flag_night
from calibration.cli import main
from calibration.io.calibrated_spectra import read_calibrated_spectra
from calibration.io.solution_file import write_solution
from calibration.model.data import Integration
from calibration.model.reflections import reach_source_reflection
from calibration.model.simulate import simulate_source
from calibration.season.archive import Cluster, season_on_dask
from calibration.season.binning import add, bin_run, combine, lst_edges
from calibration.season.chunks import bin_rows, read_rows, rows_per_chunk
from calibration.season.recalibrate import recalibrated_run_bytes
from calibration.season.season_file import read_season
from calibration.solve.solvers import band_hz
from reach_receiver.store import RunStore

POSITIONS = ("source", "load", "ns")


@dataclasses.dataclass(frozen=True)
class Run:
    """A run file and what the receiver's hand-over gave the engine for each cycle."""

    path: Path
    views: tuple


def write_observed_run(directory: Path, night, rng, n_cycles: int, night_index: int,
                       seconds: float, rfi_channel: int | None = None) -> Run:
    """A run whose antenna cycles were calibrated as the observe step does."""
    sim = night.sim
    freq, width = sim.data.freq_hz, sim.data.channel_width_hz
    below = round(freq[0] / width)  # the spectrometer's channels below the band
    gamma_ant = reach_source_reflection("ant", freq)
    times = night_times(night_index, n_cycles, step_s=float(rng.choice([600.0, 1800.0])))
    store = RunStore(directory, name=directory.name, schedule_files=[], site_yaml=SITE_YAML,
                     metadata={}, channel_width_hz=width, band_hz=(freq[0], freq[-1]))
    with store:
        store.add_s11("ant", freq, gamma_ant, timestamp=times[0] - 600, settings={},
                      calibrated=True)
        store.add_s11("lna", freq, sim.data.gamma_rec, timestamp=times[0] - 300, settings={},
                      calibrated=True)
        store.add_solution(night.solution, timestamp=times[0] - 60, verification={})
        names, means, flags, views = [], [], [], []
        sky = sky_k(freq)
        if rfi_channel is not None:
            sky = sky + np.where(np.arange(freq.size) == rfi_channel, 500.0, 0.0)
        for i, t in enumerate(times):
            ant = simulate_source("ant", freq, gamma_ant, sim.gamma_rec_true, sky, sim.truth,
                                  Integration(seconds, seconds, seconds), width, rng,
                                  known_temperature=False)
            powers = {"source": ant.p_source, "load": ant.p_load, "ns": ant.p_ns}
            number = store.add_dicke(
                "ant", spectra={p: np.concatenate([np.ones(below), v])[None, :]
                                for p, v in powers.items()},
                timestamps={p: [t - 5.0, t + 5.0] for p in POSITIONS},
                integration_s=dict.fromkeys(POSITIONS, seconds),
                n_spectra=dict.fromkeys(POSITIONS, 1), temperature_k=None,
                switch_states={}, counters={}, timestamp=t + 600,
            )
            # reach_receiver/run/steps/observe.py: calibrate_cycle
            view = store.engine_view(band_hz(night.solution), cycles={"ant": [number]})
            layout = view.layout
            views.append((layout, view.others["ant"]))
            spectrum = night.solution.calibrate(
                layout.freq_hz, layout.gamma_rec, view.others["ant"], layout.channel_width_hz,
                layout.gamma_rec_std,
            )
            own = flag_sky(spectrum.mean, 5.0, layout.freq_hz)
            store.add_calibrated(
                f"ant_{i:04d}", layout.freq_hz, spectrum.mean, spectrum.std, own,
                timestamp=t + 600, handover=view.handover,
                errors={"std_calibration": spectrum.std_calibration,
                        "std_radiometer": spectrum.std_radiometer},
            )
            names.append(f"ant_{i:04d}")
            means.append(spectrum.mean)
            flags.append(own)
        night_flags = flag_night(np.stack(means), np.stack(flags), freq, 5.0)
        store.add_check("rfi_night_ant", True, timestamp=times[-1] + 700,
                        details={"spectra": names, "threshold_sigma": 5.0,
                                 **night_flags.summary()},
                        arrays={"flags": night_flags.flags})
    return Run(directory / "run.h5", tuple(views))


@pytest.fixture(scope="module")
def nights():
    """Two nights' solutions of one simulated receiver (different noise)."""
    return [make_night(900 + k) for k in range(2)]


@pytest.fixture(scope="module")
def archive(nights, tmp_path_factory):
    """Five runs of 2-4 cycles, calibrated with the two nights' solutions in turn."""
    root = tmp_path_factory.mktemp("archive")
    rng = np.random.default_rng(39)
    return [
        write_observed_run(root / f"run{k}", nights[k % 2], rng, int(rng.integers(2, 5)), k,
                           float(rng.choice([300.0, 1200.0])), rfi_channel=40 if k == 1 else None)
        for k in range(5)
    ]


@pytest.fixture(scope="module")
def threads():
    """Clients of 1 and 2 thread workers (no memory limit: the chunking is asked for)."""
    with (LocalCluster(n_workers=1, threads_per_worker=1, processes=False, memory_limit=0,
                       dashboard_address=":0") as one, Client(one) as c1,
          LocalCluster(n_workers=2, threads_per_worker=1, processes=False, memory_limit=0,
                       dashboard_address=":0") as two, Client(two) as c2):
        yield c1, c2


def test_recalibrating_reproduces_observe_with_its_solution_and_the_handover_with_another(
    archive, nights, tmp_path
):
    for k in (0, 1, 4):
        run = str(archive[k].path)
        stored = read_calibrated_spectra(run)
        own = nights[k % 2].solution
        again = tmp_path / f"own{k}.h5"
        again.write_bytes(recalibrated_run_bytes(run, own, "own", 0.0))
        same = read_calibrated_spectra(again)
        for key in ("mean", "std_radiometer", "std_calibration", "std_reflection", "flags",
                    "time_s", "lst_h"):
            assert np.array_equal(getattr(stored, key), getattr(same, key)), (k, key)
        assert same.solutions[0].digest == stored.solutions[0].digest
        if k == 1:
            assert stored.flags[:, 40].all()  # the injected line, found again
        other = nights[(k + 1) % 2].solution
        moved = tmp_path / f"other{k}.h5"
        moved.write_bytes(recalibrated_run_bytes(run, other, "other", 0.0))
        new = read_calibrated_spectra(moved)
        for row, (layout, source) in enumerate(archive[k].views):  # one band: the same layout
            expected = other.calibrate(layout.freq_hz, layout.gamma_rec, source,
                                       layout.channel_width_hz, layout.gamma_rec_std)
            assert np.array_equal(new.mean[row], expected.mean)
            assert np.array_equal(new.std_calibration[row], expected.std_calibration)
        assert new.solutions[0].digest != stored.solutions[0].digest
        assert not np.array_equal(new.mean, stored.mean)


def test_chunks_of_a_run_give_the_run(archive):
    rng = np.random.default_rng(1)
    edges = lst_edges(0.5)
    for run in (str(r.path) for r in archive[:4]):
        whole = read_calibrated_spectra(run)
        n = len(whole.names)
        cuts = sorted({0, n, *rng.integers(1, n, size=2).tolist()})
        parts = [read_rows(run, a, b) for a, b in itertools.pairwise(cuts)]
        for key in ("mean", "flags", "std_reflection", "lst_h", "solution"):
            joined = np.concatenate([getattr(p, key) for p in parts])
            assert np.array_equal(joined, getattr(whole, key)), key
        pairs = list(itertools.pairwise(cuts))
        summed = bin_rows(run, *pairs[0], edges)
        for a, b in pairs[1:]:
            summed = add(summed, bin_rows(run, a, b, edges))
        direct = bin_run(whole, edges)
        np.testing.assert_allclose(summed.weighted, direct.weighted, rtol=1e-12)
        assert summed.runs == (run,)
    assert rows_per_chunk(16384, 2**30) == 2**30 // (24 * 8 * 16384)
    assert rows_per_chunk(16384, 1) == 1


@pytest.mark.parametrize("truth", range(3))
def test_the_dask_season_is_the_same_on_1_and_2_workers_and_equals_the_plain_combine(
    archive, threads, truth
):
    rng = np.random.default_rng(truth)
    runs = [str(archive[i].path) for i in rng.permutation(5)[: int(rng.integers(3, 6))]]
    edges = lst_edges(float(rng.choice([0.25, 1.0, 2.0])))
    n_ch = 201
    memory = float(rng.choice([1, 2, 3])) * 4 * 24 * 8 * n_ch  # chunks of 1-3 spectra
    logs = [io.StringIO(), io.StringIO()]
    seasons = [season_on_dask(Cluster(c, "test", w, int(memory)), runs, edges, log)
               for w, c, log in ((1, threads[0], logs[0]), (2, threads[1], logs[1]))]
    lines = logs[1].getvalue().splitlines()
    assert "\r" not in logs[1].getvalue()
    assert all(len(x) <= 80 for x in lines), lines
    assert 3 <= len(lines) <= 12, lines
    assert lines[-1].startswith("season: "), lines
    for key in ("mean", "std_radiometer", "std_calibration", "std_reflection", "weight", "count"):
        a, b = getattr(seasons[0], key), getattr(seasons[1], key)
        assert np.array_equal(a, b, equal_nan=True), key  # bit for bit: a fixed tree
    plain = combine(bin_run(read_calibrated_spectra(r), edges) for r in runs)
    for key in ("mean", "std_radiometer", "std_calibration", "std_reflection", "weight"):
        np.testing.assert_allclose(getattr(seasons[1], key), getattr(plain, key), rtol=1e-12,
                                   equal_nan=True, err_msg=key)
    assert seasons[1].spectra == plain.spectra
    assert seasons[1].runs == plain.runs
    assert {s.digest for s in seasons[1].solutions} == {s.digest for s in plain.solutions}


def _outputs(directory: Path) -> list[str]:
    return sorted(str(p) for p in directory.glob("*/run.h5"))


def test_recalibrate_resumes_and_its_outputs_make_the_recalibrated_season(
    archive, nights, tmp_path, capsys
):
    solution = tmp_path / "new.h5"
    write_solution(solution, nights[1].solution)  # runs 0, 2, 4 were calibrated otherwise
    runs = [str(archive[k].path) for k in (0, 2, 4)]
    out = tmp_path / "out"
    assert main(["recalibrate", str(solution), *runs[:2], "-o", str(out), "--workers", "2"]) == 0
    assert "2 worker processes" in capsys.readouterr().out
    first = {p: os.stat(p).st_mtime_ns for p in _outputs(out)}
    assert len(first) == 2
    # a task killed while writing leaves only its hidden temporary file, never run.h5
    (out / "run4").mkdir()
    (out / "run4" / ".run.h5.999.dead.tmp").write_bytes(b"half a file")
    assert main(["recalibrate", str(solution), *runs, "-o", str(out), "--workers", "1"]) == 0
    printed = capsys.readouterr().out
    assert "skipped 2 done" in printed
    assert "recalibrate: 1 runs" in printed
    assert {p: os.stat(p).st_mtime_ns for p in _outputs(out) if p in first} == first
    outputs = _outputs(out)
    assert [Path(p).parent.name for p in outputs] == ["run0", "run2", "run4"]
    for run, made in zip(runs, outputs, strict=True):  # what one uninterrupted pass makes
        direct = tmp_path / "direct.h5"
        direct.write_bytes(recalibrated_run_bytes(run, nights[1].solution, str(solution),
                                                  os.path.getmtime(solution)))
        x, y = read_calibrated_spectra(made), read_calibrated_spectra(direct)
        assert np.array_equal(x.mean, y.mean)
        assert np.array_equal(x.flags, y.flags)
        assert x.solutions[0].digest == y.solutions[0].digest
    target = tmp_path / "season.h5"
    assert main(["season", *outputs, "-o", str(target), "--workers", "1"]) == 0
    season = read_season(target)
    (used,) = season.solutions  # every spectrum now calibrated by the new solution
    with h5py.File(outputs[0]) as f:
        assert f.attrs["solution_digest"] == used.digest
    assert len(season.spectra) == sum(len(archive[k].views) for k in (0, 2, 4))


def _empty_run(directory: Path) -> str:
    with RunStore(directory, name="empty", schedule_files=[], site_yaml=SITE_YAML, metadata={},
                  channel_width_hz=400e3) as store:
        store.add_event("note", "nothing calibrated", timestamp=1.7e9)
    return str(directory / "run.h5")


@pytest.mark.parametrize(("command", "case"), [
    ("season", "missing run"), ("season", "no spectra"), ("season", "no scheduler"),
    ("recalibrate", "missing run"), ("recalibrate", "no spectra"),
    ("recalibrate", "output is a file"),
])
def test_bad_input_is_two_lines_exit_2_and_nothing_written(
    archive, nights, tmp_path, capsys, command, case
):
    runs = [str(archive[0].path)]
    if case == "missing run":
        runs.append(str(tmp_path / "gone" / "run.h5"))
    elif case == "no spectra":
        runs.append(_empty_run(tmp_path / "empty"))
    out = tmp_path / ("season.h5" if command == "season" else "out")
    if case == "output is a file":
        out.write_text("not a directory")
    argv = [command, *runs, "-o", str(out), "--workers", "1"]
    if command == "recalibrate":
        write_solution(tmp_path / "sol.h5", nights[1].solution)
        argv.insert(1, str(tmp_path / "sol.h5"))
    if case == "no scheduler":
        argv += ["--scheduler", "tcp://127.0.0.1:9"]
    capsys.readouterr()
    start = time.monotonic()
    assert main(argv) == 2
    assert time.monotonic() - start < 15
    err = capsys.readouterr().err.strip().splitlines()
    assert 1 <= len(err) <= 2, err
    assert err[0].startswith("reach-cal: error:"), err
    assert "Traceback" not in "\n".join(err)
    if case == "output is a file":
        assert out.read_text() == "not a directory"
    else:
        assert not out.exists()
    assert not list(tmp_path.rglob("*.tmp"))
