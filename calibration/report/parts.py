"""Parts of the report's summary and figures kept apart from :mod:`calibration.report.writer`.

The leave-one-out table and figure (:mod:`calibration.report.loo`): each calibrator's
in-sample residual (RMS over channels, against the solution's full predicted sd) beside
its residual held out of the solve (actual against predicted, the fractions of channels
inside the 68/95 % intervals, the orders the held-out solve used).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from .loo import ReportLeaveOneOut
from .render import Section

if TYPE_CHECKING:
    from collections.abc import Mapping

    from ..solve.solution import CalibratedSpectrum

FloatArray = NDArray[np.float64]

__all__ = ["LOO_TITLE", "NO_TRUTH", "loo_figure", "loo_section"]

#: The floor table's actual distance where no truth is known.
NO_TRUTH = "unknown (no truth): the predicted distance holds only if the model is right"
LOO_TITLE = "Leave-one-out: each calibrator held out of the solve (RMS over channels)"


class _Calibrated(Protocol):
    @property
    def spectra(self) -> Mapping[str, CalibratedSpectrum]: ...

    @property
    def references(self) -> Mapping[str, FloatArray]: ...


def _rms(values: FloatArray) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def _in_sample(
    calibrated: _Calibrated, name: str
) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """A calibrator's in-sample residual, calibration sd and the rest of its sd (K)."""
    spectrum, reference = calibrated.spectra.get(name), calibrated.references.get(name)
    if spectrum is None or reference is None or spectrum.mean.shape != reference.shape:
        return None
    rest = np.sqrt(np.maximum(spectrum.std**2 - spectrum.std_calibration**2, 0.0))
    return spectrum.mean - reference, spectrum.std_calibration, rest


def loo_section(loo: ReportLeaveOneOut | None, calibrated: _Calibrated) -> Section:
    """The table of in-sample and held-out residuals (module docstring)."""
    head = (
        "calibrator", "in-sample residual (mK)", "in-sample residual / predicted",
        "held out: actual (K)", "held out: predicted (K)", "actual / predicted",
        "in 68 %", "in 95 %", "orders used held out",
    )
    if loo is None:
        return Section(LOO_TITLE, ("note",), [(
            "not computed: `reach-cal report SOLUTION --run RUN` computes it (one solve per "
            "calibrator) unless --no-leave-one-out",
        )])
    rows: list[tuple[str, ...]] = []
    for item in loo.held:
        r = item.result
        fit = _in_sample(calibrated, r.name)
        inside = ("—", "—") if fit is None else (
            f"{_rms(fit[0]) * 1e3:.4g}",
            f"{_rms(fit[0]) / _rms(np.sqrt(fit[1] ** 2 + fit[2] ** 2)):.3f}",
        )
        if r.refused is not None:
            reason = r.refused.split(" (")[0]  # the reason; its details are validate's
            rows.append((r.name, *inside, f"refused: {reason}", *["—"] * 5))
            continue
        rows.append((
            r.name, *inside, f"{r.rms_error_k:.4g}", f"{r.rms_predicted_k:.4g}",
            f"{r.ratio:.3f}", f"{r.inside_68:.2f}", f"{r.inside_95:.2f}",
            ",".join(map(str, r.orders)) or "per channel",
        ))
    title = f"{LOO_TITLE}; {loo.procedure}; {loo.elapsed_s:.1f} s"
    return Section(title, head, rows)


def loo_figure(loo: ReportLeaveOneOut, calibrated: _Calibrated) -> Figure:
    """:func:`calibration.report.figures.held_out_residuals` of ``loo``, with the in-sample fits."""
    from .figures import held_out_residuals

    held: dict[str, tuple[FloatArray, FloatArray, FloatArray] | str] = {}
    in_sample = {}
    for item in loo.held:
        name = item.result.name
        if (
            item.residual is None or item.predicted_calibration is None
            or item.predicted_noise is None
        ):
            held[name] = item.result.refused or "not solved"
        else:
            held[name] = (item.residual, item.predicted_calibration, item.predicted_noise)
        fit = _in_sample(calibrated, name)
        if fit is not None and fit[0].shape == loo.freq_hz.shape:
            in_sample[name] = fit
    return held_out_residuals(loo.freq_hz, held, in_sample)
