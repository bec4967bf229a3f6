"""Calibrator consistency: find a calibrator whose stated temperature disagrees with the others.

The thesis (4.7) excluded two REACH calibrators by hand because they spoiled the fit. Here
each calibrator ``k`` is held out of the solve in turn (:func:`calibration.checks.validation.
leave_one_out`) and calibrated with the others' solution. Its calibration error
``e = T_cal,k - T_k`` over the ``N`` channels is, when every temperature is right and the
error bars are honest, Gaussian with covariance::

    C = R Cov(c) R^T + diag(s_meas^2)                       (eqs. 3.41, 3.42)

``R`` the held-out source's design rows (``T_cal = R c``), ``Cov(c)`` the solution's
posterior, ``s_meas`` its radiometer (or homoscedastic) noise. A wrong thermometer reading
is one offset ``d`` for the whole spectrum (``e = -d 1 + noise``); its generalised least
squares estimate and the residual chi-square are::

    d_hat = -(1^T C^-1 e) / (1^T C^-1 1),     var d_hat = 1 / (1^T C^-1 1) + sigma_T^2
    chi2  = e^T C^-1 e - (1^T C^-1 e)^2 / (1^T C^-1 1)

(``sigma_T`` the calibrator's stated thermometry uncertainty). ``d_hat`` is the
temperature the calibrator is stated at less the one the others imply, ``z = d_hat /
sqrt(var d_hat)`` it in standard errors; ``chi2`` shows a disagreement in shape (a wrong
reflection, an unmodelled cable); it is tested only with the radiometer noise model, since
the thesis solver's one homoscedastic ``sigma`` for every source (eq. 4.3) is too small
for the reflective ones and too large for the matched ones channel by channel. ``C^-1`` is
applied by the Woodbury identity (a Cholesky factor of ``I + U^T D^-1 U``, with
``U U^T = R Cov R^T`` and ``D = diag(s_meas^2)``), never formed.

**Threshold.** Under the null ``z ~ N(0, 1)`` and ``chi2 ~ chi2(N - 1)``. With ``m``
calibrators that can be held out (a refused solve cannot be checked) a round makes ``2 m``
tests, each at level ``alpha / (2 m)`` (Bonferroni): ``|z| > Phi^-1(1 - alpha / (4 m))`` or
``P(chi2) < alpha / (2 m)``. A round on a consistent set then flags something with
probability at most ``alpha`` whatever the correlation between the held-out statistics
(they share data). Default ``alpha = 0.01``: for the twelve REACH calibrators (the hot
load not checkable, ``m = 11``) ``|z| > 3.51``.

**Which one** (the likelihood). A wrong calibrator biases every solution it takes part in,
so the others fail their checks too, and the largest ``|z|`` need not be the culprit: with
the hot load held out, a wrong ambient-temperature load is the only temperature contrast
left and sets ``T_NS`` by itself, so the hot load is predicted kelvins away. When a round
flags anything, the calibrator named is the checkable ``k`` under which all the measured
``Q`` are most probable, "``k``'s temperature is off by ``d ~ N(0, tau^2)``, the others
are right"::

    log p(Q | H_k) = sum_{i != k, f} log N(Q_if; Q_if(theta_-k), var Q_if)
                     + log N(e_k; 0, C_k + (tau^2 + sigma_T^2) 1 1^T) + sum_f log|X_L T_NS|_kf

with ``theta_-k`` the others' posterior mean, ``var Q`` the radiometer equation's (eq.
3.9), the held-out calibrator's predictive with an unknown offset (Sherman-Morrison and
the determinant lemma on the forms above) and its Jacobian ``dT/dQ`` to make it a density
of ``Q`` as well. ``tau`` (default 10 K: a misread thermocouple or a wrong heater
set-point) only penalises explanations needing an offset of many ``tau``. The solvers'
own log evidence is not used: it is a density of temperatures linearised about the
solver's operating point, and where a wrong load alone sets ``T_NS`` that point is far
from converged (seen: a seed of the table 4.1 set with one load 5 K off, ``s^2 = 1.01`` in
the linearised fit, chi-square per channel 400-26000 in ``Q``), which made the hot load
look the better explanation.

:func:`exclude_inconsistent` excludes the named calibrator and checks again, at most
``max_exclusions`` times. A calibrator without which the solver refuses (e.g. the hot load,
the only one setting ``T_NS``) is never excluded: it is reported as not checkable.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_factor, cho_solve

from ..core.constants import DEFAULT_ALPHA
from ..core.errors import CalibrationError, InvalidDataError
from ..model.data import CalibrationData
from ..model.noise_waves import INDEX, design_terms, model_q
from ..solve.per_frequency import ChannelSolution
from ..solve.solvers import AnySolution
from .validation import LeaveOneOutReport, leave_one_out

__all__ = [
    "CalibratorCheck",
    "ConsistencyReport",
    "Exclusion",
    "HeldOutFit",
    "check_consistency",
    "exclude_inconsistent",
    "held_out_fit",
]

FloatArray = NDArray[np.float64]
Solve = Callable[[CalibrationData], AnySolution]
DEFAULT_OFFSET_SD_K = 10.0


@dataclass(frozen=True)
class CalibratorCheck:
    """One calibrator held out: how far its stated temperature is from the others' (K).

    ``offset_k`` is its stated temperature less the one the others' solution implies,
    ``offset_std_k`` its standard error, ``z`` their ratio; ``chi2_shape`` / ``dof_shape``
    the residual chi-square after the offset. ``p_offset`` (two-sided) and ``p_shape``
    (upper tail) are their p-values; ``flagged`` whether either passes the round's
    threshold (``p_shape`` only if ``shape_tested``). ``ratio`` is the leave-one-out RMS
    actual / predicted error; ``log_evidence`` that of "this one is off, the others
    right". ``refused`` holds the solver's message when the others alone cannot be solved.
    """

    name: str
    offset_k: float = float("nan")
    offset_std_k: float = float("nan")
    z: float = float("nan")
    chi2_shape: float = float("nan")
    dof_shape: int = 0
    p_offset: float = float("nan")
    p_shape: float = float("nan")
    ratio: float = float("nan")
    log_evidence: float = float("nan")
    shape_tested: bool = True
    flagged: bool = False
    refused: str | None = None

    def line(self, best_log_evidence: float) -> str:
        """One row of :meth:`ConsistencyReport.lines`."""
        if self.refused is not None:
            reason = self.refused.split(" (")[0]
            return f"{self.name:<10} not checkable, the solve without it is refused: {reason}"
        mark = "  flagged" if self.flagged else ""
        return (
            f"{self.name:<10} {self.offset_k:>+10.4f} {self.offset_std_k:>9.4f} "
            f"{self.z:>+8.2f} {self.chi2_shape / self.dof_shape:>9.3f} {self.p_shape:>9.2g} "
            f"{self.ratio:>7.3f} {self.log_evidence - best_log_evidence:>10.1f}{mark}"
        )


@dataclass(frozen=True)
class ConsistencyReport:
    """One round of checks: every calibrator held out, with the round's threshold."""

    checks: tuple[CalibratorCheck, ...]
    alpha: float
    z_threshold: float
    p_threshold: float
    offset_sd_k: float
    leave_one_out: LeaveOneOutReport

    @property
    def flagged(self) -> tuple[str, ...]:
        """The calibrators past the threshold, in the run's order."""
        return tuple(c.name for c in self.checks if c.flagged)

    @property
    def checkable(self) -> tuple[CalibratorCheck, ...]:
        """The checks whose held-out solve was not refused."""
        return tuple(c for c in self.checks if c.refused is None)

    @property
    def not_checkable(self) -> tuple[str, ...]:
        """The calibrators whose held-out solve was refused."""
        return tuple(c.name for c in self.checks if c.refused is not None)

    @property
    def worst(self) -> CalibratorCheck | None:
        """The calibrator named (largest evidence of being off) if any is flagged, else None."""
        if not self.flagged:
            return None
        return max(self.checkable, key=lambda c: c.log_evidence)

    def lines(self) -> list[str]:
        """A table for the terminal, then the verdict."""
        best = max((c.log_evidence for c in self.checkable), default=0.0)
        rows = [
            f"{'held out':<10} {'offset K':>10} {'+-':>9} {'z':>8} {'chi2/dof':>9} "
            f"{'p shape':>9} {'ratio':>7} {'d log Z':>10}"
        ]
        rows += [c.line(best) for c in self.checks]
        rows.append(
            f"threshold: |z| > {self.z_threshold:.2f} or p(chi2) < {self.p_threshold:.2g} "
            f"(false-alarm rate {self.alpha:g} over {len(self.checkable)} checkable "
            f"calibrators); d log Z: evidence that this one is off by N(0, "
            f"{self.offset_sd_k:g} K), relative to the best"
        )
        worst = self.worst
        if worst is None:
            rows.append("consistent: no calibrator disagrees with the others")
        else:
            rows.append(
                f"disagrees: {worst.name}, its stated temperature {worst.offset_k:+.4f} +- "
                f"{worst.offset_std_k:.4f} K from the others' (z = {worst.z:+.1f}, chi2/dof "
                f"{worst.chi2_shape / worst.dof_shape:.3f})"
            )
        return rows


