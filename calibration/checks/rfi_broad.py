"""Broad RFI: humps of many channels (0.2-8 MHz), a fraction of a sigma per channel each.

:func:`~calibration.checks.rfi.flag_spectrum`'s trend follows anything wider than its
window (31 channels, 0.4 MHz at the iTPM's 12 kHz), so a hump of a few MHz (a transmitter's
modulated band, a broadband source on at one time) is part of its trend and never flagged.
Here the smooth part is global and stiff instead: a polynomial of ``degree`` in
``log x`` against ``log f`` (a power-law sky is its first two terms; thesis 4.6 fits the
sky this way), fitted to the unflagged channels, and the relative residual ``r = x /
model - 1`` in units of the radiometer noise ``sigma`` (fourth differences,
:func:`~calibration.checks.rfi.difference_sigma`: the noise of every channel, hump or not).

Each width ``w`` (channels, doubling from :data:`MIN_WIDTH`) has a compensated top hat:
the mean of ``z = r / sigma`` over the ``w`` channels about channel ``i``, less the mean
over the ``w / 2`` channels on each side of them,

    s_w(i) = (mean_centre z - mean_sides z) / sqrt(1 / n_centre + 1 / n_sides),

a unit Gaussian for white noise without RFI (the means over unflagged channels only;
``n`` their counts). A calibrated spectrum's noise is not white on these scales (the S11s'
trace noise, interpolated between the VNA's points, and the solution's error: a clean
simulated run's ``s`` reached 4.9 where white noise gives 3.5), so each width's ``s`` is
divided by its own robust scatter over the band where that exceeds one.
It is blind to a constant and to a slope (the symmetric sides), so what the model leaves
of the sky's curvature on scales far above ``2 w`` does not show; a hump of ``a`` sigma per
channel and about ``w`` channels gives ``s ~ a sqrt(w / 2)`` (0.5 sigma over 2 MHz of
12 kHz channels: 4.5). Only positive ``s`` is RFI: power is added. A run of
``s_w > threshold / 2`` that reaches ``threshold`` somewhere flags its channels and the
``w / 4`` beside them. Widths go from narrow to wide, each masking what the narrower found
(a strong hump flagged at its own width does not spill at a wider one), and the model is
refitted without them until the flags stop changing.

**The 21-cm trough is not RFI**: it is a dip (negative), and its flanks, where it bends
the other way, are at most ``0.08 A (w / s)^2`` above the local mean for a Gaussian dip of
depth ``A`` and width ``s``; what the stiff model absorbs of the trough rings more (up
to 1.6 sigma at 1 h with 4 MHz windows, 3.4 sigma with 8 MHz ones, noise-free, over
40-200 MHz bands). :data:`MAX_WIDTH_HZ` keeps the widest window a fifth of the trough's
width; a hump much wider than it is found only by its edges (``benchmarks/rfi.py``). The
response grows as ``sqrt(tau)``: an average of many hours would see the trough, and is
flagged with ``flag_sky(..., broad=False)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import binary_dilation, label

from ..core.errors import InvalidDataError
from .rfi import NOISELESS, difference_sigma, robust_sigma

__all__ = ["MAX_WIDTH_HZ", "MIN_WIDTH", "broad_significance", "flag_broad", "smooth_model"]

BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]

#: The narrowest window (channels): narrower bumps are :func:`flag_spectrum`'s.
MIN_WIDTH = 16
#: The widest window (Hz): a fifth of the 21-cm trough's width. At 8 MHz the model's
#: misfit around EDGES' trough reached 3.4 sigma at 1 h and, with noise, was flagged.
MAX_WIDTH_HZ = 4e6
#: Channels this many sigma above the model are left out of its fit (:func:`_robust_model`).
CLIP = 3.0
#: A run of ``s`` above ``LOW threshold`` reaching ``threshold`` is flagged, widened by
#: ``GROW`` windows on each side.
LOW = 0.5
GROW = 0.25


def smooth_model(x: FloatArray, flags: BoolArray, freq_hz: FloatArray, degree: int) -> FloatArray:
    """``exp(P(log f))``, ``P`` of ``degree`` fitted to ``log x`` on unflagged channels.

    Legendre terms in ``log f`` over the band mapped to [-1, 1] (in the channel number, a
    degree-5 model of a power law over 43-174 MHz left 36 channels at the low edge).
    """
    axis = np.log(freq_hz)
    u = 2 * (axis - axis[0]) / (axis[-1] - axis[0]) - 1
    coef = np.polynomial.legendre.legfit(u[~flags], np.log(x[~flags]), degree)
    return np.asarray(np.exp(np.polynomial.legendre.legval(u, coef)))


def _window_sums(values: FloatArray, start: int, stop: int) -> FloatArray:
    """``sum(values[i + start : i + stop])`` for every ``i`` (zero beyond the ends)."""
    n = values.size
    total = np.concatenate([[0.0], np.cumsum(values)])
    i = np.arange(n)
    lo = np.clip(i + start, 0, n)
    hi = np.clip(i + stop, 0, n)
    return np.asarray(total[hi] - total[lo])


def broad_significance(z: FloatArray, valid: BoolArray, width: int) -> FloatArray:
    """``s_w`` of the module docstring for each channel (0 where a side is mostly missing)."""
    half = width // 2
    side = max(half // 2, 1)
    values = np.where(valid, z, 0.0)
    counts = valid.astype(float)
    spans = {"c": (-half, half + 1), "l": (-half - side, -half), "r": (half + 1, half + 1 + side)}
    sums = {k: _window_sums(values, *span) for k, span in spans.items()}
    n = {k: _window_sums(counts, *span) for k, span in spans.items()}
    c_sum, c_n, l_sum, l_n, r_sum, r_n = sums["c"], n["c"], sums["l"], n["l"], sums["r"], n["r"]
    # both sides needed: one side alone does not cancel a slope
    usable = (c_n >= half) & (l_n >= side / 2) & (r_n >= side / 2)
    s_n = l_n + r_n
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (c_sum / c_n - (l_sum + r_sum) / s_n) / np.sqrt(1 / c_n + 1 / s_n)
    return np.asarray(np.where(usable, s, 0.0))


def _robust_model(
    x: FloatArray, flags: BoolArray, freq: FloatArray, degree: int, noise: float, iterations: int
) -> FloatArray:
    """:func:`smooth_model` refitted without channels ``CLIP`` sigma above it.

    RFI adds power: a hump strong enough to drag the model over the whole band (50
    sigma over 10 MHz) left a misfit at the band's edges that was flagged where the hump
    was not. Clipping single channels, not running means, leaves the trough's flanks
    (a fraction of a sigma per channel) in the fit.
    """
    fit = flags.copy()
    model = smooth_model(x, fit, freq, degree)
    for _ in range(iterations):
        new = flags | ((x / model - 1) > CLIP * noise)
        if np.array_equal(new, fit) or np.count_nonzero(~new) <= 2 * (degree + 1):
            break
        fit = new
        model = smooth_model(x, fit, freq, degree)
    return model


def _widths(n: int, freq_hz: FloatArray) -> list[int]:
    step = abs(float(freq_hz[-1] - freq_hz[0])) / max(n - 1, 1)
    widest = int(MAX_WIDTH_HZ / step) if step > 0 else 0
    widths = []
    w = MIN_WIDTH
    while w <= widest:
        widths.append(w)
        w *= 2
    return widths


def _runs_above(s: FloatArray, high: float, low: float) -> BoolArray:
    runs, _ = label(s > low)
    keep = np.unique(runs[s > high])
    return np.asarray(np.isin(runs, keep[keep > 0]), dtype=bool)


def flag_broad(
    spectrum: ArrayLike,
    freq_hz: ArrayLike,
    flags: ArrayLike | None = None,
    threshold: float = 5.0,
    degree: int = 5,
    max_iterations: int = 5,
    sigma: float | None = None,
) -> BoolArray:
    """Flags of broad humps in one spectrum of positive powers (module docstring).

    ``freq_hz`` are the channels' frequencies (positive, increasing); ``flags`` (kept) are
    channels already flagged, spikes among them; ``sigma`` the relative noise per channel
    when known (else from fourth differences).
    """
    x = np.asarray(spectrum, dtype=float)
    freq = np.asarray(freq_hz, dtype=float)
    if x.ndim != 1 or np.any(~np.isfinite(x)) or np.any(x <= 0):
        raise InvalidDataError("flag_broad takes one spectrum of finite, positive powers")
    if freq.shape != x.shape or not np.all(np.diff(freq) > 0) or not freq[0] > 0:
        raise InvalidDataError("flag_broad needs each channel's frequency, positive, increasing")
    given = np.zeros(x.shape, bool) if flags is None else np.asarray(flags, bool).copy()
    widths = _widths(x.size, freq)
    noise = difference_sigma(x) if sigma is None else float(sigma)
    if not widths or not noise > NOISELESS or np.count_nonzero(~given) <= 2 * (degree + 1):
        return given
    found = np.zeros(x.shape, bool)
    for _ in range(max_iterations):
        current = given | found
        model = _robust_model(x, current, freq, degree, noise, max_iterations)
        z = (x / model - 1) / noise
        new = np.zeros(x.shape, bool)
        for width in widths:
            valid = ~(given | new)
            s = broad_significance(z, valid, width)
            s /= max(1.0, float(robust_sigma(s[valid & (s != 0)])))
            hits = _runs_above(s, threshold, LOW * threshold)
            if hits.any():
                new |= binary_dilation(hits, iterations=max(int(GROW * width), 1)) & ~given
        if np.array_equal(new, found):
            break
        found = new
    return np.asarray(given | found, dtype=bool)
