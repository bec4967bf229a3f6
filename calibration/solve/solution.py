"""A calibration solution: noise-wave polynomials with their posterior, applied to sources.

Calibrating a source inverts nothing: eq. 3.27 gives its temperature directly from its
measured ``Q``, reflection coefficient and the parameters,
``T_src(f) = x_src(f)^T c`` with ``x_src`` the source's design row (eqs. 3.22-3.26, 3.40).
The predictive distribution of ``T_src`` (eq. 3.41) has two independent parts:

* the calibration error ``x^T Cov(c) x``, correlated across channels, shared by every
  source calibrated with this solution (Student-t with the posterior's dof, eq. 3.42);
* the source's own measurement noise: for the radiometric solver
  ``(X_L T_NS)^2 s^2 var(Q_src)`` per channel from the radiometer equation; for the thesis
  solver its homoscedastic ``sigma^2 = b*/a*`` (eq. 4.3); plus, when the source's
  reflection error is known, its effect on the calibrated temperature
  (:mod:`calibration.model.reflection_noise`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from functools import cache, partial
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from ..choice.averaging import MixturePosterior
from ..choice.mixture_interval import ChannelMixture, central_interval, channel_mixture
from ..core.errors import InvalidDataError
from ..model.basis import PolynomialBasis
from ..model.data import SourceData, check_source
from ..model.noise_waves import INDEX, PARAMETERS, design_terms
from ..model.polynomial_model import Orders, PolynomialParameters, coefficient_slices, design_rows
from ..model.reflection_noise import reflection_variance
from ..regression.conjugate import LinearPosterior

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
MeasurementModel = Literal["radiometer", "homoscedastic"]


@dataclass(frozen=True)
class CalibratedSpectrum:
    """Calibrated temperature of a source with its predictive uncertainty (K).

    ``std_calibration`` is the solution's error (correlated across channels for a
    polynomial solution); ``std_measurement`` the source's own noise (independent per
    channel). ``rows`` are the source's design rows (``mean = rows @ parameters``) and
    ``draw_calibration(n, rng)`` draws ``n`` calibrated spectra from the solution's
    posterior alone: every solver (polynomial or per channel) supplies its own.
    ``systematic``, when attached (:meth:`with_systematics`), holds Monte-Carlo draws
    ``(K, n_channels)`` of the VNA's data-sheet error on this spectrum
    (:mod:`calibration.checks.vna_systematics`): deviations from this spectrum, correlated
    across channels, part of every interval and sample, their RMS ``std_systematic``.
    ``mixture``, for a model-averaged solution, gives the calibration error's components
    per channel (:mod:`calibration.choice.mixture_interval`), so that intervals are the
    mixture's quantiles; computed when an interval is asked for. ``std_radiometer`` is the
    radiometer part of ``std_measurement``, without the reflections' random errors (which a
    run's spectra share through the same S11 sweeps, while the radiometer noise of each
    spectrum is its own); None where the solver does not separate them.
    """

    freq_hz: FloatArray
    mean: FloatArray
    std_calibration: FloatArray
    std_measurement: FloatArray
    dof: float
    rows: FloatArray = field(repr=False)
    draw_calibration: Callable[[int, np.random.Generator], FloatArray] = field(repr=False)
    systematic: FloatArray | None = field(default=None, repr=False)
    mixture: Callable[[], ChannelMixture] | None = field(default=None, repr=False)
    std_radiometer: FloatArray | None = field(default=None, repr=False)

    def with_systematics(self, deviations: FloatArray) -> CalibratedSpectrum:
        """A copy with the VNA systematic error's draws ``(K, n_channels)`` attached."""
        dev = np.asarray(deviations, dtype=float)
        if dev.ndim != 2 or dev.shape[1] != self.freq_hz.size or dev.shape[0] < 2:
            raise InvalidDataError(
                f"systematic draws must be (K >= 2, {self.freq_hz.size}); got {dev.shape}"
            )
        return replace(self, systematic=dev)

    @property
    def std_systematic(self) -> FloatArray:
        """RMS of the attached systematic draws about this spectrum (zero when none)."""
        if self.systematic is None:
            return np.zeros(self.freq_hz.shape)
        return np.asarray(np.sqrt(np.mean(self.systematic**2, axis=0)))

    @property
    def std(self) -> FloatArray:
        """Total predictive standard deviation per channel."""
        return np.sqrt(self.std_calibration**2 + self.std_measurement**2 + self.std_systematic**2)

    @property
    def std_model_choice(self) -> FloatArray:
        """The part of ``std_calibration`` that is the choice of model, per channel (K).

        The spread of the averaged models' spectra about their mean
        (:meth:`ChannelMixture.between_variance
        <calibration.choice.mixture_interval.ChannelMixture.between_variance>`), whose square
        with the models' own variances makes ``std_calibration**2``; 0 for one model.
        """
        if self.mixture is None:
            return np.zeros_like(self.mean)
        return np.sqrt(self.mixture().between_variance())

    @property
    def model_choice_share(self) -> float:
        """The share of the calibration variance that is the choice of model.

        :attr:`std_model_choice` squared over ``std_calibration`` squared, summed over
        channels.
        """
        total = float(np.sum(self.std_calibration**2))
        if total == 0.0:
            return 0.0
        return min(float(np.sum(self.std_model_choice**2)) / total, 1.0)

    def interval(
        self, level: float = 0.68, calibration_only: bool = False
    ) -> tuple[FloatArray, FloatArray]:
        """Central credible interval at ``level`` per channel.

        ``calibration_only`` leaves out the source's own measurement noise (it keeps the
        attached systematic error, an error of the calibration chain). For a
        model-averaged solution, the quantiles of the mixture over models
        (:mod:`calibration.choice.mixture_interval`), the other errors joining each component;
        otherwise that of the one Student-t whose variance is the total.
        """
        if self.mixture is not None:
            mixture = self.mixture()
        else:  # one Student-t: the mixture of one component, the same quantile rule
            mixture = ChannelMixture(
                np.ones(1), self.mean[None, :], self.std_calibration[None, :] ** 2,
                np.array([self.dof], dtype=float),
            )
        extra = self.std_systematic**2
        if not calibration_only:
            extra = extra + self.std_measurement**2
        return central_interval(mixture, extra, level)

    def intervals(self, levels: tuple[float, ...] = (0.68, 0.95)) -> dict[str, FloatArray]:
        """The full predictive's intervals by name: ``lower_68``, ``upper_68``, ... (K).

        What files store beside the stds (:meth:`interval`; for an averaged solution the
        mixture's quantiles, which the stds do not give).
        """
        out = {}
        for level in levels:
            percent = f"{100 * level:g}"
            out[f"lower_{percent}"], out[f"upper_{percent}"] = self.interval(level)
        return out

    def covers(
        self, truth: FloatArray, level: float = 0.68, calibration_only: bool = False
    ) -> NDArray[np.bool_]:
        """Per channel, whether :meth:`interval` at ``level`` holds ``truth`` (K)."""
        lo, hi = self.interval(level, calibration_only)
        return np.asarray((lo <= truth) & (truth <= hi))

    def samples(
        self, n: int, rng: np.random.Generator, calibration_only: bool = False
    ) -> FloatArray:
        """``n`` draws of the calibrated spectrum, shape ``(n, n_channels)``."""
        draws = self.draw_calibration(n, rng)
        if self.systematic is not None:
            draws = draws + self.systematic[rng.integers(self.systematic.shape[0], size=n)]
        if not calibration_only:
            draws = draws + rng.standard_normal(draws.shape) * self.std_measurement
        return np.asarray(draws)