@dataclass(frozen=True)
class HeldOutFit:
    """The quadratic forms of one held-out calibrator's error ``e`` (module doc).

    ``a = 1^T C^-1 1``, ``b = 1^T C^-1 e``, ``c = e^T C^-1 e``, ``log_det = log |C|`` over
    ``n`` channels; ``temperature_var_k2`` the stated thermometry variance ``sigma_T^2``.
    """

    a: float
    b: float
    c: float
    log_det: float
    n: int
    temperature_var_k2: float

    @property
    def offset_k(self) -> float:
        """Stated temperature less the others' (GLS), ``-b / a``."""
        return -self.b / self.a

    @property
    def offset_std_k(self) -> float:
        """Its standard error, with the thermometry uncertainty."""
        return float(np.sqrt(1.0 / self.a + self.temperature_var_k2))

    @property
    def chi2_shape(self) -> float:
        """``e^T C^-1 e`` less the offset's share: chi-square with ``n - 1`` dof."""
        return self.c - self.b * self.b / self.a

    def log_predictive(self, offset_sd_k: float) -> float:
        """``log N(e; 0, C + v 1 1^T)``: ``e`` with an offset of variance ``v = sd^2 + sigma_T^2``.

        Sherman-Morrison and the matrix determinant lemma on the Woodbury forms.
        """
        v = offset_sd_k**2 + self.temperature_var_k2
        quad = self.c - v * self.b**2 / (1.0 + v * self.a)
        log_det = self.log_det + np.log1p(v * self.a)
        return float(-0.5 * (quad + log_det + self.n * np.log(2 * np.pi)))


