"""Calibrated spectra of many runs averaged in LST bins, the error of each average in two parts.

In an LST bin ``b`` and channel ``k``, spectrum ``i`` (temperature ``T_i``, radiometer
noise ``r_i``, calibration error ``c_i``, trace-noise error ``g_i``; the run file's
parts, :mod:`calibration.io.calibrated_spectra`) has the weight ``w_i = 1 / r_i^2``, or 0
where it is flagged. The bin's average and its errors are::

    T_b = sum_i w_i T_i / W,                 W = sum_i w_i
    radiometer:   s_r^2 = sum_i w_i^2 r_i^2 / W^2 = 1 / W
    calibration:  s_c^2 = [sum_s (sum_{i in s} w_i c_i)^2 + sum_g (sum_{i in g} w_i g_i)^2] / W^2
    total:        s^2 = s_r^2 + s_c^2

The radiometer noise is independent between spectra (the radiometer equation; thesis
eq. 3.13 through 3.27), so it averages down as ``1/W``. The calibration error of a
spectrum is ``x_i^T (c_s - c)``, one draw of solution ``s``'s posterior (eq. 3.41) shared
by every spectrum ``s`` calibrated; within one bin the rows ``x_i`` differ only through
the sky's small change, so the errors of one solution's spectra are taken as fully
correlated (their standard deviations add; by Cauchy-Schwarz an upper bound where the
rows differ) and those of different solutions, independent draws, add in quadrature. The
S11s' trace noise is the same sum over the spectra calibrated with one set of sweeps
(``g``), and is part of the calibration error.

The per-run work, :func:`bin_run`, is a pure function of one run file's spectra
(:func:`calibration.io.calibrated_spectra.read_calibrated_spectra`) and returns sums that
add across runs (:func:`combine`, associative): a graph over run files maps the one and
reduces with the other. The calibration sums stay per (solution, bin) until the end, so
a season's memory grows with the solutions times the bins each covers times the channels.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..core.errors import InvalidDataError
from ..io.calibrated_spectra import RunSpectra, Site, SolutionRecord

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

__all__ = ["BinnedRun", "Season", "SpectrumRow", "bin_run", "combine", "lst_edges"]

#: The widest relative difference of two runs' channel frequencies that is one grid.
GRID_RTOL = 1e-9
#: The LST bin width when none is given (h).
DEFAULT_LST_BIN_H = 1.0


def lst_edges(width_h: float) -> FloatArray:
    """Bin edges over [0, 24] h; ``width_h`` must divide 24 h."""
    n = 24.0 / width_h if width_h > 0 else math.inf
    if not (math.isfinite(n) and abs(n - round(n)) < 1e-6 and round(n) >= 1):
        raise InvalidDataError(
            f"an LST bin of {width_h:g} h does not divide 24 h; choose --lst-bin-h 0.25, 0.5, "
            "1, 2, ..."
        )
    return np.linspace(0.0, 24.0, round(n) + 1)


@dataclass(frozen=True)
class SpectrumRow:
    """One input spectrum: where it came from, when, its bin and its solution."""

    run: str
    name: str
    time_s: float
    lst_h: float
    bin: int
    solution: str
    flagged: int


@dataclass(frozen=True)
class BinnedRun:
    """Sums over LST bins ``(n_bins, n_channels)`` that add across runs (module doc)."""

    freq_hz: FloatArray
    edges_h: FloatArray
    site: Site
    weight: FloatArray
    weighted: FloatArray
    count: IntArray
    calibration: dict[tuple[str, int], FloatArray]
    reflection: dict[tuple[str, int], FloatArray]
    spectra: tuple[SpectrumRow, ...]
    solutions: dict[str, SolutionRecord]
    runs: tuple[str, ...]


@dataclass(frozen=True)
class Season:
    """LST-binned averages ``(n_bins, n_channels)`` and their errors (K).

    ``std_calibration`` includes ``std_reflection`` (the S11s' trace noise); a channel
    of a bin with no weight is flagged and its values NaN.
    """

    freq_hz: FloatArray
    edges_h: FloatArray
    site: Site
    mean: FloatArray
    std_radiometer: FloatArray
    std_calibration: FloatArray
    std_reflection: FloatArray
    weight: FloatArray
    count: IntArray
    spectra: tuple[SpectrumRow, ...]
    solutions: tuple[SolutionRecord, ...]
    runs: tuple[str, ...]
    attrs: dict[str, object] = field(default_factory=dict)

    @property
    def std(self) -> FloatArray:
        """Total error of each average (K)."""
        return np.asarray(np.sqrt(self.std_radiometer**2 + self.std_calibration**2))

    @property
    def flags(self) -> NDArray[np.bool_]:
        """Channels of bins without weight."""
        return np.asarray(self.weight <= 0)

    @property
    def lst_h(self) -> FloatArray:
        """Bin centres (h)."""
        return np.asarray(0.5 * (self.edges_h[:-1] + self.edges_h[1:]))

    def bin_times(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Per bin the mean, first and last time (Unix s) of its spectra (NaN: none)."""
        n = self.edges_h.size - 1
        mean, first, last = (np.full(n, np.nan) for _ in range(3))
        for b in range(n):
            times = [r.time_s for r in self.spectra if r.bin == b]
            if times:
                mean[b], first[b], last[b] = np.mean(times), min(times), max(times)
        return mean, first, last


def bin_run(run: RunSpectra, edges_h: FloatArray) -> BinnedRun:
    """One run's spectra summed per LST bin (module doc): the per-run work."""
    n_bins, n_ch = edges_h.size - 1, run.freq_hz.size
    width = float(edges_h[1] - edges_h[0])
    bins = np.floor(np.mod(run.lst_h, 24.0) / width).astype(np.int64) % n_bins
    weights = np.where(run.flags, 0.0, 1.0 / np.where(run.flags, 1.0, run.std_radiometer) ** 2)
    values = np.where(run.flags, 0.0, run.mean)
    weight = np.zeros((n_bins, n_ch))
    weighted = np.zeros((n_bins, n_ch))
    count = np.zeros((n_bins, n_ch), dtype=np.int64)
    np.add.at(weight, bins, weights)
    np.add.at(weighted, bins, weights * values)
    np.add.at(count, bins, (~run.flags).astype(np.int64))
    digests = [run.solutions[s].digest for s in run.solution]
    calibration = _group_sums(digests, bins, weights * run.std_calibration)
    reflection = _group_sums(list(run.sweeps), bins, weights * run.std_reflection)
    rows = tuple(
        SpectrumRow(run.path, name, float(t), float(lst), int(b), d, int(flags.sum()))
        for name, t, lst, b, d, flags in zip(
            run.names, run.time_s, run.lst_h, bins, digests, run.flags, strict=True
        )
    )
    used = {run.solutions[s].digest: run.solutions[s] for s in sorted(set(run.solution))}
    return BinnedRun(
        run.freq_hz, edges_h, run.site, weight, weighted, count, calibration, reflection,
        rows, used, (run.path,),
    )


def _group_sums(
    keys: list[str], bins: IntArray, terms: FloatArray
) -> dict[tuple[str, int], FloatArray]:
    """``sum_{i in (key, bin)} terms_i`` for every (key, bin) present."""
    out: dict[tuple[str, int], FloatArray] = {}
    for key, b, term in zip(keys, bins, terms, strict=True):
        k = (key, int(b))
        out[k] = out[k] + term if k in out else np.array(term, dtype=float)
    return out


def _check_same(a: BinnedRun, b: BinnedRun) -> None:
    """Refuse to add runs on different grids, bins or sites."""
    if a.freq_hz.shape != b.freq_hz.shape or not np.allclose(
        a.freq_hz, b.freq_hz, rtol=GRID_RTOL, atol=0
    ):
        raise InvalidDataError(
            f"{b.runs[0]}: {b.freq_hz.size} channels {b.freq_hz[0] / 1e6:.4f}-"
            f"{b.freq_hz[-1] / 1e6:.4f} MHz, not the grid of {a.runs[0]} ({a.freq_hz.size} "
            f"channels {a.freq_hz[0] / 1e6:.4f}-{a.freq_hz[-1] / 1e6:.4f} MHz): a season "
            "combines runs calibrated on one grid; leave it out or make a season per grid"
        )
    if not np.array_equal(a.edges_h, b.edges_h):
        raise InvalidDataError("runs binned with different LST bins cannot be added")
    if (a.site.longitude_deg, a.site.latitude_deg) != (b.site.longitude_deg, b.site.latitude_deg):
        raise InvalidDataError(
            f"{b.runs[0]}: site at {b.site.longitude_deg}, {b.site.latitude_deg} deg, not "
            f"{a.runs[0]}'s {a.site.longitude_deg}, {a.site.latitude_deg}: a season is one site"
        )


def add(a: BinnedRun, b: BinnedRun) -> BinnedRun:
    """The sums of two sets of runs (associative and commutative but for row order)."""
    _check_same(a, b)

    def merged(x: dict[tuple[str, int], FloatArray], y: dict[tuple[str, int], FloatArray]) -> (
        dict[tuple[str, int], FloatArray]
    ):
        out = dict(x)
        for k, v in y.items():
            out[k] = out[k] + v if k in out else v
        return out

    return BinnedRun(
        a.freq_hz, a.edges_h, a.site, a.weight + b.weight, a.weighted + b.weighted,
        a.count + b.count, merged(a.calibration, b.calibration),
        merged(a.reflection, b.reflection), a.spectra + b.spectra,
        {**b.solutions, **a.solutions}, a.runs + b.runs,
    )


def _square_sum(sums: dict[tuple[str, int], FloatArray], shape: tuple[int, int]) -> FloatArray:
    out = np.zeros(shape)
    for (_, b), s in sums.items():
        out[b] += s**2
    return out


def combine(parts: Iterable[BinnedRun]) -> Season:
    """The season of the runs' sums: averages and errors (module doc)."""
    total: BinnedRun | None = None
    for part in parts:
        total = part if total is None else add(total, part)
    if total is None:
        raise InvalidDataError("no runs to combine: give at least one run file")
    shape = total.weight.shape
    has = total.weight > 0
    safe = np.where(has, total.weight, 1.0)
    with np.errstate(invalid="ignore"):
        mean = np.where(has, total.weighted / safe, np.nan)
        radiometer = np.where(has, 1.0 / np.sqrt(safe), np.nan)
        traces = _square_sum(total.reflection, shape)
        reflection = np.where(has, np.sqrt(traces) / safe, np.nan)
        both = _square_sum(total.calibration, shape) + traces
        calibration = np.where(has, np.sqrt(both) / safe, np.nan)
    order = sorted(total.solutions.values(), key=lambda s: (s.timestamp, s.digest))
    spectra = tuple(sorted(total.spectra, key=lambda r: (r.time_s, r.run, r.name)))
    return Season(
        total.freq_hz, total.edges_h, total.site, mean, radiometer, calibration, reflection,
        total.weight, total.count, spectra, tuple(order), tuple(sorted(total.runs)),
    )
