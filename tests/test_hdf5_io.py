"""HDF5 runs and solutions: exact round trips, REACH-style input, clear errors on bad files."""

from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest

from calibration.choice.averaging import MixturePosterior
from calibration.choice.model_fit import OrderChoice
from calibration.core.errors import FileFormatError, InvalidDataError
from calibration.io.hdf5_io import FORMAT_VERSION, read_run, read_truth, write_run
from calibration.io.solution_file import read_solution, write_solution
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run
from calibration.solve.radiometric_solver import solve_radiometric
from calibration.solve.thesis_solver import solve_thesis

CFG = SimulationConfig(channel_width_hz=16 * ITPM_CHANNEL_WIDTH_HZ)
SOURCE_FIELDS = ("gamma", "p_source", "p_load", "p_ns", "temperature_k", "q_variance_override")


@pytest.fixture(scope="module")
def run():
    return simulate_run(CFG, rng=11)


@pytest.fixture
def run_file(tmp_path, run) -> Path:
    path = tmp_path / "run.h5"
    write_run(path, run.data, {"ant": run.validation}, truth=run.truth)
    return path


def _assert_same_source(a, b):
    assert a.name == b.name
    assert a.integration == b.integration
    for name in SOURCE_FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        if x is None or y is None:
            assert x is y, name
        else:
            assert x.dtype == y.dtype, name
            np.testing.assert_array_equal(x, y, err_msg=name)


def test_run_round_trip_is_exact(tmp_path, run):
    path = tmp_path / "run.h5"
    write_run(path, run.data, {"ant": run.validation}, attrs={"site": "lab"})
    data, extra = read_run(path)
    np.testing.assert_array_equal(data.freq_hz, run.data.freq_hz)
    np.testing.assert_array_equal(data.gamma_rec, run.data.gamma_rec)
    assert data.channel_width_hz == run.data.channel_width_hz
    assert data.names == run.data.names
    assert data.metadata == run.data.metadata
    for name in run.data.names:
        _assert_same_source(data.sources[name], run.data.sources[name])
    assert list(extra) == ["ant"]
    _assert_same_source(extra["ant"], run.validation)
    with h5py.File(path, "r") as f:
        assert f.attrs["format_version"] == FORMAT_VERSION
        assert f.attrs["site"] == "lab"
        assert f.attrs["software"].startswith("reach-receiver")
        assert f["observation_data/frequencies"].attrs["units"] == "Hz"
        assert f["observation_metadata/temperatures/hot"].attrs["units"] == "K"
        assert f["observation_data/ant_s11"].dtype.kind == "c"
        assert "ant" not in f["observation_metadata/temperatures"]


def test_optional_fields_and_a_source_with_temperature_round_trip(tmp_path, run):
    cold = run.data.sources["cold"]
    override = np.linspace(1e-8, 2e-8, run.data.n_channels)
    sources = {**run.data.sources, "cold": replace(cold, q_variance_override=override)}
    data = replace(run.data, sources=sources)
    # An extra source may know its temperature and still not be a calibrator.
    ant = replace(run.validation, temperature_k=run.validation_temperature_k)
    write_run(tmp_path / "run.h5", data, {"ant": ant})
    back, extra = read_run(tmp_path / "run.h5")
    _assert_same_source(back.sources["cold"], data.sources["cold"])
    assert "ant" not in back.sources
    _assert_same_source(extra["ant"], ant)


def test_reflection_errors_round_trip_and_follow_a_channel_selection(tmp_path, run):
    n = run.data.n_channels
    rec_std = np.linspace(1e-3, 2e-3, n)
    cold = replace(run.data.sources["cold"], gamma_std=np.full(n, 5e-4))
    data = replace(run.data, sources={**run.data.sources, "cold": cold}, gamma_rec_std=rec_std)
    write_run(tmp_path / "run.h5", data)
    back, _ = read_run(tmp_path / "run.h5")
    np.testing.assert_array_equal(back.gamma_rec_std, rec_std)
    np.testing.assert_array_equal(back.sources["cold"].gamma_std, np.full(n, 5e-4))
    assert read_run(tmp_path / "run.h5")[0].sources["hot"].gamma_std is None
    mask = np.arange(n) % 3 == 0
    np.testing.assert_array_equal(back.select(mask).gamma_rec_std, rec_std[mask])
    with pytest.raises(InvalidDataError, match=r"receiver.*>= 0"):
        replace(data, gamma_rec_std=-rec_std)


