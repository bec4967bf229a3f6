"""The run store: round trips, the engine reads the merged file, layout, merge, Touchstone."""

import json
import shutil
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest

from calibration.choice.model_fit import OrderChoice
from calibration.io.hdf5_io import read_run
from calibration.io.solution_file import read_solution_group
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulatedRun, simulate_run
from calibration.solve.thesis_solver import solve_thesis
from reach_receiver.store import (
    DICKE_POSITIONS,
    RunStore,
    StoreError,
    TouchstoneError,
    merge_run,
    read_run_file,
    read_touchstone,
    write_touchstone,
)

WIDTH = ITPM_CHANNEL_WIDTH_HZ
N_FULL = 16384
UNITS = {"Hz", "K", "degC", "s", "power (arbitrary)", "complex reflection", "1", "text", "JSON"}
SOLVER_UNITS = {"terms", "nats", "K^2"}
SCHEDULE = ("schedules/calibrate.yaml", "steps:\n  - dicke: hot\n")
SITE = "site:\n  longitude_deg: 21.4\n"
META = {"operator": "test", "seed": 7}


@pytest.fixture(scope="module")
def sim() -> SimulatedRun:
    return simulate_run(rng=7)


def _first_channel(sim: SimulatedRun) -> int:
    k0 = round(sim.data.freq_hz[0] / WIDTH)
    np.testing.assert_allclose(sim.data.freq_hz, WIDTH * (k0 + np.arange(sim.data.n_channels)))
    return k0


def _full(sim: SimulatedRun, band_power: np.ndarray) -> np.ndarray:
    """A 2-input, 16384-channel spectrum holding ``band_power`` at the band channels of input 0."""
    k0 = _first_channel(sim)
    spectrum = np.full((2, N_FULL), 1e-3)
    spectrum[0, k0 : k0 + band_power.size] = band_power
    return spectrum


def _store(directory: Path, **kwargs) -> RunStore:
    return RunStore(
        directory,
        name="test-run",
        schedule_files=[SCHEDULE],
        site_yaml=SITE,
        metadata=META,
        channel_width_hz=WIDTH,
        **kwargs,
    )


def _add_source(store: RunStore, sim: SimulatedRun, src, t: float, scale: float = 1.0) -> None:
    temp = None if src.temperature_k is None else float(src.temperature_k[0])
    powers = {"source": src.p_source, "load": src.p_load, "ns": src.p_ns}
    store.add_dicke(
        src.name,
        spectra={p: _full(sim, scale * powers[p]) for p in DICKE_POSITIONS},
        timestamps={p: [t + i, t + i + 0.5] for i, p in enumerate(DICKE_POSITIONS)},
        integration_s={p: src.integration.source_s for p in DICKE_POSITIONS},
        n_spectra={p: 2 for p in DICKE_POSITIONS},
        temperature_k=temp,
        switch_states={p: {"MS1": str(i + 1)} for i, p in enumerate(DICKE_POSITIONS)},
        counters={p: {"packets_lost": 0} for p in DICKE_POSITIONS},
        timestamp=t + 3,
    )


def _write_sim_run(directory: Path, sim: SimulatedRun) -> RunStore:
    store = _store(directory)
    store.open()
    freq = sim.data.freq_hz
    store.add_s11("lna", freq, sim.data.gamma_rec, timestamp=1.0, settings={}, calibrated=True)
    for i, src in enumerate([*sim.data.sources.values(), sim.validation]):
        settings = {"ifbw_hz": 1000.0, "points": freq.size, "power_dbm": -5.0}
        store.add_s11(
            src.name, freq, src.gamma, timestamp=10.0 * i, settings=settings, calibrated=True
        )
        _add_source(store, sim, src, 10.0 * i + 1)
    store.add_temperatures([100.0, 110.0], np.array([[25.0, 26.0], [25.5, 26.5]]), ["hot", "amb"])
    return store


@pytest.fixture
def run_dir(tmp_path, sim) -> Path:
    store = _write_sim_run(tmp_path / "run", sim)
    store.finish("completed")
    return tmp_path / "run"


