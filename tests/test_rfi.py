"""RFI flags (calibration.checks.rfi): injected spikes and bursts found, clean channels left alone.

Spikes are 1-3 channels wide at 8-100 sigma of the radiometer noise (log-uniform), on a
REACH-like bandpass (a sky power law with a 0.5 % ripple of 10 MHz period); bursts last one
spectrum and raise 128-512 contiguous channels by 1-3 sigma each.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.checks.rfi import flag_dynamic_spectrum, flag_sky, flag_spectrum, robust_sigma
from calibration.core.errors import InvalidDataError

SEEDS = range(6)
AMPLITUDES = [(8.0, 12.0), (12.0, 30.0), (30.0, 100.0)]


def bandpass(n):
    f = np.linspace(50e6, 130e6, n)
    return (300 + 2000 * (f / 75e6) ** -2.5) * (1 + 0.005 * np.sin(2 * np.pi * f / 10e6))


def spike_positions(rng, n_channels, count):
    """``count`` spikes (start, width) at least 4 channels apart, away from the edges."""
    starts = np.sort(rng.choice(np.arange(20, n_channels - 20, 8), count, replace=False))
    return [(int(s), int(rng.integers(1, 4))) for s in starts]


def inject_spikes(rng, x, sigma, positions, amplitudes, row=None):
    for (start, width), amp in zip(positions, rng.uniform(*np.log(amplitudes), len(positions)),
                                   strict=True):
        where = slice(start, start + width)
        scale = x[where] if row is None else x[row, where]
        bump = np.exp(amp) * sigma * scale
        if row is None:
            x[where] += bump
        else:
            x[row, where] += bump


def spike_mask(shape, positions, rows=None):
    mask = np.zeros(shape, bool)
    for i, (start, width) in enumerate(positions):
        if rows is None:
            mask[start:start + width] = True
        else:
            mask[rows[i], start:start + width] = True
    return mask


@pytest.mark.parametrize("amplitudes", AMPLITUDES)
@pytest.mark.parametrize("seed", SEEDS)
def test_spikes_in_an_averaged_spectrum(seed, amplitudes):
    rng = np.random.default_rng(seed)
    n, sigma = 4096, 1e-3
    x = bandpass(n) * (1 + sigma * rng.standard_normal(n))
    positions = spike_positions(rng, n, 60)
    inject_spikes(rng, x, sigma, positions, amplitudes)
    flags = flag_spectrum(x)
    caught = [np.all(flags[s:s + w]) for s, w in positions]
    clean = ~spike_mask(n, positions)
    assert np.mean(caught) >= 0.99, f"caught {np.mean(caught):.3f}"
    assert np.mean(flags[clean]) <= 0.01, f"clean flagged {np.mean(flags[clean]):.4f}"


@pytest.mark.parametrize("seed", SEEDS)
def test_flags_given_are_kept_and_data_untouched(seed):
    rng = np.random.default_rng(seed)
    x = bandpass(1024) * (1 + 1e-3 * rng.standard_normal(1024))
    before = x.copy()
    given = np.zeros(1024, bool)
    given[:40] = True
    flags = flag_spectrum(x, given)
    assert np.all(flags[:40])
    np.testing.assert_array_equal(x, before)
    grown = flag_spectrum(np.where(np.arange(1024) == 500, 2 * x, x), grow=2)
    assert np.all(grown[498:503])


def dynamic_run(rng, n_t=48, n_c=1024, sigma=0.01):
    gain = 1 + 0.02 * rng.standard_normal((n_t, 1))  # gain drifts between spectra
    return bandpass(n_c)[None, :] * gain * (1 + sigma * rng.standard_normal((n_t, n_c)))


@pytest.mark.parametrize("amplitudes", AMPLITUDES)
@pytest.mark.parametrize("seed", SEEDS)
def test_spikes_and_bursts_in_a_dynamic_spectrum(seed, amplitudes):
    rng = np.random.default_rng(100 + seed)
    n_t, n_c, sigma = 48, 1024, 0.01
    x = dynamic_run(rng, n_t, n_c, sigma)
    rows = rng.integers(0, n_t, 60)
    positions = spike_positions(rng, n_c, 60)
    for row, pos in zip(rows, positions, strict=True):
        inject_spikes(rng, x, sigma, [pos], amplitudes, row=row)
    burst = np.zeros(x.shape, bool)
    for row in rng.choice(n_t, 3, replace=False):
        start, width = int(rng.integers(0, n_c - 512)), int(rng.integers(128, 513))
        burst[row, start:start + width] = True
        x[row, start:start + width] *= 1 + rng.uniform(1, 3) * sigma
    result = flag_dynamic_spectrum(x)
    caught = [np.all(result.flags[r, s:s + w]) for r, (s, w) in zip(rows, positions, strict=True)]
    assert np.mean(caught) >= 0.99, f"caught {np.mean(caught):.3f}"
    assert np.mean(result.flags[burst]) >= 0.9, f"burst pixels {np.mean(result.flags[burst]):.3f}"
    assert np.all(np.any(result.bursts, axis=1)[np.any(burst, axis=1)])
    clean = ~(spike_mask(x.shape, positions, rows) | burst)
    assert np.mean(result.flags[clean]) <= 0.01, f"clean flagged {np.mean(result.flags[clean]):.4f}"


@pytest.mark.parametrize("seed", SEEDS)
def test_a_persistent_line_is_flagged_at_every_time(seed):
    rng = np.random.default_rng(200 + seed)
    x = dynamic_run(rng)
    x[:, 300] *= 1.05  # 5 sigma per spectrum, always on: the time median absorbs it
    result = flag_dynamic_spectrum(x)
    assert np.all(result.lines[:, 300])
    assert np.mean(result.flags[:, np.arange(1024) != 300]) <= 0.01
    assert "persistent line" in str(result)


def test_clean_data_is_hardly_flagged():
    rng = np.random.default_rng(5)
    result = flag_dynamic_spectrum(dynamic_run(rng))
    assert result.fraction <= 1e-3


def test_robust_sigma_ignores_outliers():
    rng = np.random.default_rng(6)
    x = rng.standard_normal(100000)
    x[:1000] = 1e6
    assert robust_sigma(x) == pytest.approx(1.0, rel=0.02)


def test_bad_input_is_refused():
    with pytest.raises(InvalidDataError, match="odd window"):
        flag_spectrum(np.ones(100), window=30)
    with pytest.raises(InvalidDataError, match="positive"):
        flag_spectrum(-np.ones(100))
    with pytest.raises(InvalidDataError, match="every channel"):
        flag_spectrum(np.ones(100), np.ones(100, bool))
    with pytest.raises(InvalidDataError, match=">= 3 spectra"):
        flag_dynamic_spectrum(np.ones((2, 100)))


def test_a_spectrum_without_noise_flags_nothing():
    """A constant or model spectrum (EDGES-3's files hold T*; their load and noise-source
    powers are constants) has no noise to judge a spike against: nothing is flagged, where
    a zero scale once flagged rounding residuals and then, iterating, 85 % of the band."""
    assert not flag_spectrum(np.full(2868, 300.0)).any()
    smooth = 300.0 * (1 + 0.1 * np.linspace(-1, 1, 2868) ** 2)
    assert not flag_spectrum(smooth).any()


@pytest.mark.parametrize(("seed", "integration_s"), [(1, 600.0), (2, 3600.0), (3, 36000.0)])
def test_cable_sources_own_spectra_are_not_overflagged_and_their_spikes_are_found(
    seed, integration_s
):
    """The 2 m and 10 m cable sources ripple by tens of percent (``calibrate.simulate``):
    the trend follows them, so a clean run flags no calibrator channel (5 sigma: ~0.2 false
    flags expected in 12 x 3 x 6554 channels), and spikes injected into one cable source's
    own spectrum alone are all found."""
    from calibration import simulate_run
    from calibration.checks.rfi import calibrator_flags
    from calibration.model.simulate import SimulationConfig

    data = simulate_run(SimulationConfig(integration_s=integration_s), rng=seed).data
    flags, counts = calibrator_flags(data)
    assert flags.sum() <= 2, counts
    rng = np.random.default_rng(seed)
    source = data.sources["c10open"]
    p = source.p_source.copy()
    sigma = 1 / np.sqrt(data.channel_width_hz * source.integration.source_s)  # eq. 2.3
    positions = spike_positions(rng, p.size, 20)
    inject_spikes(rng, p, sigma, positions, (8.0, 30.0))
    from dataclasses import replace

    spiked = replace(data, sources={**data.sources, "c10open": replace(source, p_source=p)})
    flags, counts = calibrator_flags(spiked)
    truth = spike_mask(p.shape, positions)
    assert np.all(flags[truth]), counts
    assert np.count_nonzero(flags & ~truth) <= 0.01 * np.count_nonzero(~truth)


def clean_sky(rng, index, lo_mhz, hi_mhz, seconds, trough, n=4096):
    """A power-law sky (K) with radiometer noise ``T / sqrt(B tau)``, maybe a 21-cm trough."""
    f = np.linspace(lo_mhz, hi_mhz, n)
    t = 5000.0 * (f / 50.0) ** index
    if trough:  # EDGES-like: 0.5 K deep, 20 MHz wide, at 78 MHz
        t -= 0.5 * np.exp(-0.5 * ((f - 78.0) / 8.5) ** 2)
    width_hz = (f[1] - f[0]) * 1e6
    return t * (1 + rng.standard_normal(n) / np.sqrt(width_hz * seconds))


@pytest.mark.parametrize("seed", range(3))
def test_a_clean_sky_is_not_flagged_over_a_family_of_skies(seed):
    """Indices -2.2 to -2.8, bands within 40-200 MHz, 1 s to 1 h, with and without a trough.

    At 5 sigma a Gaussian channel exceeds by chance with probability 2.9e-7: over the 12
    spectra of 4096 channels here, 0.014 false flags are expected; one is allowed.
    """
    rng = np.random.default_rng(seed)
    flagged = 0
    for _ in range(12):
        lo = rng.uniform(40.0, 80.0)
        sky = clean_sky(rng, rng.uniform(-2.8, -2.2), lo, rng.uniform(lo + 50.0, 200.0),
                        10 ** rng.uniform(0.0, np.log10(3600.0)), rng.random() < 0.5)
        flagged += int(flag_sky(sky).sum())
    assert flagged <= 1


def test_flag_sky_finds_spikes_where_the_sky_is_hot_and_where_it_is_cold():
    rng = np.random.default_rng(7)
    sky = clean_sky(rng, -2.5, 50.0, 130.0, 600.0, trough=True)
    noise = sky / np.sqrt(80e6 / 4096 * 600.0)
    spikes = [100, 1500, 3900]  # 51, 79 and 126 MHz
    sky[spikes] += 8 * noise[spikes]
    flags = flag_sky(sky)
    assert set(np.flatnonzero(flags)) >= set(spikes)
    assert flags.sum() <= len(spikes) + 2


def test_flag_sky_flags_unusable_channels_and_keeps_judging_the_rest():
    rng = np.random.default_rng(8)
    sky = clean_sky(rng, -2.5, 50.0, 130.0, 600.0, trough=False)
    sky[[10, 11, 2000]] = [np.nan, -3.0, 0.0]
    sky[3000] *= 1.01  # 15 sigma
    flags = flag_sky(sky)
    assert set(np.flatnonzero(flags)) == {10, 11, 2000, 3000}
    assert flag_sky(np.full(8, 100.0)).all()  # too few channels to judge


# Broad humps (calibration.checks.rfi_broad) and flags across a night (rfi_night). The
# numbers over many more spectra, and xrfi's beside them: benchmarks/rfi.py.


def family_sky(rng, seconds=None, trough=None, n=4096):
    """A sky of the clean family with its frequencies (Hz), radiometer sigma and trough."""
    lo = rng.uniform(40.0, 80.0)
    hi = rng.uniform(lo + 50.0, 200.0)
    trough = rng.random() < 0.5 if trough is None else trough
    seconds = 10 ** rng.uniform(0.0, np.log10(3600.0)) if seconds is None else seconds
    f = np.linspace(lo, hi, n)
    return f * 1e6, clean_sky(rng, rng.uniform(-2.8, -2.2), lo, hi, seconds, trough, n), (
        1 / np.sqrt((f[1] - f[0]) * 1e6 * seconds)
    )


def add_hump(rng, f_hz, x, sigma, width_mhz, peak_sigma):
    f = f_hz / 1e6
    centre = rng.uniform(f[0] + width_mhz, f[-1] - width_mhz)
    added = peak_sigma * np.exp(-4 * np.log(2) * ((f - centre) / width_mhz) ** 2)
    x *= 1 + sigma * added
    return np.abs(f - centre) <= width_mhz / 2, added


@pytest.mark.parametrize("seed", range(3))
def test_the_broad_stage_leaves_clean_skies_and_the_trough_alone(seed):
    """12 skies of the family with their frequencies, and 4 with the trough at 1 h (its
    worst: its flanks' response grows as sqrt(tau)), 5 sigma: none flagged. The benchmark
    flagged none of 40 either."""
    rng = np.random.default_rng(300 + seed)
    flagged = 0
    for k in range(16):
        f, sky, _ = family_sky(rng, seconds=3600.0 if k >= 12 else None,
                               trough=True if k >= 12 else None)
        flagged += int(flag_sky(sky, freq_hz=f).sum())
    assert flagged <= 1


@pytest.mark.parametrize(("width_mhz", "peak_sigma"), [(2.0, 3.0), (5.0, 8.0), (10.0, 50.0)])
def test_broad_humps_are_found_where_the_trend_of_spikes_cannot_see_them(width_mhz, peak_sigma):
    """Six skies of the family each: the hump's core (its FWHM) at least half flagged in
    five of six (the benchmark: every one, of 10); the narrow stage alone finds none of the
    two weaker kinds; where the hump adds under 0.1 sigma, at most 3 % of the band (a
    50 sigma hump's wings are flagged further out)."""
    rng = np.random.default_rng(int(width_mhz * 100 + peak_sigma))
    found = narrow_found = 0
    for _ in range(6):
        f, sky, sigma = family_sky(rng)
        core, added = add_hump(rng, f, sky, sigma, width_mhz, peak_sigma)
        flags = flag_sky(sky, freq_hz=f)
        found += int(np.mean(flags[core]) >= 0.5)
        narrow_found += int(np.mean(flag_sky(sky, broad=False)[core]) >= 0.5)
        assert np.count_nonzero(flags & (added < 0.1)) <= 0.03 * sky.size
    assert found >= 5
    if peak_sigma < 50:
        assert narrow_found == 0


def test_flag_broad_needs_frequencies_in_order():
    from calibration.checks.rfi_broad import flag_broad

    with pytest.raises(InvalidDataError, match="frequency"):
        flag_broad(np.ones(100), np.linspace(2e8, 1e8, 100))
    assert not flag_broad(np.full(1000, 300.0), np.linspace(5e7, 1.3e8, 1000)).any()


def night_of(rng, n_t=24, n=2048, seconds=200.0):
    """A night's calibrated spectra: the sky's level and index change with LST, a trough."""
    f = np.linspace(50.0, 130.0, n)
    lst = np.linspace(0.0, 1.0, n_t)[:, None]
    phase = rng.uniform(0, 2 * np.pi)
    t = 5000 * (1 + 0.2 * np.sin(3 * lst + phase)) * (f / 50) ** (-2.5 - 0.05 * lst)
    t = t - 0.5 * np.exp(-0.5 * ((f - 78.0) / 8.5) ** 2)
    sigma = 1 / np.sqrt((f[1] - f[0]) * 1e6 * seconds)
    return f * 1e6, t * (1 + sigma * rng.standard_normal(t.shape)), sigma


def own_flags(f, x):
    return np.stack([flag_sky(row, freq_hz=f) for row in x])


@pytest.mark.parametrize("seed", range(3))
def test_a_night_flags_what_its_spectra_alone_miss_and_nothing_clean(seed):
    """A line at 2 sigma per spectrum on all night (10 sigma in the mean of 24), a channel
    flagged in 14 of 24 spectra, a band-wide burst of 1 sigma per channel in one spectrum
    (a smooth model absorbs it), a 2 MHz hump of 3 sigma in another (its level's
    neighbours are judged without it only 4 spectra away): the line and the
    channel are flagged at every time, the burst's spectrum whole, the hump found; no
    other pixel is flagged (the sky changing by 20 % over the night, with a trough)."""
    from calibration.checks.rfi_night import flag_night

    rng = np.random.default_rng(400 + seed)
    f, x, sigma = night_of(rng)
    n_t, n = x.shape
    x[:, 700] *= 1 + 2 * sigma
    # rows 4 apart: the cubic through a burst's neighbours sees it in two on each side
    burst, hump_row = rng.choice(np.arange(2, n_t - 2, 4), 2, replace=False)
    x[burst] *= 1 + sigma
    core, added = add_hump(rng, f, x[hump_row], sigma, 2.0, 3.0)
    own = own_flags(f, x)
    majority = int(rng.integers(0, n))
    own[rng.choice(n_t, 14, replace=False), majority] = True
    night = flag_night(x, own, f)
    assert np.all(night.flags[own])
    assert night.channels[700]
    assert night.channels[majority]
    assert np.flatnonzero(night.spectra).tolist() == [burst]
    assert np.mean(night.flags[hump_row, core]) >= 0.5
    expected = np.zeros(x.shape, bool)
    expected[:, [700, majority]] = True
    expected[burst] = True
    expected[hump_row] |= added >= 0.1
    assert np.count_nonzero(night.flags & ~expected) <= 0.001 * x.size
    assert night.summary()["spectra_flagged_whole"] == 1


def test_a_short_night_gets_the_majority_rule_only_and_bad_input_is_refused():
    from calibration.checks.rfi_night import flag_night

    rng = np.random.default_rng(9)
    f, x, _ = night_of(rng, n_t=2, n=512)
    own = np.zeros(x.shape, bool)
    own[:, 100] = True
    night = flag_night(x, own, f)
    assert np.flatnonzero(night.channels).tolist() == [100]
    assert not night.spectra.any()
    with pytest.raises(InvalidDataError, match="shape"):
        flag_night(x, own[:, :10], f)
    with pytest.raises(InvalidDataError, match="time, channel"):
        flag_night(x[0], None, f)


@pytest.mark.parametrize("row", [0, 1, 22, 23])
def test_a_burst_at_a_nights_ends_is_not_passed_to_a_clean_neighbour(row):
    """The first and last two spectra are not judged by their level (no neighbours on
    one side), and a burst there once flagged the spectrum two in, whose cubic leans on
    it with weight 1/6."""
    from calibration.checks.rfi_night import flag_night

    rng = np.random.default_rng(500 + row)
    f, x, sigma = night_of(rng)
    x[row] *= 1 + 5 * sigma
    night = flag_night(x, own_flags(f, x), f)
    assert set(np.flatnonzero(night.spectra)) <= {row}