@dataclass(frozen=True)
class Solution:
    """Noise-wave parameters as polynomials with their posterior.

    Attributes
    ----------
    method
        ``"radiometric"`` (the default solver) or ``"thesis"`` (EXCALIBRATE).
    basis
        The polynomial basis the coefficients refer to.
    posterior
        Posterior of the concatenated coefficients (orders in ``posterior.orders``).
    measurement_model
        How a calibrated source's own noise is predicted (module docstring).
    evidence_table
        Log evidence of every model the order search evaluated.
    calibrators
        Names of the calibrators used.
    """

    method: str
    basis: PolynomialBasis
    posterior: LinearPosterior
    measurement_model: MeasurementModel
    evidence_table: Mapping[Orders, float] = field(default_factory=dict)
    calibrators: tuple[str, ...] = ()
    metadata: Mapping[str, Any] = field(default_factory=dict)

    @property
    def orders(self) -> Orders:
        """Number of polynomial terms of each parameter in the posterior's layout.

        For a model-averaged posterior this is the envelope of the models mixed; the
        evidence's own choice is :attr:`best_orders`.
        """
        return self.posterior.orders

    @property
    def best_orders(self) -> Orders:
        """The evidence-best model's orders (the layout's when none is recorded)."""
        best = self.metadata.get("best_orders")
        return self.orders if best is None else tuple(int(n) for n in best)  # type: ignore[return-value]

    @property
    def orders_used(self) -> Orders:
        """The orders of the model that carries the most weight: the model used.

        ``metadata["orders_used"]`` where the solver recorded it, else the heaviest of
        ``metadata["model_weights"]`` (an averaged solution), else :attr:`best_orders`.
        The evidence-best single model need not be it: the smooth-function hypothesis
        (every term to the box's edge) can carry the average with a lower evidence. With
        delay terms (:class:`~calibration.model.basis.DelayBasis`) the posterior's own orders:
        the one model fitted after the polynomial search.
        """
        if getattr(self.basis, "delays_s", ()):  # delay terms joined after the search
            return self.orders
        used = self.metadata.get("orders_used")
        if used is None:
            weights = self.metadata.get("model_weights") or []
            if self.metadata.get("averaged") and weights:
                used = max(weights, key=lambda w: float(w["weight"]))["orders"]
        if used is None:
            return self.best_orders
        return tuple(int(n) for n in used)  # type: ignore[return-value]

    def models_line(self, limit: int = 4) -> str:
        """The leading models and their weights, for a summary (empty if not averaged)."""
        weights = self.metadata.get("model_weights") or []
        if not self.metadata.get("averaged") or len(weights) < 2:
            return ""
        return ", ".join(
            f"({','.join(map(str, w['orders']))}) {w['weight']:.3f}" for w in weights[:limit]
        )

    @property
    def parameters(self) -> PolynomialParameters:
        """Posterior-mean coefficients as evaluable polynomials."""
        return PolynomialParameters(self.basis, self.orders, self.posterior.mean)

    def evaluate(self, freq_hz: FloatArray) -> FloatArray:
        """Posterior-mean parameters ``(5, n_channels)`` in K."""
        return self.parameters.evaluate(freq_hz)

    def parameter_std(self, freq_hz: FloatArray) -> FloatArray:
        """Posterior standard deviation of each parameter ``(5, n_channels)``."""
        b = self.basis.matrix(np.asarray(freq_hz, dtype=float), max(self.orders))
        cov = self.posterior.covariance
        out = []
        for s in coefficient_slices(self.orders):
            bs = b[:, : s.stop - s.start]
            out.append(np.sqrt(np.sum((bs @ cov[s, s]) * bs, axis=1)))
        return np.stack(out)

    def sample_parameters(
        self, freq_hz: FloatArray, n: int, rng: np.random.Generator
    ) -> FloatArray:
        """``n`` posterior draws of the parameters, ``(n, 5, n_channels)``."""
        draws = self.posterior.sample(n, rng)
        return PolynomialParameters(self.basis, self.orders, draws).evaluate(freq_hz)

    def design_rows(
        self, freq_hz: FloatArray, gamma_rec: ComplexArray, gamma: ComplexArray, q: FloatArray
    ) -> FloatArray:
        """Design rows ``(n_channels, P)`` of a source: ``T_src = rows @ c``."""
        terms = design_terms(gamma, gamma_rec)
        basis = self.basis.matrix(np.asarray(freq_hz, dtype=float), max(self.orders))
        return design_rows(terms.matrix(q), basis, self.orders)

    def calibrate(
        self,
        freq_hz: FloatArray,
        gamma_rec: ComplexArray,
        source: SourceData,
        channel_width_hz: float | None = None,
        gamma_rec_std: FloatArray | float | None = None,
    ) -> CalibratedSpectrum:
        """Calibrate ``source`` (eq. 3.27) with its predictive uncertainty.

        ``channel_width_hz`` is needed for the radiometer measurement noise; without it
        only the calibration error is reported for the radiometric solver.
        ``gamma_rec_std`` (the run's :attr:`CalibrationData.gamma_rec_std`) and the
        source's own ``gamma_std`` add the VNA's random errors to the measurement part
        (:mod:`calibration.model.reflection_noise`).
        """
        freq = np.asarray(freq_hz, dtype=float)
        source = check_source(source, freq.size)
        gamma_rec = np.asarray(gamma_rec, dtype=complex)
        if gamma_rec.shape != freq.shape:
            raise InvalidDataError(
                "receiver reflection does not match the frequencies", source.name
            )
        rows = self.design_rows(freq, gamma_rec, source.gamma, source.q)
        post = self.posterior
        mean = rows @ post.mean
        std_cal = np.sqrt(np.maximum(np.sum((rows @ post.covariance) * rows, axis=1), 0.0))
        if self.measurement_model == "homoscedastic":
            std_meas = np.full(freq.shape, np.sqrt(post.noise_variance))
        elif channel_width_hz is None:
            std_meas = np.zeros(freq.shape)
        else:
            terms = design_terms(source.gamma, gamma_rec)
            t_ns = self.evaluate(freq)[INDEX["NS"]]
            var_q = source.q_variance(channel_width_hz)
            std_meas = np.abs(terms.x_l * t_ns) * np.sqrt(post.noise_variance * var_q)
        radiometer = std_meas
        if source.gamma_std is not None or gamma_rec_std is not None:
            var_gamma = reflection_variance(
                self.evaluate(freq), source.gamma, gamma_rec, source.q, source.gamma_std,
                gamma_rec_std,
            )
            std_meas = np.sqrt(std_meas**2 + var_gamma)
        mixture = None
        if isinstance(post, MixturePosterior) and len(post.components) > 1:
            mixture = cache(partial(channel_mixture, post, rows))  # once, for every interval
        return CalibratedSpectrum(
            freq,
            mean,
            std_cal,
            std_meas,
            post.dof,
            rows,
            lambda n, rng: np.asarray(post.sample(n, rng) @ rows.T),
            mixture=mixture,
            std_radiometer=radiometer,
        )

    def summary(self) -> dict[str, Any]:
        """Plain-data summary: orders, evidence, noise scale, coefficients."""
        post = self.posterior
        return {
            "method": self.method,
            "basis": self.basis.kind,
            "band_hz": [self.basis.f_lo_hz, self.basis.f_hi_hz],
            "orders": dict(zip(PARAMETERS, self.orders, strict=True)),
            "log_evidence": post.log_evidence,
            "noise_variance": post.noise_variance,
            "chi2_per_row": post.chi2 / post.n_rows,
            "calibrators": list(self.calibrators),
            "models_evaluated": len(self.evidence_table),
        }