def held_out_fit(solution: AnySolution, data: CalibrationData, name: str) -> HeldOutFit:
    """The forms of :class:`HeldOutFit` for ``name`` calibrated by ``solution`` (without it).

    A per-channel solution on its own channels has independent errors per channel: ``C``
    is then diagonal, ``std_calibration^2 + std_measurement^2``.
    """
    source = data.sources[name]
    spectrum = solution.calibrate(
        data.freq_hz, data.gamma_rec, source,
        data.channel_width_hz, data.gamma_rec_std,
    )
    if not np.all(spectrum.std_measurement > 0):
        raise InvalidDataError("a consistency check needs the measurement noise per channel", name)
    error = spectrum.mean - np.asarray(source.temperature_k, dtype=float)
    if isinstance(solution, ChannelSolution):
        var = spectrum.std_calibration**2 + spectrum.std_measurement**2
        if not np.all(np.isfinite(var)):
            raise InvalidDataError(
                "the others' per-channel errors are undefined (least squares with exactly 5 "
                "calibrators)", name,
            )
        return HeldOutFit(
            a=float(np.sum(1.0 / var)),
            b=float(np.sum(error / var)),
            c=float(np.sum(error**2 / var)),
            log_det=float(np.sum(np.log(var))),
            n=error.size,
            temperature_var_k2=source.temperature_std_k**2,
        )
    values, vectors = np.linalg.eigh(solution.posterior.covariance)
    root = vectors * np.sqrt(np.clip(values, 0.0, None))
    w = 1.0 / spectrum.std_measurement
    u = (spectrum.rows @ root) * w[:, None]  # whitened U, U U^T = R Cov R^T
    factor = cho_factor(np.eye(u.shape[1]) + u.T @ u, lower=True)

    def inner(x: FloatArray, y: FloatArray) -> float:
        xw, yw = x * w, y * w
        return float(xw @ yw - (u.T @ xw) @ cho_solve(factor, u.T @ yw))

    ones = np.ones_like(error)
    log_det = 2 * np.sum(np.log(spectrum.std_measurement)) + 2 * np.sum(np.log(np.diag(factor[0])))
    return HeldOutFit(
        a=inner(ones, ones),
        b=inner(ones, error),
        c=inner(error, error),
        log_det=float(log_det),
        n=error.size,
        temperature_var_k2=source.temperature_std_k**2,
    )


