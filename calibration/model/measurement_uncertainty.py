"""What the instruments' data sheets say about their errors: the VNA and the noise diode.

**VNA reflection accuracy** (thesis 2.1.1, table 2.3, Copper Mountain TR1300/1): the
magnitude of a reflection reading ``m = 20 log10 |G|`` dB is good to ``+-e(m)`` dB::

    -15 dB <= m <=   0 dB:  e = 0.4 dB
    -25 dB <= m <= -15 dB:  e = 1.5 dB          (at a shared edge the larger error counts)
    -35 dB <= m <= -25 dB:  e = 4.0 dB

The thesis turns a spread in dB into a linear spread of reflected power (eq. 2.2,
:func:`measurement_spread`)::

    spread = 10^((m + e)/10) - 10^((m - e)/10)                                     (2.2)

and, below the rated range (the 50 ohm loads, near -45 dB), extrapolates a fitted curve
that levels off. Here the per-channel uncertainty is expressed on ``|G|`` itself, where a
solver can propagate it: the half-width ``|G| (10^(e/20) - 10^(-e/20)) / 2``; below the
lowest rated level the *absolute* half-width stays that of the lowest level (-35 dB,
4 dB: 0.0085), because what limits a VNA there is its residual directivity, an additive
error that does not shrink with ``|G|`` (the same levelling-off as the thesis's fit, with
its level taken from the table). The data sheet's bound is read as ``coverage`` standard
deviations (2 by default: a 95 % bound). The table gives no phase accuracy; the error is
taken as a circular complex Gaussian of standard deviation ``sigma`` per component, so
``sigma_|G| = sigma`` and ``sigma_phase = sigma / |G|`` (capped at ``pi / sqrt(3)``, a
uniform phase): :func:`sample_reflections` draws it, optionally correlated over frequency
(a VNA's calibration error is smooth in frequency, not white).

**Noise diode** (table 2.1, Noisecom NC346A; eq. 2.1): ``ENR_dB = 10 log10((T - 290) / 290)``
so the diode's excess noise is ``290 K * 10^(ENR/10)``, about 1100 K in the REACH band: the
value the fitted ``T_NS`` should take (thesis fig. 4.20 against fig. 2.11).
:func:`check_noise_source` holds a fitted ``T_NS`` to it with a stated tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import InvalidDataError
from .simulate import NC346A_ENR_DB, enr_noise_temperature

__all__ = [
    "TR1300_1",
    "AccuracyBand",
    "NoiseSourceCheck",
    "VnaAccuracy",
    "check_noise_source",
    "expected_t_ns",
    "measurement_spread",
    "sample_reflections",
]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

T0_K = 290.0

#: Correlation lengths of :func:`sample_reflections` are capped at this many sweep lengths.
MAX_CORRELATION_SWEEPS = 4.0


@dataclass(frozen=True)
class AccuracyBand:
    """Readings between ``low_db`` and ``high_db`` are good to ``+-error_db``."""

    low_db: float
    high_db: float
    error_db: float


#: Thesis table 2.3: the TR1300/1's reflection magnitude accuracy.
TR1300_1 = (
    AccuracyBand(-15.0, 0.0, 0.4),
    AccuracyBand(-25.0, -15.0, 1.5),
    AccuracyBand(-35.0, -25.0, 4.0),
)


def measurement_spread(measurement_db: ArrayLike, error_db: ArrayLike) -> FloatArray:
    """Linear spread of reflected power for a reading ``m +- e`` dB, eq. (2.2)."""
    m, e = np.asarray(measurement_db, dtype=float), np.asarray(error_db, dtype=float)
    return np.asarray(10 ** ((m + e) / 10) - 10 ** ((m - e) / 10), dtype=float)


def _db(gamma: ArrayLike) -> FloatArray:
    mag = np.abs(np.asarray(gamma, dtype=complex))
    with np.errstate(divide="ignore"):
        return np.asarray(20 * np.log10(mag), dtype=float)


@dataclass(frozen=True)
class VnaAccuracy:
    """A VNA's reflection accuracy table as a per-channel standard uncertainty."""

    bands: tuple[AccuracyBand, ...] = TR1300_1
    coverage: float = 2.0
    """How many standard deviations the data sheet's bound is."""

    def __post_init__(self) -> None:
        if not self.bands or not self.coverage > 0:
            raise InvalidDataError("a VNA accuracy needs at least one band and coverage > 0")

    def error_db(self, gamma: ArrayLike) -> FloatArray:
        """The table's ``+-e`` for each reading (the top band above it, NaN below it)."""
        m = _db(gamma)
        err = np.full(m.shape, np.nan)
        top = max(self.bands, key=lambda b: b.high_db)
        for band in self.bands:
            inside = (m >= band.low_db) & ((m <= band.high_db) | (band is top))
            err = np.where(inside, np.fmax(err, band.error_db), err)
        return err

    def halfwidth(self, gamma: ArrayLike) -> FloatArray:
        """Half-width of the bound on ``|G|``, in reflection units; a floor below the table."""
        mag = np.abs(np.asarray(gamma, dtype=complex))
        err = self.error_db(gamma)
        half = mag * (10 ** (err / 20) - 10 ** (-err / 20)) / 2
        lowest = min(self.bands, key=lambda b: b.low_db)
        floor_mag = 10 ** (lowest.low_db / 20)
        floor = floor_mag * (10 ** (lowest.error_db / 20) - 10 ** (-lowest.error_db / 20)) / 2
        return np.asarray(np.where(np.isnan(err), floor, half), dtype=float)

    def sigma_magnitude(self, gamma: ArrayLike) -> FloatArray:
        """Standard uncertainty of ``|G|`` per channel (also of each of Re and Im)."""
        return np.asarray(self.halfwidth(gamma) / self.coverage, dtype=float)

    def sigma_phase_rad(self, gamma: ArrayLike) -> FloatArray:
        """Standard uncertainty of ``arg G`` per channel, radians."""
        mag = np.abs(np.asarray(gamma, dtype=complex))
        with np.errstate(divide="ignore"):
            ratio = self.sigma_magnitude(gamma) / mag
        return np.asarray(np.minimum(ratio, np.pi / np.sqrt(3)), dtype=float)


