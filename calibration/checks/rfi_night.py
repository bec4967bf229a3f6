"""Flags across a night: what each calibrated spectrum alone cannot tell.

:func:`~calibration.checks.rfi.flag_sky` judges each spectrum against itself. Over the
``(time, channel)`` spectra of one night, :func:`flag_night` adds, in this order:

* *the majority rule*: a channel flagged in more than ``majority`` of the spectra (half by
  default) is flagged in all of them; the spectra where it was not flagged hold the same
  interference under the threshold;
* *the night's mean*: the average spectrum has ``sqrt(n_t)`` times less noise, so a line
  on all night, too faint for one spectrum, stands out in it
  (:func:`~calibration.checks.rfi.flag_spectrum`); its channels are flagged at every
  time. Not broad humps: at a night's depth the 21-cm trough is one (a simulated night of
  48 cycles of 200 s flagged 460 channels of it), and a hump on all night is as smooth
  as the sky; strong ones are each spectrum's and come through the majority rule;
* *bursts*: each spectrum divided by the night's mean ``q_t = x_t / mean_t x`` (the sky's
  shape and whatever is on all night divide out; the sky's slow change with LST is
  smooth in frequency and goes into the smooth model, of degree :data:`RATIO_DEGREE`)
  goes through :func:`~calibration.checks.rfi_broad.flag_broad`: an intermittent hump
  stands out against the same channels at other times. Not the median: it switches
  between spectra where they cross, and its kinks were flagged as humps;
* *whole spectra*: a spectrum with more than ``whole`` of its channels flagged, or whose
  level ``l_t`` (the band's mean of the smooth model of ``q_t``; a median over the
  channels moved with every hole, ``q_t`` having the slope of the sky's change in index)
  stands above the cubic through its two neighbours on each side, ``l_t - (4 (l_{t-1} +
  l_{t+1}) - (l_{t-2} + l_{t+2})) / 6``, by more than ``threshold`` times the robust
  scatter of that excess over the night, is flagged whole (a burst over the whole band,
  which a smooth model absorbs; the sky's own change with LST is slow, and a cubic
  follows it where a straight line through the neighbours left its curvature, 20 % over
  an hour and a half, larger than a 5 sigma burst). Only the largest excess within two
  spectra counts (a burst's neighbours see it at -2/3 and +1/6 of its size); the first
  and last two spectra, with no neighbours on one side, are not judged this way (the
  quadratic through the next three, extrapolated, missed the sky's change by 4e-4 in
  the tests and flagged a clean spectrum); a spectrum is flagged only where its
  neighbours dip by a third of its excess at least (a burst at the ends raised the
  spectrum two in by 1/6 of it, with no dip beside it). From
  :data:`MIN_LEVEL_SPECTRA` spectra on. The model leaves out flagged channels and as
  many again on each side of each flagged run (a hump's unflagged wings).

Flagged channels are first filled with their spectrum's own trend: the sky changes over
a night (by 20 % in level and 0.05 in spectral index in the tests), and a hole in one
spectrum would step the night's mean by ``1 / n_t`` of that change, 5e-4 for 48 spectra,
7 times the mean's noise at 200 s per spectrum. Nothing is unflagged: the result is the
union with the flags given.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import find_objects, label, maximum_filter1d

from ..core.errors import InvalidDataError
from .rfi import _bridge, _trend, flag_spectrum, robust_sigma
from .rfi_broad import flag_broad, smooth_model

__all__ = ["NightFlags", "flag_night"]

BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]

#: Degree of the smooth model of each spectrum's ratio to the night's median.
RATIO_DEGREE = 3
#: The trend that fills a spectrum's flagged channels (:func:`.rfi.flag_spectrum`'s).
TREND_WINDOW = 31
TREND_DEGREE = 7
#: Fewer spectra than this are judged one by one only.
MIN_SPECTRA = 3
#: Fewer spectra than this give no scatter of the level to judge one by (three spectra
#: have one second difference, and flagged one of a clean simulated night's three whole).
MIN_LEVEL_SPECTRA = 8


@dataclass(frozen=True)
class NightFlags:
    """A night's flags ``(time, channel)`` (the union) and what each rule added.

    ``channels``: flagged at every time (majority or the night's mean); ``spectra``:
    flagged whole; ``bursts`` ``(time, channel)``: found against the rest of the night.
    """

    flags: BoolArray
    channels: BoolArray
    spectra: BoolArray
    bursts: BoolArray

    def summary(self) -> dict[str, int]:
        """Counts for a log line or a check's details."""
        return {
            "channels_flagged_at_every_time": int(np.count_nonzero(self.channels)),
            "spectra_flagged_whole": int(np.count_nonzero(self.spectra)),
            "burst_pixels": int(np.count_nonzero(self.bursts)),
            "pixels_flagged": int(np.count_nonzero(self.flags)),
        }


def _usable(x: FloatArray) -> BoolArray:
    with np.errstate(invalid="ignore"):
        return np.asarray(np.isfinite(x) & (x > 0))


def _filled(x: FloatArray, flags: BoolArray) -> FloatArray:
    """Each spectrum with its flagged channels replaced by its own trend (NaN: none)."""
    out = np.full(x.shape, np.nan)
    for t in range(x.shape[0]):
        good = ~flags[t]
        if np.count_nonzero(good) >= 9:
            row = _bridge(np.where(good, x[t], 1.0), ~good)
            out[t] = np.where(good, x[t], _trend(row, ~good, TREND_WINDOW, TREND_DEGREE))
    return out


def _mean_flags(filled: FloatArray, threshold: float) -> BoolArray:
    """Channels the night's mean spectrum flags as narrow spikes."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a night of unusable spectra
        mean = np.nanmean(filled, axis=0)
    unknown = ~_usable(mean)
    if np.count_nonzero(~unknown) < 9:
        return unknown
    bridged = _bridge(np.where(unknown, 1.0, mean), unknown)
    return flag_spectrum(bridged, unknown, threshold=threshold)


def _widened(flags: BoolArray) -> BoolArray:
    """Each run of flags widened by its own length on each side (a hump's wings)."""
    runs, count = label(flags)
    out = flags.copy()
    for where in find_objects(runs)[:count]:
        if where is not None:
            start, stop = where[0].start, where[0].stop
            length = stop - start
            out[max(start - length, 0) : stop + length] = True
    return out


def _excess(values: FloatArray) -> FloatArray:
    """Each level less the cubic through two neighbours on each side (NaN at the ends)."""
    v = values
    out = np.full(v.size, np.nan)
    if v.size >= 5:
        out[2:-2] = v[2:-2] - (4 * (v[1:-3] + v[3:-1]) - (v[:-4] + v[4:])) / 6
    return out


def _level_outliers(level: FloatArray, threshold: float) -> BoolArray:
    """Spectra whose level stands above its neighbours' (module docstring)."""
    out = np.zeros(level.shape, bool)
    known = np.flatnonzero(np.isfinite(level))
    if known.size < MIN_LEVEL_SPECTRA:
        return out
    scale = float(robust_sigma(_excess(level[known])))
    if not scale > 0:
        return out
    excess = _excess(level[known])
    filled = np.nan_to_num(excess, nan=-np.inf)
    peak = filled >= maximum_filter1d(filled, size=5, mode="nearest")
    # a burst's neighbours see it at -2/3 of its size; a spectrum two in from a burst at
    # the ends (not judged) sees it at +1/6 with no such dip beside it
    before = np.concatenate([[np.nan], excess[:-1]])
    after = np.concatenate([excess[1:], [np.nan]])
    dips = [np.where(np.isnan(side), -np.inf, side) < -excess / 3 for side in (before, after)]
    out[known] = peak & dips[0] & dips[1] & (np.nan_to_num(excess, nan=0.0) > threshold * scale)
    return out


def flag_night(
    spectra: ArrayLike,
    flags: ArrayLike | None = None,
    freq_hz: ArrayLike | None = None,
    threshold: float = 5.0,
    majority: float = 0.5,
    whole: float = 0.5,
) -> NightFlags:
    """Flags of a night's calibrated spectra ``(time, channel)`` (K), given each one's own.

    ``flags`` are each spectrum's flags (:func:`~calibration.checks.rfi.flag_sky`); a
    channel not finite or not above zero is flagged. Without ``freq_hz`` no bursts are
    looked for (their widths and the smooth model are in frequency). Fewer than :data:`MIN_SPECTRA`
    spectra get the majority rule only.
    """
    x = np.asarray(spectra, dtype=float)
    if x.ndim != 2:
        raise InvalidDataError("flag_night takes spectra (time, channel)")
    given = np.zeros(x.shape, bool) if flags is None else np.asarray(flags, bool).copy()
    if given.shape != x.shape:
        raise InvalidDataError(f"flags {given.shape} and spectra {x.shape} differ in shape")
    given |= ~_usable(x)
    freq = None if freq_hz is None else np.asarray(freq_hz, dtype=float)
    n_t = x.shape[0]
    channels = np.mean(given, axis=0) > majority
    empty = np.zeros(x.shape, bool)
    if n_t < MIN_SPECTRA:
        return _result(given, channels, np.zeros(n_t, bool), empty)
    filled = _filled(x, given | channels)
    channels |= _mean_flags(filled, threshold)
    current = given | channels
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        reference = np.nanmean(filled, axis=0)
    known = _usable(reference)
    bursts = empty.copy()
    level = np.full(n_t, np.nan)
    for t in range(n_t):
        usable = ~current[t] & known
        if np.count_nonzero(usable) < 9:
            continue
        q = _bridge(np.where(usable, x[t] / np.where(known, reference, 1.0), 1.0), ~usable)
        if freq is not None:
            bursts[t] = flag_broad(q, freq, ~usable, threshold, degree=RATIO_DEGREE) & usable
        away = usable & ~_widened(~usable | bursts[t])
        away = away if np.count_nonzero(away) > 2 * (RATIO_DEGREE + 1) else usable
        if freq is None:
            level[t] = np.median(q[away])
        else:  # the band's mean of the smooth ratio: holes do not move it
            level[t] = np.mean(smooth_model(q, ~away, freq, RATIO_DEGREE))
    spectra_whole = _level_outliers(level, threshold)
    spectra_whole |= np.mean(current | bursts, axis=1) > whole
    return _result(given, channels, spectra_whole, bursts)


def _result(
    given: BoolArray, channels: BoolArray, spectra: BoolArray, bursts: BoolArray
) -> NightFlags:
    union = given | channels[None, :] | spectra[:, None] | bursts
    return NightFlags(np.asarray(union), channels, spectra, bursts & ~given)
