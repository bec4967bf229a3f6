"""One-port (SOL) calibration and calibration-kit models, against scikit-rf and closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import skrf
from skrf.calibration import OnePort
from skrf.media import DefinedGammaZ0

from calibration.core.errors import DegenerateStandardsError, InvalidDataError
from calibration.rf.cal_kit import (
    IDEAL_KIT,
    CalKit,
    LoadStandard,
    Offset,
    OpenStandard,
    ShortStandard,
    offset_reflection,
)
from calibration.rf.one_port import (
    OnePortTerms,
    correct_reflection,
    embed_reflection,
    solve_one_port,
)

SEEDS = range(50)
RTOL = 1e-12


def random_complex(rng, size, low, high):
    return rng.uniform(low, high, size) * np.exp(2j * np.pi * rng.uniform(size=size))


def random_freq(rng, n=None):
    """Random channels in the TR1300/1's range, 0.3 MHz to 1.3 GHz."""
    n = n or int(rng.integers(5, 60))
    return np.sort(rng.uniform(0.3e6, 1.3e9, n))


def random_terms(rng, freq):
    """Smooth, frequency-dependent error terms of realistic size."""
    x = freq / freq.max()

    def term(low, high, delay_s):
        a, b = random_complex(rng, 1, low, high)[0], random_complex(rng, 1, 0, 0.3)[0]
        return a * (1 + b * x) * np.exp(-2j * np.pi * freq * delay_s * rng.uniform(0.5, 2))

    return OnePortTerms(term(0.01, 0.2, 0.3e-9), term(0.05, 0.3, 1e-9), term(0.5, 1.0, 3e-9))


def random_offset(rng):
    return Offset(
        delay_s=rng.uniform(0, 100e-12),
        loss_gohm_per_s=rng.uniform(0, 5),
        z0_ohm=rng.uniform(45, 55),
    )


def random_kit(rng):
    """Coefficients in ranges around a Keysight 85033E's (C0 49 fF, C1 -310e-27 F/Hz, ...)."""
    c = rng.uniform([0, -500, -50, -1], [100, 500, 50, 1])
    inductance = rng.uniform([0, -200, -10, -0.1], [20, 200, 10, 0.1])
    return CalKit(
        short=ShortStandard(*inductance, offset=random_offset(rng)),
        open=OpenStandard(*c, offset=random_offset(rng)),
        load=LoadStandard(rng.uniform(45, 55), offset=random_offset(rng)),
        name="random",
    )


def extra_standards(rng, freq, count):
    """Further standards: offset shorts and mismatched loads."""
    out = []
    for i in range(count):
        if i % 2:
            out.append(LoadStandard(rng.uniform(10, 200), random_offset(rng)).reflection(freq))
        else:
            short = ShortStandard(l0=rng.uniform(0, 20), offset=random_offset(rng))
            out.append(short.reflection(freq))
    return np.stack(out) if out else np.empty((0, freq.size), dtype=complex)


def network(freq, s):
    return skrf.Network(frequency=skrf.Frequency.from_f(freq, unit="hz"), s=s, z0=50)


def assert_rel(ours, reference, rtol=RTOL):
    ours, reference = np.asarray(ours), np.asarray(reference)
    err = np.abs(ours - reference) / np.abs(reference)
    assert np.max(err) <= rtol, np.max(err)


# --- (a) against scikit-rf --------------------------------------------------------------


@pytest.mark.parametrize("seed", SEEDS)
def test_terms_and_correction_match_scikit_rf(seed):
    rng = np.random.default_rng((seed, 11))
    freq = random_freq(rng)
    truth = random_terms(rng, freq)
    actual = np.concatenate(
        [random_kit(rng).reflections(freq), extra_standards(rng, freq, seed % 3)]
    )
    measured = truth.embed(actual)
    if seed % 3 == 2:  # more standards than unknowns, and noisy: least squares proper
        measured = measured + random_complex(rng, measured.shape, 0, 1e-3)
    devices = random_complex(rng, (4, freq.size), 0.1, 1)  # relative errors need |G| > 0
    raw_devices = truth.embed(devices)

    terms = solve_one_port(measured, actual, freq)
    cal = OnePort(
        measured=[network(freq, m) for m in measured],
        ideals=[network(freq, a) for a in actual],
    )
    cal.run()
    assert_rel(terms.directivity, cal.coefs["directivity"])
    assert_rel(terms.source_match, cal.coefs["source match"])
    assert_rel(terms.reflection_tracking, cal.coefs["reflection tracking"])
    for raw in raw_devices:
        assert_rel(terms.correct(raw), cal.apply_cal(network(freq, raw)).s[:, 0, 0])
    if seed % 3 != 2:  # exact data: the truth itself
        for ours, true in zip(terms, truth, strict=True):
            assert_rel(ours, true, 1e-10)


# --- (b) round trip ----------------------------------------------------------------------