def _assert_sources_equal(a, b, rtol=1e-12):
    assert a.name == b.name
    assert a.integration == b.integration
    for field in ("p_source", "p_load", "p_ns"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
    np.testing.assert_allclose(a.gamma, b.gamma, rtol=rtol, atol=1e-14)
    if b.temperature_k is None:
        assert a.temperature_k is None
    else:
        np.testing.assert_allclose(a.temperature_k, b.temperature_k, rtol=1e-15)


def test_engine_reads_the_merged_run(run_dir, sim):
    data, extra = read_run(run_dir / "run.h5")
    np.testing.assert_allclose(data.freq_hz, sim.data.freq_hz, rtol=1e-15)
    np.testing.assert_allclose(data.gamma_rec, sim.data.gamma_rec, rtol=1e-12, atol=1e-14)
    assert data.channel_width_hz == WIDTH
    assert data.names == sim.data.names
    assert data.metadata == META
    for name in data.names:
        _assert_sources_equal(data.sources[name], sim.data.sources[name])
    assert list(extra) == ["ant"]
    _assert_sources_equal(extra["ant"], sim.validation)
    assert data.sources["hot"].temperature_k[0] == pytest.approx(370.0, abs=1e-12)


def test_a_receiver_run_names_its_noise_diode_for_the_engine(run_dir):
    """REACH's NC346A is named in the run, so the engine's ENR check runs on it (only)."""
    from calibration.io.hdf5_io import NC346A, run_noise_source_model

    assert run_noise_source_model(run_dir / "run.h5") == NC346A


def test_run_description_and_root_attributes(run_dir):
    with h5py.File(run_dir / "run.h5") as f:
        assert f.attrs["format"] == "reach-receiver-run"
        assert f.attrs["format_version"] == "1.0"
        assert set(json.loads(f.attrs["software"])) == {"reach-receiver", "numpy", "h5py", "python"}
        assert (f.attrs["status"], f.attrs["reason"]) == ("completed", "")
        assert f.attrs["noise_source_model"] == "NC346A"
        assert f["run/schedule_0"].asstr()[()] == SCHEDULE[1]
        assert f["run/schedule_0"].attrs["path"] == SCHEDULE[0]
        assert f["run/site"].asstr()[()] == SITE
        assert json.loads(f["run/metadata"].asstr()[()]) == META
        meta = f["observation_metadata"]
        assert list(meta.attrs["calibrators"]) == list(simulate_run(rng=None).data.names)
        assert list(meta.attrs["sources"])[-1] == "ant"
        assert "ant" not in meta["temperatures"]
        np.testing.assert_array_equal(meta["temperature_log/values"][()][:, 1], [26.0, 26.5])
        assert f["observation_data/hot_timestamps"].shape == (3,)
        assert list(f["observation_data"].attrs["warnings"]) == []
    assert not list((run_dir / "parts").iterdir())


def test_every_dataset_has_units(run_dir):
    seen = []

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset):
            seen.append(name)
            assert obj.attrs.get("units") in UNITS | SOLVER_UNITS, name

    with h5py.File(run_dir / "run.h5") as f:
        f.visititems(visit)
        assert f["observation_data/hot_spectra"].attrs["units"] == "power (arbitrary)"
        assert f["observation_data/hot_s11"].attrs["units"] == "complex reflection"
        assert f["measurements/000003_dicke_cold/temperature"].attrs["units"] == "K"
    assert len(seen) > 100


def test_measurements_round_trip_in_order(run_dir, sim):
    contents = read_run_file(run_dir / "run.h5")
    assert (contents.name, contents.status, contents.merged) == ("test-run", "completed", True)
    assert contents.schedule_files == (SCHEDULE,)
    assert (contents.site_yaml, contents.metadata) == (SITE, META)
    assert contents.band_hz == (50e6, 130e6)
    kinds = [m.kind for m in contents.measurements]
    assert kinds[:3] == ["s11", "s11", "dicke"]
    assert [m.sequence for m in contents.measurements] == list(range(1, len(kinds) + 1))
    hot = next(m for m in contents.of_kind("dicke") if m.name == "hot")
    assert hot.group == f"/measurements/{hot.sequence:06d}_dicke_hot"
    arrays = contents.read(hot)
    assert arrays["ns/spectrum"].shape == (2, N_FULL)
    np.testing.assert_array_equal(
        arrays["load/timestamps"], [hot.timestamp - 2, hot.timestamp - 1.5]
    )
    s11 = contents.of_kind("s11")[2]
    assert s11.attrs["settings"]["points"] == sim.data.n_channels
    assert s11.attrs["calibrated"] is True