def sample_reflections(
    gamma: ArrayLike,
    rng: np.random.Generator,
    n_samples: int,
    accuracy: VnaAccuracy | None = None,
    correlation_channels: float = 0.0,
) -> ComplexArray:
    """Monte-Carlo draws of the true reflections given readings ``gamma`` (1-D, channels).

    Returns shape ``(n_samples, n_channels)``: ``gamma + sigma (x + j y)`` with ``x, y``
    unit Gaussian processes over channels of correlation ``exp(-d^2 / (2 c^2))`` at a
    distance of ``d`` channels, ``c = correlation_channels`` (0: independent channels; a
    length beyond :data:`MAX_CORRELATION_SWEEPS` sweeps counts as that many, where a draw
    is already rigid across the sweep to 3 %).
    Pushing each draw through a solver gives the reflection error's share of its error bars.
    """
    from scipy.signal import fftconvolve
    g = np.asarray(gamma, dtype=complex)
    if g.ndim != 1:
        raise InvalidDataError("sample_reflections takes one reflection per channel (1-D)")
    sigma = (accuracy or VnaAccuracy()).sigma_magnitude(g)
    if correlation_channels > 0:
        # white noise smoothed by a Gaussian of width c / sqrt(2) has correlation exp(-d^2/2c^2);
        # it is drawn 5 widths beyond both ends so that the edges are as correlated as the middle
        width = min(correlation_channels, MAX_CORRELATION_SWEEPS * g.size) / np.sqrt(2)
        half = int(np.ceil(5 * width))
        kernel = np.exp(-0.5 * (np.arange(-half, half + 1) / width) ** 2)
        kernel /= np.sqrt(np.sum(kernel**2))
        white = rng.standard_normal((2, n_samples, g.size + 2 * half))
        white = fftconvolve(white, kernel[None, None, :], mode="valid", axes=-1)
    else:
        white = rng.standard_normal((2, n_samples, g.size))
    return np.asarray(g + sigma * (white[0] + 1j * white[1]), dtype=complex)


def expected_t_ns(freq_hz: ArrayLike, t_ambient_k: float | None = None) -> FloatArray:
    """The noise diode's ``T_NS`` from its ENR table (table 2.1, eq. 2.1), per channel.

    ``290 K * 10^(ENR/10)``, linear in dB between the table's frequencies (the simulated
    receiver's truth, :func:`calibration.model.simulate.enr_noise_temperature`). With
    ``t_ambient_k`` it is the thesis's fig. 2.11 instead: the on-state temperature of
    eq. (2.1), ``290 (1 + 10^(ENR/10))``, less the ambient temperature (8 K lower at 298 K,
    well inside the ENR tolerance).
    """
    f = np.asarray(freq_hz, dtype=float)
    lo, hi = min(NC346A_ENR_DB) * 1e6, max(NC346A_ENR_DB) * 1e6
    if f.size and (np.min(f) < lo or np.max(f) > hi):
        raise InvalidDataError(f"the ENR table covers {lo / 1e6:g}-{hi / 1e6:g} MHz only")
    excess = enr_noise_temperature(f)
    return excess if t_ambient_k is None else np.asarray(excess + T0_K - t_ambient_k)


