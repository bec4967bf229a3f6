"""Two-port de-embedding and embedding (thesis eqs. 4.4-4.7), against scikit-rf and identities."""

from __future__ import annotations

import numpy as np
import pytest
import skrf
from skrf.network import s2t as skrf_s2t

from calibration.core.errors import InvalidDataError
from calibration.rf.two_port import (
    cascade,
    check_port_order,
    check_two_port,
    compare_port_order,
    deembed_reflection,
    deembed_two_port,
    embed_reflection,
    flip_ports,
    interpolate_s,
    s_to_t,
    t_to_s,
)

SEEDS = range(40)
N_FREQ = 64


def random_complex(rng, size, low=0.0, high=1.0):
    return rng.uniform(low, high, size) * np.exp(2j * np.pi * rng.uniform(size=size))


def random_two_port(rng, n=N_FREQ, max_gain=0.99):
    """Reciprocal passive two-ports, one per frequency: Takagi form ``U diag(sigma) U^T``."""
    z = rng.normal(size=(n, 2, 2)) + 1j * rng.normal(size=(n, 2, 2))
    u, _ = np.linalg.qr(z)
    sigma = rng.uniform(0.2, max_gain, (n, 2))
    return u @ (sigma[:, :, None] * np.swapaxes(u, -1, -2))


def random_general_two_port(rng, n=N_FREQ):
    """Any two-port (not reciprocal, not passive) with |S21| well away from 0."""
    s = random_complex(rng, (n, 2, 2), 0.0, 0.6)
    s[:, 1, 0] = random_complex(rng, n, 0.3, 1.0)
    return s


def skrf_network(s, freq_hz):
    return skrf.Network(frequency=skrf.Frequency.from_f(freq_hz, unit="hz"), s=s)


def freq_grid(n=N_FREQ):
    return np.linspace(50e6, 200e6, n)