def test_truth_round_trip(run_file, run, tmp_path):
    truth = read_truth(run_file)
    assert truth is not None
    assert truth.parameters.orders == run.truth.parameters.orders
    assert truth.parameters.basis == run.truth.parameters.basis
    np.testing.assert_array_equal(truth.parameters.coefficients, run.truth.parameters.coefficients)
    assert truth.gain_coefficients == run.truth.gain_coefficients
    assert truth.offset_coefficients_k == run.truth.offset_coefficients_k
    write_run(tmp_path / "measured.h5", run.data)
    assert read_truth(tmp_path / "measured.h5") is None


@pytest.mark.parametrize("method", ["radiometric", "thesis"])
def test_solution_round_trip_reproduces_calibration(tmp_path, run, method):
    if method == "radiometric":
        solution = solve_radiometric(run.data, OrderChoice(max_orders=(5, 4, 5, 5, 4)))
    else:
        solution = solve_thesis(run.data)
    path = tmp_path / "solution.h5"
    write_solution(path, solution)
    back = read_solution(path)
    assert back.method == solution.method
    assert back.basis == solution.basis
    assert back.orders == solution.orders
    assert back.measurement_model == solution.measurement_model
    assert back.calibrators == solution.calibrators
    assert back.metadata == dict(solution.metadata)
    assert back.evidence_table == dict(solution.evidence_table)
    assert list(back.evidence_table) == list(solution.evidence_table)
    for name in ("dof", "log_evidence", "noise_variance", "chi2", "n_rows"):
        assert getattr(back.posterior, name) == getattr(solution.posterior, name), name
    d = run.data
    before = solution.calibrate(d.freq_hz, d.gamma_rec, run.validation, d.channel_width_hz)
    after = back.calibrate(d.freq_hz, d.gamma_rec, run.validation, d.channel_width_hz)
    for name in ("mean", "std_calibration", "std_measurement"):
        np.testing.assert_array_equal(getattr(after, name), getattr(before, name), err_msg=name)
    with h5py.File(path, "r") as f:
        assert f["posterior/mean"].attrs["units"] == "K"
        assert f["evidence/orders"].shape == (len(solution.evidence_table), 5)
        assert f["evidence/orders"].dtype.kind == "i"


@pytest.mark.parametrize("seed", [11, 12])
def test_averaged_solution_reads_back_as_the_same_mixture(tmp_path, seed):
    """Components, weights and draws of a model-averaged posterior survive the file."""
    data = simulate_run(CFG, rng=seed).data
    solution = solve_radiometric(data, OrderChoice(max_orders=(5, 4, 5, 5, 4)))
    post = solution.posterior
    assert isinstance(post, MixturePosterior)
    assert len(post.components) > 1
    path = tmp_path / "solution.h5"
    write_solution(path, solution)
    back = read_solution(path).posterior
    assert isinstance(back, MixturePosterior)
    np.testing.assert_array_equal(back.weights, post.weights)
    assert [c.orders for c in back.components] == [c.orders for c in post.components]
    assert back.model_weights() == post.model_weights()
    draws = [p.sample(500, np.random.default_rng(0)) for p in (post, back)]
    np.testing.assert_array_equal(draws[1], draws[0])


def test_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, run_file, run):
    before = run_file.read_bytes()
    with pytest.raises(TypeError):
        write_run(run_file, run.data, attrs={"unstorable": object()})
    assert run_file.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.h5"]
    write_run(run_file, run.data)  # a successful overwrite replaces it
    _, extra = read_run(run_file)
    assert extra == {}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.h5"]


def test_missing_group_names_file_and_group(run_file):
    with h5py.File(run_file, "a") as f:
        del f["observation_metadata"]
    with pytest.raises(FileFormatError, match=r"run\.h5: missing group '/observation_metadata'"):
        read_run(run_file)


def test_missing_dataset_names_it(run_file):
    with h5py.File(run_file, "a") as f:
        del f["observation_data/c2r27_ns_spectra"]
    with pytest.raises(FileFormatError, match=r"run\.h5.*c2r27_ns_spectra"):
        read_run(run_file)


@pytest.mark.parametrize("version", ["2.0", "0.9"])
def test_unknown_major_version_is_refused(run_file, version):
    with h5py.File(run_file, "a") as f:
        f.attrs["format_version"] = version
    with pytest.raises(FileFormatError, match=rf"run\.h5.*{version}.*major version"):
        read_run(run_file)


def test_newer_minor_version_is_read(run_file):
    with h5py.File(run_file, "a") as f:
        f.attrs["format_version"] = "1.7"
    data, _ = read_run(run_file)
    assert data.n_channels > 2


def test_nan_in_spectrum_names_file_and_source(run_file):
    with h5py.File(run_file, "a") as f:
        f["observation_data/hot_load_spectra"][7] = np.nan
    with pytest.raises(InvalidDataError, match=r"run\.h5.*'hot'.*non-finite") as info:
        read_run(run_file)
    assert info.value.source == "hot"


