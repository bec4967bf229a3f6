"""``reach-cal solve`` with data preparation, calibrator consistency and the T_NS check.

In-process ``main([...])`` on a run written by ``reach-cal simulate`` (twelve calibrators,
820 channels of 8 iTPM channels, seed 3), changed where a test needs it: one calibrator's
stated temperature off, spikes injected into a spectrum. Orders are fixed at the truth's.
"""

from dataclasses import replace

import numpy as np
import pytest

from calibration.cli import main
from calibration.io.hdf5_io import read_run, write_run
from calibration.io.solution_file import read_solution
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ

ORDERS = ["--orders", "4,3,4,4,3"]


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("corrections") / "run.h5"
    width = str(8 * ITPM_CHANNEL_WIDTH_HZ)
    assert main(["simulate", "-o", str(path), "--seed", "3", "--channel-width-hz", width]) == 0
    return path


def changed_run(run_file, out, name, **fields):
    """The run with calibrator ``name``'s fields replaced (a function of the source)."""
    data, extra = read_run(run_file)
    source = data.sources[name]
    new = replace(source, **{k: f(source) for k, f in fields.items()})
    # a simulation of REACH's NC346A diode, as reach-cal simulate writes it
    attrs = {"noise_source_model": "NC346A"}
    write_run(out, replace(data, sources={**data.sources, name: new}), extra, attrs=attrs)
    return out


def solve(capsys, run, out, *options):
    status = main(["solve", str(run), "-o", str(out), *ORDERS, *options])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def test_band_mask_and_smoothing_are_applied_and_recorded(run_file, tmp_path, capsys):
    sol = tmp_path / "sol.h5"
    status, out, _ = solve(
        capsys, run_file, sol, "--band", "60,120", "--mask-band", "78,80",
        "--mask-band", "100,101", "--smooth-s11", "0.99999999",
    )  # fmt: skip
    assert status == 0
    data, _ = read_run(run_file)
    in_band = (data.freq_hz >= 60e6) & (data.freq_hz <= 120e6)
    masked = in_band & (
        ((data.freq_hz >= 78e6) & (data.freq_hz <= 80e6))
        | ((data.freq_hz >= 100e6) & (data.freq_hz <= 101e6))
    )
    assert f"band 60-120 MHz: {np.count_nonzero(in_band)} of {data.n_channels} channels" in out
    assert f"{np.count_nonzero(masked)} channels dropped" in out
    assert "reflections smoothed: factor 1" in out
    solution = read_solution(sol)
    assert solution.metadata["masked_channels"] == np.count_nonzero(masked)
    assert solution.metadata["band_mhz"] == [60.0, 120.0]
    assert solution.basis.f_lo_hz >= 60e6
    assert solution.basis.f_hi_hz <= 120e6


def test_rfi_spikes_are_flagged_and_dropped(run_file, tmp_path, capsys):
    data, _ = read_run(run_file)
    spikes = np.array([100, 333, 500, 701])

    def spiked(source):
        p = source.p_load.copy()
        p[spikes] *= 1.01  # about 100 radiometer sigma (820 channels, 600 s)
        return p

    run = changed_run(run_file, tmp_path / "rfi.h5", "r25", p_load=spiked)
    status, out, _ = solve(capsys, run, tmp_path / "sol.h5", "--rfi")
    assert status == 0
    meta = read_solution(tmp_path / "sol.h5").metadata
    assert meta["rfi_flagged_by_source"]["r25"] >= spikes.size
    assert spikes.size <= meta["rfi_flagged_channels"] <= spikes.size + 0.01 * data.n_channels
    assert f"RFI: {meta['rfi_flagged_channels']} of {data.n_channels} channels" in out


@pytest.mark.parametrize(("name", "offset_k"), [("c2r36", 1.0), ("c10open", -0.5)])
def test_inconsistent_calibrator_is_named_and_excluded(run_file, tmp_path, capsys, name, offset_k):
    run = changed_run(
        run_file, tmp_path / "wrong.h5", name, temperature_k=lambda s: s.temperature_k + offset_k
    )
    status, out, _ = solve(capsys, run, tmp_path / "check.h5", "--check-consistency")
    assert status == 0
    assert f"disagrees: {name}," in out
    assert name in read_solution(tmp_path / "check.h5").calibrators  # checked, not excluded
    status, out, _ = solve(capsys, run, tmp_path / "excl.h5", "--exclude-inconsistent")
    assert status == 0
    assert f"excluded: {name};" in out
    assert "stopped: no calibrator disagrees" in out
    solution = read_solution(tmp_path / "excl.h5")
    assert name not in solution.calibrators
    assert len(solution.calibrators) == 11
    assert solution.metadata["excluded_inconsistent"] == [name]


def test_noise_source_check_passes_and_fails(run_file, tmp_path, capsys):
    sol = tmp_path / "sol.h5"
    status, out, _ = solve(capsys, run_file, sol)
    assert status == 0
    assert "noise source PASS" in out
    assert main(["summary", str(sol)]) == 0
    assert "noise source PASS" in capsys.readouterr().out
    # A hot load stated 10 K too hot scales T_NS by ~82/72 (+0.56 dB): outside the table.
    hot = changed_run(
        run_file, tmp_path / "hot.h5", "hot", temperature_k=lambda s: s.temperature_k + 10.0
    )
    status, out, _ = solve(capsys, hot, tmp_path / "hot_sol.h5", "--check-consistency")
    assert status == 0
    assert "noise source FAIL" in out
    assert "consistent: no calibrator disagrees" in out  # only T_NS can show it


@pytest.mark.parametrize(
    "options",
    [["--band", "120,60"], ["--band", "60"], ["--smooth-s11", "1.5"], ["--alpha", "0"]],
)
def test_bad_options_exit_2(run_file, tmp_path, capsys, options):
    status, _, err = solve(capsys, run_file, tmp_path / "sol.h5", *options)
    assert status == 2
    assert "error" in err
