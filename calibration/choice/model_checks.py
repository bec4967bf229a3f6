"""Checks of a solution's model size that do not rest on its in-sample fit alone.

In-sample residuals at the noise say little about overfitting: a model with as many
smooth terms as the data have smooth degrees of freedom fits the noise's smooth part too
(EDGES B18, four loads and 56 coefficients: residuals at the noise channel by channel, but
63 and 49 mK in 2 MHz bins where the noise alone gives 105 and 75 mK). Two checks look
elsewhere:

* **Binned residuals against the noise** (:func:`binned_chi_square`). Each calibrator's
  residual ``r_f = T_cal,f - T_f`` (its calibration with the solution, eq. 3.27, against
  its known temperature) is averaged over bins of ``bin_hz``, where the radiometer noise
  is reduced by the channel count and a missing smooth structure is not. A fit of ``p``
  effective coefficients leaves residuals whose variance is the noise's less what the fit
  absorbed, ``E[r r^T] = Sigma - X Cov(c) X^T`` (generalised least squares; the hat
  matrix's trace is ``p``). Per bin ``b`` the absorbed share is the leverage
  ``h_b = s_cal,b^2 / sigma_b^2`` (the calibration variance over the noise variance of the
  bin's mean, calibration errors taken as correlated across a bin, the noise as not), so::

      chi^2 = sum_b rbar_b^2 / sigma_b^2,      dof = sum_b (1 - h_b)

  and ``chi^2 / dof`` is near 1 for a model of the right size: above, structure is left
  (too few terms, or a wrong noise model); below, the fit holds more of the noise than
  its own error bars say.
* **Leave-one-out** (:mod:`calibration.checks.validation`): each calibrator held out and
  calibrated with the others' solution, its actual error against the predicted one.

:func:`fit_warnings` turns these and the noise scale into sentences for
``metadata["warnings"]``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..model.data import CalibrationData

FloatArray = NDArray[np.float64]

#: Bin width of the binned residual check (Hz): the issue's 2 MHz, about a tenth of the
#: 50 MHz bands EDGES measures over, wide enough to average 10-100 channels.
BIN_HZ = 2e6


@dataclass(frozen=True)
class BinnedSource:
    """One calibrator's binned residuals: RMS residual and RMS noise of the bins' means (K)."""

    name: str
    rms_residual_k: float
    rms_noise_k: float
    chi2: float
    dof: float


@dataclass(frozen=True)
class BinnedCheck:
    """The binned residual chi-square of a solution over its calibrators (module docstring)."""

    sources: tuple[BinnedSource, ...]
    bin_hz: float

    @property
    def chi2(self) -> float:
        """The binned residual chi-square over every calibrator."""
        return float(sum(s.chi2 for s in self.sources))

    @property
    def dof(self) -> float:
        """Its degrees of freedom: the bins less their leverage."""
        return float(sum(s.dof for s in self.sources))

    @property
    def per_dof(self) -> float:
        """``chi^2 / dof``: 1 for a model of the right size, NaN with no degree of freedom."""
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    def metadata(self) -> dict[str, object]:
        """Plain numbers for a solution's metadata."""
        return {
            "bin_mhz": self.bin_hz / 1e6,
            "chi2_per_dof": round(self.per_dof, 4),
            "dof": round(self.dof, 2),
            "sources": {
                s.name: {
                    "rms_residual_k": round(s.rms_residual_k, 6),
                    "rms_noise_k": round(s.rms_noise_k, 6),
                }
                for s in self.sources
            },
        }


def _bins(freq_hz: FloatArray, bin_hz: float) -> list[NDArray[np.intp]]:
    edges = np.arange(freq_hz[0], freq_hz[-1] + bin_hz, bin_hz)
    which = np.clip(np.searchsorted(edges, freq_hz, side="right") - 1, 0, None)
    return [np.flatnonzero(which == b) for b in np.unique(which)]