def test_unmerged_directory_reads_like_the_merged_file(tmp_path, sim):
    store = _write_sim_run(tmp_path / "run", sim)
    contents = read_run_file(tmp_path / "run")
    assert not contents.merged
    assert contents.status == "unfinished"
    data, extra = contents.calibration_data()
    assert not (tmp_path / "run" / "run.h5").exists()
    merged = read_run(store.finish("completed"))
    for name in data.names:
        _assert_sources_equal(data.sources[name], merged[0].sources[name], rtol=0)
    assert list(extra) == list(merged[1])


def test_s11_is_interpolated_with_splines_and_never_extrapolated(tmp_path, sim):
    def gamma(f):  # a smooth reflection: 0.2 delayed by 15 ns
        return 0.2 * np.exp(-2j * np.pi * f * 15e-9)

    coarse = np.arange(40e6, 180e6 + 1, 1e6)
    store = _store(tmp_path / "run")
    store.open()
    store.add_s11("lna", coarse, gamma(coarse), timestamp=0.0, settings={}, calibrated=True)
    for src in (sim.data.sources["hot"], sim.data.sources["cold"]):
        _add_source(store, sim, src, 1.0)
    store.add_s11("hot", coarse, gamma(coarse), timestamp=5.0, settings={}, calibrated=True)
    narrow = np.arange(60e6, 180e6 + 1, 1e6)
    store.add_s11("cold", narrow, gamma(narrow), timestamp=6.0, settings={}, calibrated=True)
    store.add_s11("hot", coarse, 0 * coarse, timestamp=7.0, settings={}, calibrated=False)
    data, _ = read_run(store.finish("completed"))
    assert data.names == ["hot"]
    np.testing.assert_allclose(data.gamma_rec, gamma(data.freq_hz), rtol=0, atol=2e-6)
    np.testing.assert_allclose(data.sources["hot"].gamma, gamma(data.freq_hz), rtol=0, atol=2e-6)
    with h5py.File(tmp_path / "run" / "run.h5") as f:
        warnings = list(f["observation_data"].attrs["warnings"])
        assert "cold_spectra" not in f["observation_data"]
    assert len(warnings) == 1
    assert warnings[0].startswith("cold: S11 does not cover")


def test_several_cycles_of_one_source_become_2d(tmp_path, sim):
    hot = sim.data.sources["hot"]
    store = _store(tmp_path / "run")
    store.open()
    freq = sim.data.freq_hz
    store.add_s11("lna", freq, sim.data.gamma_rec, timestamp=0.0, settings={}, calibrated=True)
    store.add_s11("hot", freq, hot.gamma, timestamp=0.0, settings={}, calibrated=True)
    for i, scale in enumerate((1.0, 1.1, 0.9)):
        _add_source(store, sim, replace(hot, temperature_k=hot.temperature_k + i), 10.0 * i, scale)
    path = store.finish("completed")
    with h5py.File(path) as f:
        spectra = f["observation_data/hot_ns_spectra"]
        assert spectra.shape == (3, freq.size)
        assert f["observation_data/hot_spectra"].attrs["integration_s_ns"] == 600.0
        assert f["observation_data/hot_timestamps"].shape == (3, 3)
        np.testing.assert_allclose(spectra[1], 1.1 * hot.p_ns, rtol=1e-15)
    data, _ = read_run(path)
    assert data.sources["hot"].integration.ns_s == 3 * 600.0
    np.testing.assert_allclose(data.sources["hot"].p_load, hot.p_load, rtol=1e-14)
    np.testing.assert_allclose(data.sources["hot"].temperature_k, 371.0, rtol=1e-15)