@pytest.mark.parametrize("seed", SEEDS)
def test_deembedding_recovers_the_source(seed):
    """A source seen through a simulated switch path (cascaded by scikit-rf, in its own
    port-1-at-the-VNA convention) comes back to 1e-12 (the thesis checked 1e-6, fig. 4.17)."""
    rng = np.random.default_rng(seed)
    f = freq_grid()
    fixture_vna_first = random_general_two_port(rng)
    source = random_complex(rng, N_FREQ, 0.0, 1.0)
    measured = skrf_network(fixture_vna_first, f) ** skrf_network(source[:, None, None], f)
    ours = deembed_reflection(measured.s[:, 0, 0], flip_ports(fixture_vna_first))
    np.testing.assert_allclose(ours, source, rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_embed_then_deembed_is_the_identity(seed):
    rng = np.random.default_rng(seed)
    s = random_general_two_port(rng)
    gamma = random_complex(rng, N_FREQ, 0.0, 1.0)
    np.testing.assert_allclose(deembed_reflection(embed_reflection(gamma, s), s), gamma,
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(embed_reflection(deembed_reflection(gamma, s), s), gamma,
                               rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_agrees_with_scikit_rf_deembedding(seed):
    """``fixture.inv ** measured`` in scikit-rf equals eq. (4.6) on the flipped fixture."""
    rng = np.random.default_rng(seed)
    f = freq_grid()
    fixture = skrf_network(random_general_two_port(rng), f)
    measured = skrf_network(random_complex(rng, N_FREQ, 0.0, 1.0)[:, None, None], f)
    reference = (fixture.inv ** measured).s[:, 0, 0]
    ours = deembed_reflection(measured.s[:, 0, 0], flip_ports(fixture.s))
    np.testing.assert_allclose(ours, reference, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_transfer_parameters_and_cascades_agree_with_scikit_rf(seed):
    rng = np.random.default_rng(seed)
    f = freq_grid()
    a, x, b = (random_general_two_port(rng) for _ in range(3))
    np.testing.assert_allclose(s_to_t(a), skrf_s2t(a), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(t_to_s(s_to_t(a)), a, rtol=0, atol=1e-12)
    total = cascade(a, x, b)
    ref = skrf_network(a, f) ** skrf_network(x, f) ** skrf_network(b, f)
    np.testing.assert_allclose(total, ref.s, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(deembed_two_port(total, left=a, right=b), x, rtol=0, atol=1e-10)


@pytest.mark.parametrize("seed", SEEDS)
def test_embedding_agrees_with_a_cascade(seed):
    """Eq. (4.7): the LNA seen through the J2->J4 path is the flipped path ** the LNA."""
    rng = np.random.default_rng(seed)
    f = freq_grid()
    s = random_two_port(rng)
    lna = random_complex(rng, N_FREQ, 0.0, 0.1)
    ref = skrf_network(flip_ports(s), f) ** skrf_network(lna[:, None, None], f)
    np.testing.assert_allclose(embed_reflection(lna, s), ref.s[:, 0, 0], rtol=0, atol=1e-13)


@pytest.mark.parametrize("seed", SEEDS)
def test_passive_reciprocal_paths_pass_the_checks(seed):
    s = random_two_port(np.random.default_rng(seed))
    check = check_two_port(s)
    assert check.ok, str(check)
    assert np.max(check.reciprocity) < 1e-12
    assert np.max(check.passivity_excess) < 1e-12


def test_a_non_reciprocal_file_is_reported_at_its_worst_frequency():
    rng = np.random.default_rng(1)
    s = random_two_port(rng)
    f = freq_grid()
    s[17, 0, 1] *= 1.1  # 10 % off at one frequency
    check = check_two_port(s, f, name="MTS J1-J2")
    assert not check.ok
    assert len(check.problems) == 1
    assert "MTS J1-J2 not reciprocal" in check.problems[0]
    assert f"{f[17] / 1e6:.3f} MHz" in check.problems[0]
    assert "(1 of 64 frequencies" in check.problems[0]


def test_an_active_file_is_reported():
    s = random_two_port(np.random.default_rng(2)) * 1.2
    check = check_two_port(s)
    assert not check.ok
    assert "not passive" in str(check)


def asymmetric_path(rng, n=N_FREQ):
    """A switch path with different port matches: a mismatch (a 60-70 ohm step) behind a line."""
    s = random_two_port(rng, n)
    s[:, 0, 0] = s[:, 0, 0] * 0.05 + 0.15 * np.exp(2j * np.pi * rng.uniform())
    s[:, 1, 1] = s[:, 1, 1] * 0.05
    return s


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("expected", [0.0, 1.0, -1.0])
def test_a_swapped_recording_is_named_from_a_known_source(seed, expected):
    """A matched load, an open and a short read through the path: each tells the port order."""
    rng = np.random.default_rng(seed)
    s = asymmetric_path(rng)
    truth = np.full(N_FREQ, expected, dtype=complex)
    measured = embed_reflection(truth + random_complex(rng, N_FREQ, 0, 1e-3), s)  # VNA noise
    assert check_port_order(s, measured, truth).verdict == "as recorded"
    swapped = check_port_order(flip_ports(s), measured, truth)
    assert swapped.swapped, str(swapped)


def test_a_symmetric_path_is_undecided():
    rng = np.random.default_rng(3)
    s = random_two_port(rng)
    s[:, 1, 1] = s[:, 0, 0]
    measured = embed_reflection(np.zeros(N_FREQ), s)
    assert check_port_order(s, measured, 0.0).verdict == "undecided"


@pytest.mark.parametrize("seed", SEEDS)
def test_a_swapped_recording_is_named_against_an_earlier_file(seed):
    rng = np.random.default_rng(seed)
    s = asymmetric_path(rng)
    remeasured = s + random_complex(rng, s.shape, 0, 2e-3)
    assert compare_port_order(remeasured, s).verdict == "as recorded"
    assert compare_port_order(flip_ports(remeasured), s).swapped


def test_interpolation_is_exact_on_the_grid_and_linear_between():
    rng = np.random.default_rng(4)
    f = freq_grid()
    s = random_general_two_port(rng)
    np.testing.assert_array_equal(interpolate_s(f, s, f), s)
    mid = 0.5 * (f[:-1] + f[1:])
    np.testing.assert_allclose(interpolate_s(f, s, mid), 0.5 * (s[:-1] + s[1:]), atol=1e-15)
    with pytest.raises(InvalidDataError, match="no extrapolation"):
        interpolate_s(f, s, np.array([40e6]))


def test_bad_shapes_and_zero_transmission_are_refused():
    with pytest.raises(InvalidDataError, match=r"\(\.\.\., 2, 2\)"):
        deembed_reflection(0.1, np.zeros((4, 3, 3)))
    with pytest.raises(InvalidDataError, match="S21 = 0"):
        s_to_t(np.zeros((4, 2, 2)))