def binned_chi_square(
    solution: object, data: CalibrationData, bin_hz: float = BIN_HZ,
    names: Sequence[str] | None = None,
) -> BinnedCheck:
    """Each calibrator's residuals averaged over ``bin_hz`` against the noise (module doc).

    ``solution`` is any solution with ``calibrate`` (:class:`~calibration.solve.solution.Solution`).
    ``names`` defaults to every calibrator of ``data``.
    """
    out = []
    for name in names or data.names:
        source = data.sources[name]
        spectrum = solution.calibrate(  # type: ignore[attr-defined]
            data.freq_hz, data.gamma_rec, source, data.channel_width_hz, data.gamma_rec_std,
        )
        residual = spectrum.mean - np.asarray(source.temperature_k, dtype=float)
        noise_var = spectrum.std_measurement**2
        cal_var = spectrum.std_calibration**2
        chi2 = dof = 0.0
        rbar, sbar = [], []
        for idx in _bins(data.freq_hz, bin_hz):
            var = float(np.sum(noise_var[idx])) / idx.size**2
            if var <= 0:
                continue
            mean = float(np.mean(residual[idx]))
            leverage = min(float(np.mean(cal_var[idx])) / var, 1.0)
            chi2 += mean**2 / var
            dof += 1.0 - leverage
            rbar.append(mean)
            sbar.append(var)
        out.append(BinnedSource(
            name, float(np.sqrt(np.mean(np.square(rbar)))) if rbar else float("nan"),
            float(np.sqrt(np.mean(sbar))) if sbar else float("nan"), chi2, dof,
        ))
    return BinnedCheck(tuple(out), bin_hz)


#: ``s^2`` outside this range is far from the radiometer equation's 1: the noise model or
#: the model's size is wrong (an IG(1, 2) prior has its mode at 1; 68 % of runs of a
#: right model with thousands of rows fall within a few per cent of it).
S2_RANGE = (0.8, 1.25)
#: A held-out calibrator's actual / predicted error outside this range: error bars wrong
#: by more than the scatter a four-load run's leave-one-out shows with a right model.
LOO_RANGE = (0.7, 1.4)
#: Binned residual chi-square per degree of freedom outside this range.
BINNED_RANGE = (0.8, 1.25)


def fit_warnings(
    solution: object, loo: object | None = None, binned: BinnedCheck | None = None,
) -> list[str]:
    """Sentences on a solution whose numbers say its model or its error bars are off.

    ``solution`` has ``posterior.noise_variance`` and ``metadata``; ``loo`` is a
    :class:`~calibration.checks.validation.LeaveOneOutReport`; ``binned`` a :class:`BinnedCheck`.
    Each sentence gives the figure and what to do (the CLI's options).
    """
    out: list[str] = []
    meta = getattr(solution, "metadata", {}) or {}
    posterior = getattr(solution, "posterior", None)
    s2 = getattr(posterior, "noise_variance", None)
    orders = meta.get("orders_used") or meta.get("best_orders")
    named = f" (orders {','.join(map(str, orders))})" if orders else ""
    # The thesis solver's noise variance is sigma^2 in K^2, not a scale: not judged.
    scale = getattr(solution, "measurement_model", None) != "homoscedastic"
    if scale and s2 is not None and np.isfinite(s2) and not S2_RANGE[0] <= s2 <= S2_RANGE[1]:
        why = (
            "the model leaves structure the noise does not explain, or the noise is "
            "underestimated" if s2 > 1 else "the model fits part of the noise"
        )
        out.append(
            f"noise scale s^2 = {s2:.2f}{named}, far from the radiometer equation's 1: "
            f"{why}; check with `reach-cal validate RUN --leave-one-out`"
        )
    ceiling = meta.get("orders_at_ceiling") or []
    if ceiling:
        out.append(
            f"{', '.join(ceiling)} ended at the order limit {meta.get('order_limits')}: the "
            "data may want more terms than the model holds; its error bars miss that part"
        )
    for r in getattr(loo, "results", ()):
        if r.refused is not None or not np.isfinite(r.ratio):
            continue
        if not LOO_RANGE[0] <= r.ratio <= LOO_RANGE[1]:
            way = "under-predicted" if r.ratio > 1 else "over-predicted"
            out.append(
                f"held out, {r.name} misses by {r.rms_error_k:.3g} K against "
                f"{r.rms_predicted_k:.3g} K predicted ({way} {max(r.ratio, 1 / r.ratio):.1f}x)"
                f"{named}: the error bars do not hold off the calibrators; try other "
                "--orders or --max-orders"
            )
    if binned is not None and np.isfinite(binned.per_dof):
        lo, hi = BINNED_RANGE
        if not lo <= binned.per_dof <= hi:
            way = (
                "structure the model does not hold" if binned.per_dof > hi
                else "noise the model has fitted"
            )
            out.append(
                f"residuals in {binned.bin_hz / 1e6:g} MHz bins: chi^2/dof = "
                f"{binned.per_dof:.2f}{named}, {way}"
            )
    return out


def add_warnings(solution: object, sentences: list[str]) -> None:
    """Append ``sentences`` to ``solution.metadata["warnings"]`` (kept: others add there)."""
    meta = solution.metadata  # type: ignore[attr-defined]
    have = list(meta.get("warnings") or [])
    meta["warnings"] = have + [s for s in sentences if s not in have]
