"""Source temperature models (thesis eqs. 3.15-3.16, 4.8-4.11, 5.1) and lossy-coax two-ports.

The independent reference is the noise-wave sum of a passive network in thermal
equilibrium (Bosma's theorem: noise-wave correlation ``k T (I - S S^H)``), evaluated
exactly, and scikit-rf's transmission-line media for the cable S-parameters.
"""

from __future__ import annotations

import numpy as np
import pytest
import skrf
from skrf.media import DefinedGammaZ0

from calibration.core.errors import InvalidDataError
from calibration.io.edges_text import UT141C, coax_power_gain
from calibration.model.reflections import Cable, terminated_cable
from calibration.model.source_temperatures import (
    antenna_loss_correction,
    available_gain,
    cable_source_temperature,
    split_cable_temperature,
    terminating_load_temperature,
)
from calibration.rf.coax import DataSheetCoax, PhysicalCoax, line_s_parameters
from calibration.rf.two_port import deembed_reflection, embed_reflection

SEEDS = range(30)
FREQ = np.linspace(50e6, 200e6, 61)


def random_complex(rng, size, high):
    return rng.uniform(0, high, size) * np.exp(2j * np.pi * rng.uniform(size=size))


def random_cable(rng):
    return DataSheetCoax(
        length_m=rng.uniform(0.1, 30.0),
        velocity_factor=rng.uniform(0.6, 0.9),
        loss_db_per_m=rng.uniform(0.02, 0.5),
        ref_freq_hz=rng.uniform(50e6, 500e6),
        loss_exponent=rng.uniform(0.4, 1.0),
        z0_ohm=rng.uniform(45.0, 55.0),
    )


def random_passive(rng, n):
    """Any passive two-port (not necessarily reciprocal): ``U diag(sigma) V^H``, sigma < 1."""
    def unitary():
        q, _ = np.linalg.qr(rng.normal(size=(n, 2, 2)) + 1j * rng.normal(size=(n, 2, 2)))
        return q
    sigma = rng.uniform(0.05, 0.98, (n, 2))
    return unitary() @ (sigma[:, :, None] * np.conj(np.swapaxes(unitary(), -1, -2)))


def bosma_temperature(s, gamma_term, t_term, t_cab):
    """Available noise temperature at port 2, summing noise waves (k = B = 1).

    The termination emits ``c_R`` (variance ``T_R (1 - |G_R|^2)``), the cable ``c1, c2``
    (covariance ``T_cab (I - S S^H)``); port 2 into a matched load (``a2 = 0``)::

        a1 = G_R b1 + c_R,  b1 = S11 a1 + c1,  b2 = S21 a1 + c2
    """
    n = s.shape[0]
    d = 1 - gamma_term * s[:, 0, 0]
    h = np.stack([s[:, 1, 0] * gamma_term / d, np.ones(n), s[:, 1, 0] / d], axis=-1)
    cov = np.zeros((n, 3, 3), dtype=complex)
    cov[:, :2, :2] = t_cab * (np.eye(2) - s @ np.conj(np.swapaxes(s, -1, -2)))
    cov[:, 2, 2] = t_term * (1 - np.abs(gamma_term) ** 2)
    power = np.einsum("ni,nij,nj->n", h, cov, np.conj(h)).real
    gamma_out = embed_reflection(gamma_term, s)
    return power / (1 - np.abs(gamma_out) ** 2)


@pytest.mark.parametrize("seed", SEEDS)
def test_effective_temperature_equals_the_noise_wave_sum_for_any_passive_cable(seed):
    rng = np.random.default_rng(seed)
    n = FREQ.size
    s = random_passive(rng, n) if seed % 2 else random_cable(rng).s_parameters(FREQ)
    gamma_term = random_complex(rng, n, 0.95)
    t_term, t_cab = rng.uniform(250, 400), rng.uniform(250, 320)
    gain = available_gain(s, gamma_term)
    assert np.all((gain >= 0) & (gain <= 1 + 1e-12))
    ours = cable_source_temperature(gain, t_term, t_cab)
    np.testing.assert_allclose(ours, bosma_temperature(s, gamma_term, t_term, t_cab),
                               rtol=1e-10)