# ------------------------------------------------------------------ checks of a solution read
#: The most polynomial terms a solution file may give one parameter: four times the order
#: search's ceiling (16); more is a corrupt file, not a model.
MAX_FILE_ORDER = 64


def posterior_problems(post: LinearPosterior) -> list[str]:
    """What makes a posterior read from a file unusable (empty when it is sound).

    ``dof`` may be ``inf`` (a Gaussian posterior); every other number must be finite, the
    noise variance and ``dof`` positive, and ``scale`` symmetric with a non-negative
    diagonal: otherwise every calibrated spectrum is NaN, or its error bars meaningless.
    """
    problems = []
    if not np.all(np.isfinite(post.mean)):
        problems.append("mean is not finite")
    scale = post.scale
    if not np.all(np.isfinite(scale)):
        problems.append("scale is not finite")
    elif np.any(np.diag(scale) < 0) or not np.allclose(scale, scale.T, rtol=1e-8, atol=0):
        problems.append("scale is not a covariance (asymmetric, or a negative variance)")
    if np.isnan(post.dof) or post.dof <= 0:
        problems.append(f"dof {post.dof} is not > 0")
    if not (np.isfinite(post.noise_variance) and post.noise_variance > 0):
        problems.append(f"noise_variance {post.noise_variance} is not a finite number > 0")
    if not (np.isfinite(post.log_evidence) and np.isfinite(post.chi2) and post.chi2 >= 0):
        problems.append("log_evidence or chi2 is not finite (or chi2 < 0)")
    if post.n_rows < 1:
        problems.append(f"n_rows {post.n_rows} is not >= 1")
    return problems