@dataclass(frozen=True)
class NoiseSourceCheck:
    """A fitted ``T_NS`` held to the ENR table: :func:`check_noise_source`.

    Attributes
    ----------
    passed
        At least ``min_fraction`` of the channels lie within ``[low_k, high_k]``.
    fraction_within
        The fraction of channels that do.
    offset_db
        ``10 log10`` of the median ratio fitted / expected: the ENR the fit implies, less the
        table's (a path loss in front of the diode shows as a negative offset).
    worst_freq_hz, worst_halfwidths
        The channel furthest from the band's centre, in half-widths of the band (1 is its
        edge).
    """

    expected_k: FloatArray
    low_k: FloatArray
    high_k: FloatArray
    fraction_within: float
    offset_db: float
    worst_freq_hz: float
    worst_halfwidths: float
    min_fraction: float

    @property
    def passed(self) -> bool:
        """The verdict."""
        return self.fraction_within >= self.min_fraction

    def __str__(self) -> str:
        verdict = "PASS" if self.passed else "FAIL"
        return (
            f"noise source {verdict}: {100 * self.fraction_within:.1f}% of channels within the "
            f"ENR table's tolerance (need {100 * self.min_fraction:.0f}%), fitted T_NS "
            f"{self.offset_db:+.2f} dB from the table, worst at "
            f"{self.worst_freq_hz / 1e6:.2f} MHz ({self.worst_halfwidths:.1f} half-widths "
            "from the centre)"
        )


def check_noise_source(
    fitted_t_ns: ArrayLike,
    freq_hz: ArrayLike,
    fitted_sigma_k: ArrayLike | None = None,
    enr_uncertainty_db: float = 0.2,
    path_loss_db: float = 0.0,
    k_sigma: float = 3.0,
    min_fraction: float = 0.95,
    t_ambient_k: float | None = None,
) -> NoiseSourceCheck:
    """Hold a fitted ``T_NS`` to the noise diode's ENR table (thesis fig. 4.20).

    The expected band per channel is the table's ``T_NS`` (:func:`expected_t_ns`) with the
    ENR ``+-enr_uncertainty_db`` (an assumed calibration uncertainty of the data sheet,
    which quotes none), lowered by up to ``path_loss_db`` (the path from the diode to the
    receiver input, e.g. through the MTS switch), widened by ``k_sigma`` times the fit's
    own standard error ``fitted_sigma_k``. The check passes when at least ``min_fraction``
    of the channels lie inside (a few channels of RFI or fit artefacts do not fail it).
    """
    f = np.asarray(freq_hz, dtype=float)
    fitted = np.asarray(fitted_t_ns, dtype=float)
    if fitted.shape != f.shape or f.ndim != 1 or f.size == 0:
        raise InvalidDataError("fitted T_NS and frequencies must be 1-D of the same length")
    if enr_uncertainty_db < 0 or path_loss_db < 0:
        raise InvalidDataError("ENR uncertainty and path loss are dB >= 0")
    expected = expected_t_ns(f, t_ambient_k)
    sigma = np.zeros_like(f) if fitted_sigma_k is None else np.asarray(fitted_sigma_k, float)
    low = expected * 10 ** (-(enr_uncertainty_db + path_loss_db) / 10) - k_sigma * sigma
    high = expected * 10 ** (enr_uncertainty_db / 10) + k_sigma * sigma
    within = (fitted >= low) & (fitted <= high)
    centre, half = (high + low) / 2, (high - low) / 2
    excess = np.abs(fitted - centre) / half
    worst = int(np.argmax(excess))
    return NoiseSourceCheck(
        expected_k=expected,
        low_k=low,
        high_k=high,
        fraction_within=float(np.mean(within)),
        offset_db=float(10 * np.log10(np.median(fitted / expected))),
        worst_freq_hz=float(f[worst]),
        worst_halfwidths=float(excess[worst]),
        min_fraction=min_fraction,
    )
