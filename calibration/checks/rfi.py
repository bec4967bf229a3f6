"""RFI excision: flags for narrow spikes and short broadband bursts, kept beside the data.

Broad humps of one spectrum are :mod:`calibration.checks.rfi_broad`'s (through
:func:`flag_sky`), and a night's calibrated spectra flagged together
:mod:`calibration.checks.rfi_night`'s.

Nothing here changes or drops data: every function returns boolean flags of the data's
shape (``True`` = flagged), to be stored next to the spectra and honoured by whatever
averages or fits them (thesis 4.7 excised a spike at 78 MHz and four bands by hand; 5.1
asks for spikes and broadband RFI both).

**Averaged spectrum** (:func:`flag_spectrum`, one spectrum over channels): the smooth
part is a polynomial of ``degree`` in log power (Legendre, over unflagged channels), times
a local quadratic of the ratio to it (Savitzky-Golay over ``window`` channels), times a
running median over ``window`` channels of what is left (robust to spikes narrower than
half the window). A running median alone returns the data themselves wherever their
slope per channel exceeds the noise (a 10 m cable source's ripple: 0.2 % per channel,
the noise 0.005-0.1 %), and then flags nothing there; the polynomial and the local
quadratic take the slope out first. Flagged channels are bridged by interpolation; the
residual ``r = x / trend - 1`` (relative: radiometer noise is a fixed fraction of the
power for equal channel widths and integration) has a robust scale
``sigma = 1.4826 median|r - median r|`` over unflagged channels; a channel is flagged when
``r > threshold sigma``. Where ``window`` channels are too many for the local quadratic
(the residual scatters more than the noise that fourth differences find), the window is
halved until they are not. The flags are recomputed with the last ones bridged until they
stop changing, so that strong spikes neither hide weaker ones through the trend nor
leave their neighbours flagged.

**Dynamic spectrum** (:func:`flag_dynamic_spectrum`, ``(time, channel)``): each channel is
divided by its median over time (the bandpass) and each spectrum by its median ratio to
the bandpass (its gain, which drifts between spectra), ``z = (x / (g_t bandpass) - 1) /
sigma_c`` with ``sigma_c`` each channel's robust scale over time, smoothed across channels.
A burst over more than half the band is therefore taken for a gain change, which the
Dicke switch divides out anyway. Then

* *spikes*: ``z > threshold`` flags single pixels;
* *bursts*: for each pixel, ``s = sum(z) / sqrt(n)`` over the ``n`` unflagged, non-spike
  pixels of its spectrum within ``block`` channels of it is a unit Gaussian without RFI; a
  burst a fraction of a sigma per channel but spanning many channels stands out
  (``sqrt(block)`` times its per-channel size); a run of pixels along a spectrum with
  ``s > burst_threshold / 2`` is flagged when it reaches ``s > burst_threshold`` somewhere
  (hysteresis: the burst's edges, where the window covers it only partly, come with it);
* *persistent lines* (a transmitter on all the time, absorbed by the time median): the
  time-averaged spectrum goes through :func:`flag_spectrum` and its flagged channels are
  flagged at every time.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import binary_dilation, label, median_filter

from ..core.errors import InvalidDataError
from ..model.data import CalibrationData

__all__ = [
    "RfiFlags",
    "calibrator_flags",
    "difference_sigma",
    "flag_dynamic_spectrum",
    "flag_sky",
    "flag_spectrum",
    "robust_sigma",
]

BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]

MAD_TO_SIGMA = 1.4826
#: The narrowest trend window (channels), and how much more than the noise its residual
#: may scatter before a narrower one is taken (:func:`_trend_window`).
MIN_WINDOW = 7
TREND_SLACK = 1.2
BLOCK_SIGMAS = 5.0
#: A relative scatter below this is rounding, not noise (radiometer noise of a 12 kHz
#: channel integrated for a year is 5e-8): such a spectrum is not flagged.
NOISELESS = 1e-9


def robust_sigma(values: ArrayLike, axis: int | None = None) -> FloatArray:
    """``1.4826 median|x - median x|``: a Gaussian's sigma, unmoved by outliers; NaN skipped."""
    x = np.asarray(values, dtype=float)
    centre = np.nanmedian(x, axis=axis, keepdims=True)
    return np.asarray(MAD_TO_SIGMA * np.nanmedian(np.abs(x - centre), axis=axis), dtype=float)