def _is_orders(value: object) -> bool:
    return (
        isinstance(value, list) and len(value) == len(PARAMETERS)
        and all(type(v) is int and 0 <= v <= MAX_FILE_ORDER for v in value)
    )


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _is_weights(value: object) -> bool:
    return isinstance(value, list) and all(
        isinstance(w, dict) and _is_orders(w.get("orders")) and _is_number(w.get("weight"))
        for w in value
    )


def _is_cuts(value: object) -> bool:
    return isinstance(value, list) and all(
        isinstance(c, dict) and isinstance(c.get("why"), str)
        and _is_orders(c.get("asked")) and _is_orders(c.get("kept"))
        for c in value
    )


#: The metadata entries the commands read, and what each must be when present.
_METADATA_RULES: dict[str, tuple[Callable[[object], bool], str]] = {
    "best_orders": (_is_orders, f"{len(PARAMETERS)} integers 0-{MAX_FILE_ORDER}"),
    "orders_used": (_is_orders, f"{len(PARAMETERS)} integers 0-{MAX_FILE_ORDER}"),
    "orders_used_weight": (_is_number, "a number"),
    "mean_coefficients": (_is_number, "a number"),
    "warnings": (
        lambda v: isinstance(v, list) and all(isinstance(n, str) for n in v), "a list of text"
    ),
    "order_limits": (_is_orders, f"{len(PARAMETERS)} integers 0-{MAX_FILE_ORDER}"),
    "model_weights": (_is_weights, "a list of {orders, weight}"),
    "averaged": (lambda v: isinstance(v, bool), "true or false"),
    "orders_at_ceiling": (
        lambda v: isinstance(v, list) and all(isinstance(n, str) for n in v), "a list of names"
    ),
    "prior_dominated": (
        lambda v: isinstance(v, dict) and all(_is_number(r) for r in v.values()),
        "a mapping of parameters to numbers",
    ),
    "order_box_cuts": (_is_cuts, "a list of {why, asked, kept}"),
    "reflection_errors_uncorrected": (_is_number, "a number"),
    "channel_width_hz": (lambda v: _is_number(v) and float(v) > 0, "a width > 0"),  # type: ignore[arg-type]
    "grid_origin_hz": (_is_number, "a frequency"),
}