def _radiometer_noise(solution: AnySolution) -> bool:
    """Whether the solution's noise model is the radiometer equation (shape is testable)."""
    if isinstance(solution, ChannelSolution):
        return solution.method == "bayesian"
    return solution.measurement_model == "radiometer"


def _log_likelihood(solution: AnySolution, data: CalibrationData, name: str) -> float:
    """``log p(Q of all | others' fit)`` less ``log N(e; ...)`` of ``name`` (module doc)."""
    rest = data.subset(n for n in data.names if n != name)
    theta = solution.evaluate(data.freq_hz)
    temps, q, var_q = rest.stacked()
    resid = q - model_q(theta, rest.terms(), temps)
    rest_part = -0.5 * np.sum(resid**2 / var_q + np.log(2 * np.pi * var_q))
    x_l = design_terms(data.sources[name].gamma, data.gamma_rec).x_l
    return float(rest_part + np.sum(np.log(np.abs(x_l * theta[INDEX["NS"]]))))


def check_consistency(
    data: CalibrationData,
    solve: Solve,
    alpha: float = DEFAULT_ALPHA,
    offset_sd_k: float = DEFAULT_OFFSET_SD_K,
) -> ConsistencyReport:
    """Hold each calibrator out (with ``solve``) and test it against the others (module doc).

    ``alpha`` is the round's false-alarm rate; ``offset_sd_k`` the prior width of a wrong
    temperature, used only to name the calibrator that explains a disagreement best.
    """
    from scipy import stats

    if not 0 < alpha < 1:
        raise InvalidDataError(f"the false-alarm rate alpha must be in (0, 1), got {alpha}")
    if not offset_sd_k > 0:
        raise InvalidDataError(f"offset_sd_k must be > 0 K, got {offset_sd_k}")
    solutions: dict[tuple[str, ...], AnySolution] = {}

    def capture(subset: CalibrationData) -> AnySolution:
        solution = solve(subset)
        solutions[tuple(subset.names)] = solution
        return solution

    report = leave_one_out(data, capture)
    raw = []
    for held in report.results:
        if held.refused is not None:
            raw.append(CalibratorCheck(held.name, refused=held.refused))
            continue
        others = solutions[tuple(n for n in data.names if n != held.name)]
        fit = held_out_fit(others, data, held.name)
        z = fit.offset_k / fit.offset_std_k
        raw.append(
            CalibratorCheck(
                held.name,
                offset_k=fit.offset_k,
                offset_std_k=fit.offset_std_k,
                z=z,
                chi2_shape=fit.chi2_shape,
                dof_shape=fit.n - 1,
                p_offset=float(2 * stats.norm.sf(abs(z))),
                p_shape=float(stats.chi2.sf(fit.chi2_shape, fit.n - 1)),
                ratio=held.ratio,
                shape_tested=_radiometer_noise(others),
                log_evidence=_log_likelihood(others, data, held.name)
                + fit.log_predictive(offset_sd_k),
            )
        )
    m = max(1, sum(c.refused is None for c in raw))
    p_threshold = alpha / (2 * m)
    checks = tuple(
        c
        if c.refused is not None
        else replace(
            c, flagged=c.p_offset < p_threshold or (c.shape_tested and c.p_shape < p_threshold)
        )
        for c in raw
    )
    return ConsistencyReport(
        checks=checks,
        alpha=alpha,
        z_threshold=float(stats.norm.isf(p_threshold / 2)),
        p_threshold=p_threshold,
        offset_sd_k=offset_sd_k,
        leave_one_out=report,
    )