def _bridge(x: FloatArray, flags: BoolArray) -> FloatArray:
    """``x`` with flagged channels replaced by linear interpolation between unflagged ones."""
    good = np.flatnonzero(~flags)
    if good.size == 0:
        raise InvalidDataError("every channel is flagged: nothing to estimate the trend from")
    out = x.copy()
    out[flags] = np.interp(np.flatnonzero(flags), good, x[good])
    return out


def _trend(x: FloatArray, flags: BoolArray, window: int, degree: int) -> FloatArray:
    """A smooth curve through the unflagged channels (module docstring).

    A polynomial in log power, a local quadratic (Savitzky-Golay) of the ratio to it,
    then a running median of what is left: the median alone returns the data where their
    slope per channel exceeds the noise (a 10 m cable source's ripple, 0.2 % per channel
    against 0.1 % noise), which hid every spike there.
    """
    from scipy.signal import savgol_filter
    u = np.linspace(-1.0, 1.0, x.size)
    coef = np.polynomial.legendre.legfit(u[~flags], np.log(x[~flags]), degree)
    base = np.exp(np.polynomial.legendre.legval(u, coef))
    ratio = _bridge(x / base, flags)
    local = savgol_filter(ratio, min(window, x.size - 1 + x.size % 2), 3, mode="interp")
    rest = median_filter(ratio / local, size=window, mode="nearest")
    return np.asarray(base * local * rest)


def difference_sigma(spectrum: FloatArray) -> float:
    """Relative noise per channel from fourth differences, ``robust_sigma(D^4 x / x) / sqrt(70)``.

    White noise of ``sigma`` gives fourth differences of ``sqrt(70) sigma``; a smooth
    spectrum's own fourth difference is its ripple's ``(2 pi / period)^4`` times its
    amplitude (1e-5 of 30 % for a ripple of 100 channels), so it is left out.
    """
    x = np.asarray(spectrum, dtype=float)
    if x.size < 9:
        return float("nan")
    return float(robust_sigma(np.diff(x, 4) / x[2:-2]) / np.sqrt(70.0))