def test_solution_checks_calibrated_spectra_and_events(tmp_path, sim):
    solution = solve_thesis(sim.data, OrderChoice.fixed((4, 3, 3, 3, 3)))
    store = _write_sim_run(tmp_path / "run", sim)
    rng = np.random.default_rng(3)
    store.add_check(
        "test_load",
        False,
        timestamp=200.0,
        details={"tolerance": 0.05},
        arrays={"freq_hz": np.arange(3.0), "s11": np.ones(3, complex)},
    )
    store.add_check("test_load", True, timestamp=210.0, details={"attempt": 2})
    store.add_solution(solution, timestamp=220.0, verification={"within": True})
    mean = rng.normal(size=sim.data.n_channels)
    flags = mean > 1.5
    store.add_calibrated("ant", sim.data.freq_hz, mean, abs(mean), flags, timestamp=230.0)
    store.add_event("fault", "VNA timeout on *OPC?", timestamp=240.0)
    store.add_event("safe_state", "front-end safe", timestamp=241.0)
    path = store.finish("failed", "VNA timeout")
    with h5py.File(path) as f:
        assert (f.attrs["status"], f.attrs["reason"]) == ("failed", "VNA timeout")
        back = read_solution_group(f["calibration/solution"], path)
        np.testing.assert_array_equal(back.posterior.mean, solution.posterior.mean)
        assert list(f["checks"]) == ["000_test_load", "001_test_load"]
        assert not f["checks/000_test_load"].attrs["passed"]
        assert f["checks/000_test_load/freq_hz"].attrs["units"] == "Hz"
        np.testing.assert_array_equal(f["calibration/calibrated/ant/flags"][()], flags)
        assert list(f["events/kinds"].asstr()[()]) == ["fault", "safe_state"]
        np.testing.assert_array_equal(f["events/timestamps"][()], [240.0, 241.0])
    contents = read_run_file(path)
    assert contents.solution().posterior.orders == solution.posterior.orders
    assert contents.of_kind("check")[0].attrs["details"] == {"tolerance": 0.05}


def test_merge_is_idempotent_and_survives_a_crash_mid_merge(tmp_path, sim):
    run = tmp_path / "run"
    _write_sim_run(run, sim)
    saved = tmp_path / "saved_parts"
    shutil.copytree(run / "parts", saved)
    first = read_run_file(merge_run(run)).measurements
    assert read_run_file(merge_run(run)).measurements == first
    # A crash after the replace, part-way through deleting parts: some parts come back.
    for part in sorted(saved.iterdir())[5:9]:
        shutil.copy(part, run / "parts")
    again = read_run_file(merge_run(run))
    assert [(m.sequence, m.name) for m in again.measurements] == [
        (m.sequence, m.name) for m in first
    ]
    assert again.status == "interrupted"  # no status record: the writer was killed
    assert not list((run / "parts").iterdir())
    # A crash before the replace: the temporary is left, the parts all remain.
    (run / "run.h5").unlink()
    shutil.rmtree(run / "parts")
    shutil.copytree(saved, run / "parts")
    (run / ".run.h5.x1y2.tmp").write_bytes(b"\x89HDF half written")
    merged = read_run_file(merge_run(run, "interrupted", "killed"))
    assert merged.measurements == first
    assert merged.reason == "killed"
    assert not (run / ".run.h5.x1y2.tmp").exists()


def test_a_stale_temporary_part_is_ignored_and_cleaned(tmp_path, sim):
    run = tmp_path / "run"
    _write_sim_run(run, sim)
    n = len(read_run_file(run).measurements)
    stale = run / "parts" / ".000099-dicke-hot.h5.abcd.tmp"
    stale.write_bytes(b"\x89HDF\r\n\x1a\n truncated")
    assert len(read_run_file(run).measurements) == n
    assert len(read_run_file(merge_run(run)).measurements) == n
    assert not stale.exists()


