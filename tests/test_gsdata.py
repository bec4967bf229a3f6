"""reach-cal export --format gsdata: a season read back by pygsdata's own reader."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from pygsdata import GSData

from calibration.cli import main
from calibration.season.season_file import read_season
from tests.test_season import cycles, make_night, night_times, sky_k, write_run


@pytest.mark.parametrize(("start_lst_h", "width_h"), [(2.0, 1.0), (23.3, 0.5)])
def test_a_season_round_trips_through_pygsdata_s_reader(tmp_path, start_lst_h, width_h):
    """Over LST midnight too: each bin's range ends after it starts."""
    runs = []
    for k in range(2):
        night = make_night(60 + k)
        rng = np.random.default_rng(k)
        spectra = cycles(night, rng, 4, 600.0, sky_k(night.sim.data.freq_hz))
        flags = np.zeros((4, spectra[0].freq_hz.size), dtype=bool)
        flags[:, 7] = True
        runs.append(write_run(tmp_path / f"night{k}", night, spectra,
                              night_times(k, 4, start_lst_h=start_lst_h), flags))
    season_file, out = tmp_path / "season.h5", tmp_path / "out.gsh5"
    assert main(["season", *map(str, runs), "-o", str(season_file),
                 "--lst-bin-h", str(width_h)]) == 0
    assert main(["export", "--format", "gsdata", str(season_file), "-o", str(out)]) == 0
    season = read_season(season_file)
    keep = np.flatnonzero(~np.all(season.flags, axis=1))
    data = GSData.from_file(out)
    assert data.data.shape == (1, 1, keep.size, season.freq_hz.size)
    assert data.data_unit == "temperature"
    np.testing.assert_allclose(data.freqs.to_value("Hz"), season.freq_hz, rtol=1e-12)
    np.testing.assert_array_equal(data.data[0, 0], season.mean[keep])
    np.testing.assert_array_equal(data.nsamples[0, 0], np.where(
        season.flags[keep], 0.0, season.weight[keep]))
    np.testing.assert_array_equal(data.complete_flags[0, 0], season.flags[keep])
    assert data.complete_flags[0, 0, :, 7].all()
    aux = data.auxiliary_measurements
    np.testing.assert_array_equal(np.asarray(aux["calibration_error_k"]),
                                  season.std_calibration[keep])
    np.testing.assert_array_equal(np.asarray(aux["radiometer_error_k"]),
                                  season.std_radiometer[keep])
    np.testing.assert_allclose(data.lsts.hour[:, 0], season.lst_h[keep], atol=1e-9)
    # pygsdata's own sidereal time of each bin's time is the bin's centre LST
    own = data.times[:, 0].sidereal_time("apparent", data.telescope.location.lon).hour
    assert np.all(np.abs((own - season.lst_h[keep] + 12) % 24 - 12) < 1e-3)
    assert np.all(data.time_ranges.jd[..., 1] > data.time_ranges.jd[..., 0])
    location = data.telescope.location
    assert abs(location.lon.deg - 21.52) < 1e-9
    assert abs(location.lat.deg + 30.97) < 1e-9
    # again over the same output: a GSH5 is replaced whole, never appended to
    assert main(["export", "--format", "gsdata", str(season_file), "-o", str(out)]) == 0
    with h5py.File(out) as f:
        assert set(f) == {"metadata", "data", "auxiliary_measurements"}


def test_export_refuses_to_replace_a_run_file(tmp_path, capsys):
    night = make_night(70)
    run = write_run(tmp_path / "night", night,
                    cycles(night, np.random.default_rng(0), 2, 600.0,
                           sky_k(night.sim.data.freq_hz)), night_times(0, 2))
    season_file = tmp_path / "season.h5"
    assert main(["season", str(run), "-o", str(season_file)]) == 0
    before = run.read_bytes()
    assert main(["export", "--format", "gsdata", str(season_file), "-o", str(run)]) == 2
    assert "not a GSH5 file" in capsys.readouterr().err
    assert run.read_bytes() == before