def metadata_problems(metadata: Mapping[str, Any]) -> list[str]:
    """What is wrong with the metadata entries a solution's readers use (empty: none)."""
    return [
        f"{key} must be {what}, not {metadata[key]!r}"[:200]
        for key, (good, what) in _METADATA_RULES.items()
        if metadata.get(key) is not None and not good(metadata[key])
    ]


def grid_metadata(freq_hz: FloatArray, channel_width_hz: float) -> dict[str, float]:
    """The channel grid a solution was solved on, for its metadata (:func:`check_grid`)."""
    return {"channel_width_hz": float(channel_width_hz), "grid_origin_hz": float(freq_hz[0])}


def check_grid(
    metadata: Mapping[str, Any], freq_hz: FloatArray, channel_width_hz: float, run: str
) -> None:
    """Refuse to calibrate a run on another channel grid than the solution's.

    The noise waves and the noise scale are fitted to spectra of one channel width (the
    spectrometer's channelisation smooths the reflections' ripple and sets the radiometer
    noise): a run of wider or shifted channels is another receiver setting, and calibrated
    with this solution would be silently wrong. Solutions without a recorded grid (made
    before it was recorded, or by the receiver's own calibrate step) are not checked.
    """
    width, origin = metadata.get("channel_width_hz"), metadata.get("grid_origin_hz")
    if width is None or origin is None:
        return
    width, origin = float(width), float(origin)
    if not np.isclose(channel_width_hz, width, rtol=1e-6, atol=0):
        raise InvalidDataError(
            f"{run} has channels {channel_width_hz:g} Hz wide; the solution was solved on "
            f"{width:g} Hz channels: solve this run's grid, or calibrate a run of that grid"
        )
    freq = np.asarray(freq_hz, dtype=float)
    # The grid's step is the channels' spacing, which an import's width (EDGES': the noise
    # bandwidth of its smoothing, 1.5 channels) need not equal.
    spacing = width
    if freq.size > 1:  # the median step, refined over the band (EDGES' are rounded to 1 Hz)
        k = np.round((freq - freq[0]) / float(np.median(np.diff(freq))))
        spacing = float(np.dot(k, freq - freq[0]) / np.dot(k, k)) if k[-1] > 0 else width
    steps = (freq - origin) / spacing
    if np.max(np.abs(steps - np.round(steps)), initial=0.0) > 1e-3:
        raise InvalidDataError(
            f"{run}'s channels are offset from the solution's channel grid "
            f"({origin:.6g} Hz + k x {spacing:g} Hz): another spectrometer setting"
        )