def test_nan_in_extra_source_names_it(run_file):
    with h5py.File(run_file, "a") as f:
        f["observation_data/ant_spectra"][0] = np.inf
    with pytest.raises(InvalidDataError, match=r"run\.h5.*'ant'.*non-finite"):
        read_run(run_file)


def test_wrong_kind_of_file(tmp_path, run_file):
    with pytest.raises(FileFormatError, match="expected 'reach-calibration-solution'"):
        read_solution(run_file)
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5")
    with pytest.raises(FileFormatError, match=r"notes\.h5: not a readable HDF5 file"):
        read_run(text)
    with pytest.raises(FileNotFoundError):
        read_run(tmp_path / "absent.h5")


def test_solution_without_version_is_refused(tmp_path, run):
    path = tmp_path / "solution.h5"
    write_solution(path, solve_thesis(run.data, OrderChoice.fixed((4, 3, 4, 4, 3))))
    with h5py.File(path, "a") as f:
        del f.attrs["format_version"]
    with pytest.raises(FileFormatError, match="format_version"):
        read_solution(path)


def test_reach_style_2d_spectra_are_averaged(tmp_path):
    """A file as REACH's tools write it: no format attributes, repeated spectra, scalars."""
    rng = np.random.default_rng(5)
    n = 16
    freq = np.linspace(50e6, 130e6, n)
    tau = 2.5
    rows = {"hot": (4, 3, 5), "cold": (6, 6, 6), "ant": (3, 2, 2)}
    written = {}
    path = tmp_path / "reach.h5"
    with h5py.File(path, "w") as f:
        obs = f.create_group("observation_data")
        obs["frequencies"] = freq
        obs["lna_s11"] = np.full(n, 0.03 + 0.01j)
        meta = f.create_group("observation_metadata")
        meta.attrs["channel_width_hz"] = 24414.0625
        meta.attrs["integration_s_load"] = tau  # file-wide default for every source
        temps = meta.create_group("temperatures")
        temps["hot"] = 370.0
        temps["cold"] = np.full(n, 298.0)
        for name, (n_src, n_load, n_ns) in rows.items():
            spectra = {
                "spectra": 1.5 + 0.01 * rng.standard_normal((n_src, n)),
                "load_spectra": 1.0 + 0.01 * rng.standard_normal((n_load, n)),
                "ns_spectra": 3.0 + 0.01 * rng.standard_normal((n_ns, n)),
            }
            for suffix, value in spectra.items():
                obs[f"{name}_{suffix}"] = value
            obs[f"{name}_spectra"].attrs["integration_s_source"] = tau
            obs[f"{name}_spectra"].attrs["integration_s_ns"] = 2 * tau
            obs[f"{name}_s11"] = (0.1 + 0.05j) * np.exp(1j * freq / 1e7)
            obs[f"{name}_timestamps"] = np.arange(n_src, dtype=float)
            written[name] = spectra
    data, extra = read_run(path)
    assert data.names == ["cold", "hot"]  # every source with a temperature, sorted
    assert list(extra) == ["ant"]
    np.testing.assert_array_equal(data.sources["hot"].temperature_k, np.full(n, 370.0))
    for name, (n_src, n_load, n_ns) in rows.items():
        src = data.sources.get(name) or extra[name]
        np.testing.assert_allclose(src.p_source, written[name]["spectra"].mean(axis=0), rtol=1e-15)
        np.testing.assert_allclose(
            src.p_load, written[name]["load_spectra"].mean(axis=0), rtol=1e-15
        )
        np.testing.assert_allclose(src.p_ns, written[name]["ns_spectra"].mean(axis=0), rtol=1e-15)
        assert src.integration.source_s == pytest.approx(n_src * tau)
        assert src.integration.load_s == pytest.approx(n_load * tau)
        assert src.integration.ns_s == pytest.approx(n_ns * 2 * tau)


def test_missing_integration_time_is_reported(tmp_path, run_file):
    with h5py.File(run_file, "a") as f:
        del f["observation_data/r25_spectra"].attrs["integration_s_load"]
    with pytest.raises(FileFormatError, match=r"integration_s_load.*r25_spectra"):
        read_run(run_file)


def test_three_dimensional_spectra_are_refused(run_file, run):
    n = run.data.n_channels
    with h5py.File(run_file, "a") as f:
        del f["observation_data/r100_spectra"]
        ds = f["observation_data"].create_dataset("r100_spectra", data=np.ones((2, 2, n)))
        for position in ("source", "load", "ns"):
            ds.attrs[f"integration_s_{position}"] = 1.0
    with pytest.raises(FileFormatError, match=r"r100_spectra has shape \(2, 2, "):
        read_run(run_file)
