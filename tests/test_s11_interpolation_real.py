"""Real VNA data: S11s measured on a coarse grid, interpolated onto spectrometer channels.

The daemon measures S11 on the VNA's grid and the engine needs it per channel
(:func:`reach_receiver.store.handover.interpolate_s11`: the one hand-over to the engine). The
EDGES-3 data set holds real VNA-corrected S11s on a 1.07 MHz grid and the EDGES
pipeline's own smooth models of them on its 48.8 kHz spectrum grid. The test: our
interpolation differs from those models by no more than the measurements themselves
scatter about the models at the grid points, i.e. interpolating adds no error of its own.
"""

from pathlib import Path

import numpy as np
import pytest

from calibration.io import edges_text as et
from reach_receiver.devices.vna import S11Measurement, SweepSettings
from reach_receiver.store.handover import interpolate_s11
from reach_receiver.store.touchstone import read_touchstone, write_touchstone

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "edges3-2022-316"
pytestmark = pytest.mark.skipif(
    not DATA.is_dir(),
    reason=f"the shared EDGES-3 data set is not beside this checkout (looked for {DATA})",
)
FILES = {"amb": "s11amb.csv", "hot": "s11hot.csv", "open": "s11open.csv",
         "short": "s11short.csv", "lna": "s11lna.csv"}


def measurement(name: str) -> S11Measurement:
    freq, s11 = et.read_s11_csv(DATA / FILES[name])
    return S11Measurement(freq, s11, SweepSettings(), 0.0, "EDGES-3 VNA", True)


@pytest.mark.parametrize("name", sorted(FILES))
def test_interpolation_adds_no_error_beyond_the_measurement_noise(name):
    freq_model, models = et.read_modelled_s11(DATA / "s11_modelled.txt")
    model = models[name]
    m = measurement(name)
    inside = (m.freq_hz >= freq_model[0]) & (m.freq_hz <= freq_model[-1])
    at_points = np.interp(m.freq_hz[inside], freq_model, model.real) + 1j * np.interp(
        m.freq_hz[inside], freq_model, model.imag
    )
    scatter = np.sqrt(np.mean(np.abs(m.s11[inside] - at_points) ** 2))
    ours = interpolate_s11(m.freq_hz, m.s11, freq_model)
    difference = np.sqrt(np.mean(np.abs(ours - model) ** 2))
    assert difference <= 1.5 * scatter, (difference, scatter)


def test_real_s11_survives_a_touchstone_round_trip(tmp_path):
    m = measurement("open")
    write_touchstone(tmp_path / "open.s1p", m.freq_hz, m.s11, comment="EDGES-3 open, 2022-316")
    freq, s11, z0 = read_touchstone(tmp_path / "open.s1p")
    np.testing.assert_allclose(freq, m.freq_hz, rtol=1e-12)
    np.testing.assert_allclose(s11, m.s11, rtol=0, atol=1e-12)
    assert z0 == 50.0