def _misfit(
    residual: FloatArray, flags: BoolArray, given: BoolArray, window: int, noise: float
) -> bool:
    """Whether a trend leaves more than noise: overall, or in any block of half a window.

    Overall: the robust scale of the unflagged residual above :data:`TREND_SLACK` times
    ``noise`` (:func:`difference_sigma`). Per block of ``b = window // 2`` channels: a
    median offset above :data:`BLOCK_SIGMAS` of its own noise, ``1.2533 noise / sqrt(b)``,
    over every channel but the ``given`` flags (a spike a few channels wide hardly moves
    a median; a bend the flagger took for a run of spikes does). This finds a trend that
    bends away from the data over a few channels, at a band edge where the local fit
    extrapolates or on a ripple of a few windows' period.
    """
    if not noise > NOISELESS:  # no noise to compare with (or under 9 channels)
        return False
    if robust_sigma(residual[~flags]) > TREND_SLACK * noise:
        return True
    b = max(window // 2, 4)
    usable = residual.size // b * b
    values = np.where(given, np.nan, residual)
    ends = np.concatenate([values[:usable], values[residual.size - usable :]]).reshape(-1, b)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a block with every channel given
        offset = np.abs(np.nanmedian(ends, axis=1))
    return bool(np.nanmax(offset, initial=0.0) > BLOCK_SIGMAS * 1.2533 * noise / np.sqrt(b))


def _iterate_flags(
    x: FloatArray,
    given: BoolArray,
    window: int,
    degree: int,
    threshold: float,
    max_iterations: int,
) -> BoolArray:
    """Flags ``r > threshold sigma``, recomputed with the last ones bridged until stable."""
    current = given.copy()
    for _ in range(max_iterations):
        r = x / _trend(x, current, window, degree) - 1
        sigma = robust_sigma(r[~current])
        if not sigma > NOISELESS:  # a constant or a model spectrum: nothing stands out
            break
        # recomputed, not accumulated: a strong spike's first trend leaks into its
        # neighbours (the local fit's side lobes), which the next one, bridging it, does not
        new = given | (r > threshold * sigma)
        if np.array_equal(new, current):
            break
        current = new
    return current


def flag_spectrum(
    spectrum: ArrayLike,
    flags: ArrayLike | None = None,
    window: int = 31,
    threshold: float = 5.0,
    max_iterations: int = 10,
    grow: int = 0,
    degree: int = 7,
) -> BoolArray:
    """Flags of narrow spikes in one spectrum (positive powers, channels on the only axis).

    ``flags`` are flags already set (band edges, known bands); they are kept. ``grow``
    widens each new flag by that many channels on each side (for spikes with faint wings).
    """
    x = np.asarray(spectrum, dtype=float)
    if x.ndim != 1 or window < 3 or window % 2 == 0:
        raise InvalidDataError("flag_spectrum takes a 1-D spectrum and an odd window >= 3")
    if np.any(~np.isfinite(x)) or np.any(x <= 0):
        raise InvalidDataError("flag_spectrum needs finite, positive powers")
    given = np.zeros(x.shape, bool) if flags is None else np.asarray(flags, bool).copy()
    if np.all(given):
        raise InvalidDataError("every channel is flagged: nothing to estimate the trend from")
    noise = difference_sigma(x)
    while True:
        current = _iterate_flags(x, given, window, degree, threshold, max_iterations)
        r = x / _trend(x, current, window, degree) - 1
        if window <= MIN_WINDOW or not _misfit(r, current, given, window, noise):
            break
        window = max(MIN_WINDOW, (window // 2) | 1)
    found = current & ~given
    if grow:
        found = binary_dilation(found, iterations=grow)
    return np.asarray(given | found, dtype=bool)


def flag_sky(
    temperature: ArrayLike,
    threshold: float = 5.0,
    freq_hz: ArrayLike | None = None,
    broad: bool = True,
) -> BoolArray:
    """Flags of a calibrated sky spectrum (K): narrow spikes, then broad humps.

    :func:`flag_spectrum` on its positive channels, then, given the channels' frequencies
    ``freq_hz`` and unless ``broad`` is off, :func:`calibration.checks.rfi_broad.flag_broad`
    (humps of 0.2-4 MHz; a hump's width and the sky's power law are in frequency).

    The residual is relative to the trend, so the noise level follows the spectrum: a
    sky's radiometer noise is a fixed fraction of its temperature (``1 / sqrt(B tau)``),
    about 10x larger in kelvin at 50 MHz than at 130 MHz, which one band-wide level in
    kelvin took for interference (a clean ``5000 (f / 50 MHz)^-2.5`` K sky over 50-130
    MHz, 6554 channels: 170-250 channels flagged below 70 MHz; here none, for indices
    -2.2 to -2.8 and 1 s to 1 h). A channel that is not finite or not above zero (a
    calibration gone wrong there) is flagged and bridged before the rest are judged;
    fewer than 9 usable channels are all flagged.
    """
    x = np.asarray(temperature, dtype=float)
    if x.ndim != 1:
        raise InvalidDataError("flag_sky takes one spectrum (1-D)")
    with np.errstate(invalid="ignore"):
        unusable = ~np.isfinite(x) | ~(x > 0)
    if np.count_nonzero(~unusable) < 9:
        return np.ones(x.shape, dtype=bool)
    bridged = _bridge(np.where(unusable, 1.0, x), unusable)
    flags = flag_spectrum(bridged, unusable, threshold=threshold)
    if not broad or freq_hz is None:
        return flags
    from .rfi_broad import flag_broad  # here: it imports this module's noise estimates

    return flag_broad(bridged, freq_hz, flags, threshold)


def _running_significance(z: FloatArray, width: int) -> FloatArray:
    """``sum(z) / sqrt(n)`` over the finite ``z`` within ``width`` channels of each channel."""
    half = width // 2
    width = 2 * half + 1
    padded = np.pad(np.nan_to_num(z, nan=0.0), ((0, 0), (half + 1, half)))
    counts = np.pad(np.isfinite(z).astype(float), ((0, 0), (half + 1, half)))
    total = np.cumsum(padded, axis=1)
    n = np.cumsum(counts, axis=1)
    window_sum = total[:, width:] - total[:, :-width]
    window_n = n[:, width:] - n[:, :-width]
    return np.asarray(window_sum / np.sqrt(np.maximum(window_n, 1.0)), dtype=float)


def _hysteresis(values: FloatArray, high: float, low: float) -> BoolArray:
    """Runs of ``values > low`` along channels that reach ``high`` somewhere."""
    runs, _ = label(values > low, structure=[[0, 0, 0], [1, 1, 1], [0, 0, 0]])
    keep = np.unique(runs[values > high])
    return np.asarray(np.isin(runs, keep[keep > 0]), dtype=bool)


@dataclass(frozen=True)
class RfiFlags:
    """Flags of a dynamic spectrum, by kind; ``flags`` is their union with those given.

    Attributes
    ----------
    flags, spikes, bursts, lines
        Each of the data's shape ``(time, channel)``.
    """

    flags: BoolArray
    spikes: BoolArray
    bursts: BoolArray
    lines: BoolArray

    @property
    def fraction(self) -> float:
        """Fraction of all pixels flagged."""
        return float(np.mean(self.flags))

    def __str__(self) -> str:
        n_t = self.flags.shape[0]
        burst_rows = int(np.count_nonzero(np.any(self.bursts, axis=1)))
        line_channels = int(np.count_nonzero(np.all(self.lines, axis=0))) if n_t else 0
        return (
            f"RFI: {100 * self.fraction:.2f}% of pixels flagged; "
            f"{int(np.count_nonzero(self.spikes))} spike pixels, bursts in {burst_rows} of "
            f"{n_t} spectra, {line_channels} persistent line channels"
        )


def flag_dynamic_spectrum(
    data: ArrayLike,
    flags: ArrayLike | None = None,
    threshold: float = 5.0,
    burst_threshold: float = 5.0,
    block: int = 64,
    window: int = 31,
    max_iterations: int = 5,
) -> RfiFlags:
    """Flags of spikes, broadband bursts and persistent lines in spectra ``(time, channel)``."""
    x = np.asarray(data, dtype=float)
    if x.ndim != 2 or x.shape[0] < 3:
        raise InvalidDataError("flag_dynamic_spectrum takes (time, channel) with >= 3 spectra")
    if np.any(~np.isfinite(x)) or np.any(x <= 0):
        raise InvalidDataError("flag_dynamic_spectrum needs finite, positive powers")
    given = np.zeros(x.shape, bool) if flags is None else np.asarray(flags, bool)
    spikes = bursts = lines = np.zeros(x.shape, bool)
    for _ in range(max_iterations):
        masked = np.where(given | spikes | bursts | lines, np.nan, x)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN channels: bridged below
            bandpass = np.nanmedian(masked, axis=0)
            ratio = masked / bandpass
            r = ratio / np.nanmedian(ratio, axis=1, keepdims=True) - 1  # each spectrum's gain
            sigma_c = robust_sigma(r, axis=0)
        dead = ~np.isfinite(sigma_c) | (sigma_c <= 0)
        sigma_c = median_filter(_bridge(sigma_c, dead), size=window, mode="nearest")
        z = r / sigma_c
        new_spikes = spikes | (np.nan_to_num(z, nan=0.0) > threshold)
        significance = _running_significance(np.where(new_spikes, np.nan, z), block)
        new_bursts = bursts | _hysteresis(significance, burst_threshold, burst_threshold / 2)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mean = np.nanmean(np.where(given | new_spikes | new_bursts, np.nan, x), axis=0)
        known = np.isfinite(mean)
        line_channels = flag_spectrum(_bridge(mean, ~known), ~known, window, threshold) & known
        new_lines = np.broadcast_to(line_channels, x.shape)
        if (np.array_equal(new_spikes, spikes) and np.array_equal(new_bursts, bursts)
                and np.array_equal(new_lines, lines)):
            break
        spikes, bursts, lines = new_spikes, new_bursts, new_lines
    union = given | spikes | bursts | lines
    return RfiFlags(np.asarray(union), spikes & ~given, bursts & ~given, lines & ~given)


def calibrator_flags(data: CalibrationData) -> tuple[BoolArray, dict[str, int]]:
    """Union of the spike flags of every calibrator's three Dicke spectra.

    The source position's too: a 10 m cable source ripples by tens of percent every
    10 MHz (hundreds of channels), which the trend's polynomial in log power and its
    running median follow to far below the radiometer noise (a clean simulated run flags
    none of the cable sources' channels, at the iTPM's resolution or every eighth
    channel). Returns the flags and the number of channels each calibrator flagged.
    """
    union = np.zeros(data.n_channels, dtype=bool)
    counts = {}
    for name, source in data.sources.items():
        flags = np.zeros(data.n_channels, dtype=bool)
        for spectrum in (source.p_source, source.p_load, source.p_ns):
            flags |= flag_spectrum(spectrum)
        counts[name] = int(np.count_nonzero(flags))
        union |= flags
    return union, counts