@pytest.mark.parametrize("seed", SEEDS)
def test_a_matched_lossless_cable_gives_the_termination_temperature(seed):
    rng = np.random.default_rng(seed)
    cable = DataSheetCoax(rng.uniform(0.1, 30), rng.uniform(0.6, 0.9), loss_db_per_m=0.0)
    gamma_term = random_complex(rng, FREQ.size, 0.95)
    gain = available_gain(cable.s_parameters(FREQ), gamma_term)
    np.testing.assert_allclose(gain, 1.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cable_source_temperature(gain, 370.0, 300.0), 370.0, atol=1e-9)


@pytest.mark.parametrize("seed", SEEDS)
def test_a_fully_lossy_cable_gives_the_cable_temperature(seed):
    rng = np.random.default_rng(seed)
    cable = DataSheetCoax(rng.uniform(50, 100), 0.8, loss_db_per_m=rng.uniform(20, 40),
                          z0_ohm=rng.uniform(45, 55))
    gain = available_gain(cable.s_parameters(FREQ), random_complex(rng, FREQ.size, 0.95))
    assert np.max(gain) < 1e-50
    np.testing.assert_allclose(cable_source_temperature(gain, 370.0, 300.0), 300.0, atol=1e-9)


@pytest.mark.parametrize("seed", SEEDS)
def test_a_matched_lossy_cable_with_a_matched_load_transmits_its_loss(seed):
    rng = np.random.default_rng(seed)
    loss_db, length = rng.uniform(0.05, 1.0), rng.uniform(0.5, 20)
    cable = DataSheetCoax(length, 0.8, loss_db, ref_freq_hz=FREQ[10])
    gain = available_gain(cable.s_parameters(FREQ[10:11]), np.zeros(1))
    np.testing.assert_allclose(gain, 10 ** (-loss_db * length / 10), rtol=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_cable_s_parameters_agree_with_scikit_rf_lines(seed):
    rng = np.random.default_rng(seed)
    frequency = skrf.Frequency.from_f(FREQ, unit="hz")
    cable = random_cable(rng)
    gl = cable.propagation(FREQ)
    medium = DefinedGammaZ0(frequency, z0_port=50, z0=cable.z0_ohm, gamma=gl / cable.length_m)
    np.testing.assert_allclose(cable.s_parameters(FREQ), medium.line(cable.length_m, "m").s,
                               rtol=1e-10, atol=1e-13)
    physical = PhysicalCoax(**{**UT141C, "length": rng.uniform(0.05, 5.0),
                               "tan_d": rng.uniform(0, 1e-3)})
    zc, gl = physical.line_constants(FREQ)
    medium = DefinedGammaZ0(frequency, z0_port=50, z0=zc, gamma=gl / physical.length)
    np.testing.assert_allclose(physical.s_parameters(FREQ), medium.line(physical.length, "m").s,
                               rtol=1e-10, atol=1e-13)


@pytest.mark.parametrize("seed", SEEDS)
def test_data_sheet_cable_matches_the_reflection_models_cable(seed):
    rng = np.random.default_rng(seed)
    length, vf, loss = rng.uniform(0.1, 20), rng.uniform(0.6, 0.9), rng.uniform(0.01, 0.5)
    gamma_term = random_complex(rng, FREQ.size, 1.0)
    ours = embed_reflection(gamma_term, DataSheetCoax(length, vf, loss).s_parameters(FREQ))
    np.testing.assert_allclose(ours, terminated_cable(FREQ, gamma_term, Cable(length, vf, loss)),
                               rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_physical_cable_reproduces_the_edges_hot_load_gain(seed):
    """edges_text.coax_power_gain is available_gain on PhysicalCoax with the termination
    de-embedded from the S11 at the cable input (CODATA 2018 vs 2022 mu0: 1e-9)."""
    rng = np.random.default_rng(seed)
    gamma_in = random_complex(rng, FREQ.size, 0.3)
    s = PhysicalCoax(**UT141C).s_parameters(FREQ)
    ours = available_gain(s, deembed_reflection(gamma_in, s), gamma_in)
    np.testing.assert_allclose(ours, coax_power_gain(FREQ, gamma_in), rtol=1e-8)


@pytest.mark.parametrize("seed", SEEDS)
def test_terminating_load_temperature_inverts_the_source_temperature(seed):
    rng = np.random.default_rng(seed)
    gain = available_gain(random_cable(rng).s_parameters(FREQ), random_complex(rng, 61, 0.5))
    t_load, t_cab = rng.uniform(200, 5000, FREQ.size), rng.uniform(270, 320)
    t_ant = cable_source_temperature(gain, t_load, t_cab)
    np.testing.assert_allclose(terminating_load_temperature(t_ant, gain, t_cab), t_load,
                               rtol=1e-12)


def test_split_cable_temperature_is_the_exact_cascade_to_second_order_in_loss():
    """The mock antenna (28 cm inside at 303 K, 100 cm outside at 283 K, 0.1 dB/m): eq. (4.11)
    in (4.9) against the exact matched-line cascade, termination -> outside -> inside."""
    g_int, g_ext = 10 ** (-0.1 * 0.28 / 10), 10 ** (-0.1 * 1.00 / 10)
    t_load, t_int, t_ext = 350.0, 303.0, 283.0
    exact = g_int * g_ext * t_load + g_int * (1 - g_ext) * t_ext + (1 - g_int) * t_int
    t_cab = split_cable_temperature(t_int, 0.28, t_ext, 1.00)
    np.testing.assert_allclose(t_cab, (303.0 * 0.28 + 283.0 * 1.00) / 1.28, rtol=1e-15)
    approx = cable_source_temperature(g_int * g_ext, t_load, t_cab)
    first_order = (1 - g_int * g_ext) * abs(t_int - t_ext)  # what ignoring the split costs
    assert abs(approx - exact) < 0.02 * first_order
    assert abs(approx - exact) < 2e-3  # kelvin


@pytest.mark.parametrize("seed", SEEDS)
def test_antenna_loss_correction_recovers_the_sky(seed):
    rng = np.random.default_rng(seed)
    loss_db = rng.uniform(0, 3, FREQ.size)
    eta = 10 ** (-loss_db / 10)
    t_sky, t_amb = rng.uniform(200, 8000, FREQ.size), rng.uniform(270, 320)
    t_raw = eta * t_sky + (1 - eta) * t_amb  # an attenuator at t_amb in front of the sky
    np.testing.assert_allclose(antenna_loss_correction(t_raw, t_amb, loss_db), t_sky, rtol=1e-12)


def test_a_lossy_antenna_at_equilibrium_calibrates_to_ambient_unlike_the_printed_eq_5_1():
    loss_db, t_amb = 1.0, 300.0
    assert antenna_loss_correction(t_amb, t_amb, loss_db) == pytest.approx(t_amb, rel=1e-14)
    eta = 10 ** (-loss_db / 10)
    printed = (t_amb - t_amb * (eta - 1)) / eta  # eq. (5.1) as printed in the thesis
    assert printed - t_amb > 100.0


def test_bad_inputs_are_refused():
    with pytest.raises(InvalidDataError, match="no available power"):
        available_gain(np.eye(2)[None], np.zeros(1), gamma_src=np.ones(1))
    with pytest.raises(InvalidDataError, match="G <= 0"):
        terminating_load_temperature(300.0, 0.0, 300.0)
    with pytest.raises(InvalidDataError, match="lengths"):
        split_cable_temperature(300.0, -1.0, 290.0, 1.0)
    with pytest.raises(InvalidDataError, match="antenna loss"):
        antenna_loss_correction(300.0, 300.0, -0.1)
    with pytest.raises(InvalidDataError, match="not a physical cable"):
        DataSheetCoax(1.0, velocity_factor=1.5, loss_db_per_m=0.1)
    with pytest.raises(InvalidDataError, match="not a physical coaxial"):
        PhysicalCoax(**{**UT141C, "b": 1e-4})
    with pytest.raises(InvalidDataError, match="frequencies"):
        DataSheetCoax(1.0, 0.8, 0.1).s_parameters(np.array([0.0]))
    np.testing.assert_allclose(line_s_parameters(50.0, np.zeros(1))[0], [[0, 1], [1, 0]])