@pytest.mark.parametrize("seed", SEEDS)
def test_embed_then_correct_recovers_the_device(seed):
    rng = np.random.default_rng((seed, 12))
    freq = random_freq(rng)
    truth = random_terms(rng, freq)
    kit = random_kit(rng)
    terms = solve_one_port(truth.embed(kit.reflections(freq)), kit.reflections(freq), freq)
    device = random_complex(rng, (3, freq.size), 0, 1)
    assert (
        np.max(np.abs(correct_reflection(embed_reflection(device, truth), terms) - device)) < 1e-12
    )
    assert np.max(np.abs(terms.embed(terms.correct(device)) - device)) < 1e-12


def test_ideal_kit_with_the_simulators_vector_of_ideals():
    rng = np.random.default_rng(5)
    freq = random_freq(rng, 201)
    truth = random_terms(rng, freq)
    measured = truth.embed(IDEAL_KIT.reflections(freq))
    from_vector = solve_one_port(measured, np.array([-1, 1, 0], dtype=complex))
    from_kit = solve_one_port(measured, IDEAL_KIT.reflections(freq))
    from_list = solve_one_port(measured, [-1, 1, 0])
    for a, b, c, true in zip(from_vector, from_kit, from_list, truth, strict=True):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)
        assert_rel(a, true, 1e-12)
    e00, e11, tracking = from_vector  # unpacks like the simulator's tuple
    assert e00.shape == e11.shape == tracking.shape == freq.shape


def test_one_frequency_and_grids():
    rng = np.random.default_rng(6)
    terms = OnePortTerms(*random_complex(rng, 3, 0.1, 0.9))
    actual = np.array([-1, 1, 0, 0.5j])
    scalar = solve_one_port(terms.embed(actual), actual)
    assert scalar.directivity.shape == ()
    grid = random_complex(rng, (3, 4, 5), 0.1, 0.9)
    gterms = OnePortTerms(*grid)
    solved = solve_one_port(gterms.embed(actual[:, None, None]), actual)
    for ours, true in zip(solved, gterms, strict=True):
        assert ours.shape == (4, 5)
        assert_rel(ours, true, 1e-12)


# --- (c) kit model against closed forms --------------------------------------------------


@pytest.mark.parametrize("delay_s", [0.0, 17e-12, 250e-12, 3e-9])
def test_lossless_offset_short(delay_s):
    freq = np.linspace(0, 3e9, 301)
    got = ShortStandard(offset=Offset(delay_s=delay_s)).reflection(freq)
    np.testing.assert_allclose(got, -np.exp(-2j * 2 * np.pi * freq * delay_s), rtol=0, atol=1e-14)


@pytest.mark.parametrize("c0_ff", [0.0, 10.0, 79.0, 1000.0])
def test_open_with_only_c0(c0_ff):
    freq = np.linspace(0, 3e9, 301)
    jwcz = 1j * 2 * np.pi * freq * c0_ff * 1e-15 * 50
    got = OpenStandard(c0=c0_ff).reflection(freq)
    np.testing.assert_allclose(got, (1 - jwcz) / (1 + jwcz), rtol=0, atol=1e-15)


def test_ideal_kit_is_exact():
    freq = np.linspace(0, 3e9, 11)
    np.testing.assert_array_equal(
        IDEAL_KIT.reflections(freq), np.array([[-1], [1], [0]]) * np.ones_like(freq)
    )


def line_input_reflection(freq, z_t, offset, z_ref=50.0):
    """Transmission-line input impedance ``Zc (Z_T + Zc tanh gl) / (Zc + Z_T tanh gl)``."""
    w = 2 * np.pi * freq
    loss, root = offset.loss_gohm_per_s * 1e9, np.sqrt(freq / 1e9)
    alpha_l = loss * offset.delay_s * root / (2 * offset.z0_ohm)
    gamma_l = alpha_l + 1j * (w * offset.delay_s + alpha_l)
    zc = offset.z0_ohm + (1 - 1j) * loss * root / (2 * w)
    t = np.tanh(gamma_l)
    z_in = zc * (z_t + zc * t) / (zc + z_t * t)
    return gamma_l, zc, (z_in - z_ref) / (z_in + z_ref)


@pytest.mark.parametrize("seed", SEEDS)
def test_kit_against_line_impedance_and_scikit_rf_media(seed):
    rng = np.random.default_rng((seed, 13))
    freq = random_freq(rng)
    kit = random_kit(rng)
    w = 2 * np.pi * freq
    z_terms = (
        1j * w * kit.short.inductance_h(freq),
        1 / (1j * w * kit.open.capacitance_f(freq)),
        np.full(freq.shape, kit.load.resistance_ohm, dtype=complex),
    )
    offsets = (kit.short.offset, kit.open.offset, kit.load.offset)
    got = kit.reflections(freq)
    for g, z_t, offset in zip(got, z_terms, offsets, strict=True):
        gamma_l, zc, expected = line_input_reflection(freq, z_t, offset)
        np.testing.assert_allclose(g, expected, rtol=0, atol=1e-13)
        medium = DefinedGammaZ0(
            skrf.Frequency.from_f(freq, unit="hz"), z0_port=50, z0=zc, gamma=gamma_l
        )
        via_skrf = medium.line(1, "m") ** network(freq, (z_t - 50) / (z_t + 50))
        np.testing.assert_allclose(g, via_skrf.s[:, 0, 0], rtol=0, atol=1e-10)