def test_misuse_is_refused(tmp_path, sim):
    store = _store(tmp_path / "run")
    with pytest.raises(StoreError, match="new run"):
        store.add_event("x", "y", timestamp=0.0)
    store.open()
    bad = {"source": np.ones((2, 8)), "load": np.ones((2, 8))}
    with pytest.raises(ValueError, match="Dicke positions"):
        store.add_dicke(
            "hot",
            spectra=bad,
            timestamps={},
            integration_s={},
            n_spectra={},
            temperature_k=None,
            switch_states={},
            counters={},
            timestamp=0.0,
        )
    with pytest.raises(ValueError, match="status"):
        store.finish("done")
    with pytest.raises(StoreError, match="already holds a run"):
        _store(tmp_path / "run").open()
    store.finish("completed")
    with pytest.raises(StoreError, match="finished run"):
        store.add_event("x", "y", timestamp=0.0)
    assert read_run_file(store.finish("failed", "merged again")).status == "failed"
    with pytest.raises(ValueError, match="channel_width_hz"):
        RunStore(
            tmp_path / "x",
            name="x",
            schedule_files=[],
            site_yaml="",
            metadata={},
            channel_width_hz=0.0,
        )


def test_context_manager_records_a_failure(tmp_path):
    def fail() -> None:
        with _store(tmp_path / "run") as store:
            store.add_event("fault", "about to fail", timestamp=1.0)
            raise RuntimeError("boom")

    with pytest.raises(RuntimeError, match="boom"):
        fail()
    contents = read_run_file(tmp_path / "run" / "run.h5")
    assert (contents.status, contents.reason) == ("failed", "RuntimeError: boom")
    assert [m.kind for m in contents.measurements] == ["event"]


# --- Touchstone -------------------------------------------------------------------------


def test_touchstone_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(1)
    freq = np.sort(rng.uniform(40e6, 180e6, 50))
    s11 = rng.normal(size=50) * 0.3 + 1j * rng.normal(size=50) * 0.3
    path = tmp_path / "load.s1p"
    write_touchstone(path, freq, s11, z0=50.0, comment="test load\nMS2 port")
    f2, s2, z0 = read_touchstone(path)
    np.testing.assert_array_equal(f2, freq)
    np.testing.assert_array_equal(s2, s11)
    assert z0 == 50.0
    assert path.read_text().startswith("! test load\n! MS2 port\n")


HAND_WRITTEN = {
    "ma_mhz.s1p": "! from the VNA\n# MHz S MA R 50\n50 0.1 90 ! comment\n60.5 0.2 -180\n",
    "db_ghz.s1p": "!\n#GHz s db r 75\n\n0.05 -20 0\n0.0605 -6.020599913279624 180\n",
    "ri_khz.s1p": "# khz ri\n50000 0 0.1\n60500 -0.2 0\n",
}


@pytest.mark.parametrize("name", sorted(HAND_WRITTEN))
def test_touchstone_formats_and_units(tmp_path, name):
    path = tmp_path / name
    path.write_text(HAND_WRITTEN[name])
    freq, s11, z0 = read_touchstone(path)
    np.testing.assert_allclose(freq, [50e6, 60.5e6], rtol=1e-15)
    expected = [0.1j, -0.2] if name != "db_ghz.s1p" else [0.1, -0.5]
    np.testing.assert_allclose(s11, expected, rtol=0, atol=1e-12)
    assert z0 == (75.0 if name == "db_ghz.s1p" else 50.0)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("# Hz S RI R 50\n1 2\n", r"bad\.s1p:2: expected 'f a b'"),
        ("# Hz S RI R 50\n1 0 0\n1 0 0\n", r"bad\.s1p:3: frequency 1\.0 does not increase"),
        ("# Hz Y RI R 50\n1 0 0\n", r"bad\.s1p:1: unsupported option 'Y'"),
        ("! nothing\n", r"bad\.s1p:1: no data lines"),
        ("# Hz S RI R\n1 0 0\n", r"bad\.s1p:1: 'R' needs"),
        ("# Hz S RI\n1 x 0\n", r"bad\.s1p:2: not a number"),
    ],
)
def test_touchstone_errors_name_file_and_line(tmp_path, text, message):
    path = tmp_path / "bad.s1p"
    path.write_text(text)
    with pytest.raises(TouchstoneError, match=message):
        read_touchstone(path)