@dataclass(frozen=True)
class Exclusion:
    """Rounds of :func:`check_consistency`, excluding the named calibrator after each.

    ``rounds[i]`` is the check before the ``i``-th exclusion (the last one that of the
    final set); ``excluded`` in the order they were dropped; ``solution`` that of the final
    set ``calibrators``, or ``None`` with the solver's message in ``refused``; ``stopped``
    why the rounds ended.
    """

    rounds: tuple[ConsistencyReport, ...]
    excluded: tuple[str, ...]
    calibrators: tuple[str, ...]
    solution: AnySolution | None
    stopped: str
    refused: str | None = None

    def lines(self) -> list[str]:
        """Each round's table, the exclusions and why they stopped."""
        out: list[str] = []
        for i, report in enumerate(self.rounds):
            out.append(f"round {i + 1} ({len(report.checks)} calibrators):")
            out += [f"  {line}" for line in report.lines()]
        excluded = ", ".join(self.excluded) or "none"
        out.append(f"excluded: {excluded}; calibrators left: {', '.join(self.calibrators)}")
        out.append(f"stopped: {self.stopped}")
        if self.refused is not None:
            out.append(f"the solve of the calibrators left was refused: {self.refused}")
        return out


def exclude_inconsistent(
    data: CalibrationData,
    solve: Solve,
    alpha: float = DEFAULT_ALPHA,
    max_exclusions: int = 2,
    offset_sd_k: float = DEFAULT_OFFSET_SD_K,
) -> Exclusion:
    """Check, exclude the calibrator named, check again; at most ``max_exclusions`` times.

    Only a checkable calibrator is named, i.e. one the others were solved without, so the
    solver never loses one it needs (e.g. for ``T_NS``). The final set is solved; a refusal
    (:class:`~calibration.core.errors.CalibrationError`) is kept in ``refused``, not raised.
    """
    if max_exclusions < 0:
        raise InvalidDataError(f"max_exclusions must be >= 0, got {max_exclusions}")
    rounds: list[ConsistencyReport] = []
    excluded: list[str] = []
    current = data
    while True:
        report = check_consistency(current, solve, alpha, offset_sd_k)
        rounds.append(report)
        worst = report.worst
        if worst is None:
            stopped = "no calibrator disagrees with the others"
            break
        if len(excluded) >= max_exclusions:
            stopped = (
                f"{worst.name} disagrees but the limit of {max_exclusions} exclusions is reached"
            )
            break
        excluded.append(worst.name)
        current = current.subset(n for n in current.names if n != worst.name)
    solution, refused = None, None
    try:
        solution = solve(current)
    except CalibrationError as err:
        refused = str(err)
    return Exclusion(
        tuple(rounds), tuple(excluded), tuple(current.names), solution, stopped, refused
    )