def test_lossy_offset_attenuates_by_its_loss():
    """|G| of an offset short with Z0 = Zr is exp(-2 alpha l), alpha l = L tau sqrt(f/1G)/(2 Z0)."""
    freq = np.array([0.25e9, 1e9, 4e9])
    offset = Offset(delay_s=50e-12, loss_gohm_per_s=2.0, z0_ohm=50.0)
    alpha_l = 2e9 * 50e-12 * np.sqrt(freq / 1e9) / 100
    got = np.abs(offset_reflection(freq, -1.0, offset))
    # not exact: the lossy Zc (K4) differs from Zr by (1 - j) 0.3 ohm at 0.25 GHz
    np.testing.assert_allclose(got, np.exp(-2 * alpha_l), rtol=3e-3)
    assert np.all(got < 1)


def test_kit_rejects_bad_frequencies_and_offsets():
    with pytest.raises(InvalidDataError, match="0 Hz"):
        ShortStandard(offset=Offset(1e-12, 1.0)).reflection(np.array([0.0, 1e6]))
    with pytest.raises(InvalidDataError, match="finite"):
        IDEAL_KIT.reflections(np.array([1e6, np.nan]))
    with pytest.raises(InvalidDataError):
        Offset(loss_gohm_per_s=-1.0)


# --- (d) more than three standards -------------------------------------------------------


@pytest.mark.parametrize("seed", SEEDS)
def test_consistent_extra_standards_give_the_exact_solution(seed):
    rng = np.random.default_rng((seed, 14))
    freq = random_freq(rng)
    truth = random_terms(rng, freq)
    actual = np.concatenate([random_kit(rng).reflections(freq), extra_standards(rng, freq, 3)])
    measured = truth.embed(actual)
    exact = solve_one_port(measured[:3], actual[:3], freq)
    least_squares = solve_one_port(measured, actual, freq)
    for ls, ex, true in zip(least_squares, exact, truth, strict=True):
        assert_rel(ls, ex, 1e-12)
        assert_rel(ls, true, 1e-12)


# --- (e) degenerate standards ------------------------------------------------------------


def test_coinciding_standards_raise_naming_the_frequencies():
    freq = np.linspace(50e6, 200e6, 16)
    actual = IDEAL_KIT.reflections(freq)
    actual[2, [3, 11]] = actual[0, [3, 11]]  # the load is a short at two channels
    measured = random_terms(np.random.default_rng(7), freq).embed(actual)
    with pytest.raises(DegenerateStandardsError, match="standards 0 and 2") as info:
        solve_one_port(measured, actual, freq)
    assert info.value.freq_hz == (freq[3], freq[11])
    assert f"{freq[3]:.9g} Hz" in str(info.value)
    assert f"{freq[11]:.9g} Hz" in str(info.value)
    assert isinstance(info.value, ValueError)
    with pytest.raises(DegenerateStandardsError, match="channel 3, channel 11"):
        solve_one_port(measured, actual)


def test_four_standards_two_alike_are_still_enough():
    freq = np.linspace(50e6, 200e6, 5)
    actual = np.concatenate([IDEAL_KIT.reflections(freq), -np.ones((1, 5))])
    truth = random_terms(np.random.default_rng(8), freq)
    terms = solve_one_port(truth.embed(actual), actual, freq)
    assert_rel(terms.directivity, truth.directivity, 1e-12)
    with pytest.raises(DegenerateStandardsError, match="5 frequencies"):
        solve_one_port(truth.embed(actual[[0, 1, 3]]), actual[[0, 1, 3]], freq)


def test_identical_readings_raise():
    freq = np.linspace(50e6, 200e6, 5)
    measured = np.tile(0.3 + 0.1j, (3, 5))
    measured[:, 2] = [0.1, 0.2, 0.3]
    with pytest.raises(DegenerateStandardsError, match="singular") as info:
        solve_one_port(measured, [-1, 1, 0], freq)
    assert info.value.freq_hz == (freq[0], freq[1], freq[3], freq[4])


def test_bad_inputs():
    with pytest.raises(InvalidDataError, match="three standards"):
        solve_one_port(np.zeros((2, 4)), [-1, 1])
    with pytest.raises(InvalidDataError, match="do not match"):
        solve_one_port(np.zeros((3, 4)), np.zeros((3, 5)))
    with pytest.raises(InvalidDataError, match="do not match"):
        solve_one_port(np.zeros((3, 4)), [-1, 1])
    with pytest.raises(InvalidDataError, match="non-finite"):
        solve_one_port(np.full((3, 4), np.nan), [-1, 1, 0])
