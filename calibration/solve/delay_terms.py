"""Structure beyond the polynomial box: found in the binned residuals, held by delay terms.

A reflection along a cable puts a ripple on the noise waves, ``A cos(2 pi nu tau + phi)``
with ``tau`` the cable's round trip (thesis section 3.1: the noise waves seen through a
line rotate with its delay). No polynomial of a few terms holds a ripple of several
periods over the band: the order search runs to its ceiling and, at a 10 MHz period and
1 K, the calibrated error was ~20x the noise floor and 8x its own error bar
(``benchmarks/beyond_box.py``).

1. **Test.** The rows' residuals about the fitted curves, averaged in :data:`N_BINS` bins
   of frequency per calibrator, against the radiometer noise alone (``w`` the rows'
   weights, ``r`` their residuals in K)::

       chi2_bin = sum_{i, b} (sum_{f in b} w_if r_if)^2 / sum_{f in b} w_if

   has ``M B - P`` degrees of freedom under the model (``M`` calibrators, ``B`` bins,
   ``P`` coefficients). Averaging over channels beats the per-channel noise down, so a
   ripple well below it shows. An excess beyond :data:`EXCESS_SIGMA` standard deviations
   (``sqrt(2 dof)``) is structure the model does not hold.
2. **Delays.** Candidates are the peaks of the residuals' periodogram
   (``sum_i |FFT_f(w_i r_i)|^2``, delays above 1.5 / band: slower structure is the
   polynomials' own). For each, with ``K`` polynomial terms, every parameter gets
   ``cos``/``sin(2 pi nu tau)`` (:class:`~calibration.model.basis.DelayBasis`); the evidence of
   that model under the fixed wide prior (eq. 3.35) is set against the best polynomial
   model under the same prior, over ``K``. A delay model is kept only where its evidence
   exceeds the polynomials' by :data:`MIN_GAIN_NATS`; up to :data:`MAX_DELAYS` delays.
   Where the order search ended at its ceiling the delays are tried even if the test
   passes (a slow ripple the polynomials hold only with every term they have).
3. **What remains.** If the test still fails, the posterior's scale is multiplied by
   ``chi2_bin / dof`` (its error bars carry the misfit that remains, spread over the
   band) and a warning says so.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from ..choice.model_fit import OrderChoice, fit
from ..core.errors import IllPosedError
from ..model.basis import DelayBasis, PolynomialBasis
from ..model.noise_waves import INDEX
from ..model.polynomial_model import as_orders
from ..regression.conjugate import CoefficientPrior, LinearPosterior, ScalePrior
from ..regression.normal_equations import build_normal_equations, evaluate_coefficients

FloatArray = NDArray[np.float64]
#: Frequency bins of the residual test.
N_BINS = 64
#: The binned chi-square's excess over its dof, in its sds, that counts as structure.
EXCESS_SIGMA = 5.0
#: Evidence a delay model must gain over the polynomials (nats).
MIN_GAIN_NATS = 10.0
#: Delays at most.
MAX_DELAYS = 2
#: Periodogram peaks tried per delay.
CANDIDATES = 3
#: Polynomial terms tried beside the delays.
POLYNOMIAL_TERMS = tuple(range(3, 13))
#: Gauss-Newton steps about a delay model's curves.
RELINEARISE = 2


@dataclass(frozen=True)
class Rows:
    """Gauss-Newton rows: features ``(M, N, 5)``, weights and response ``(M, N)``.

    ``offset_variance`` ``(M,)``: each calibrator's declared temperature variance (K^2),
    an offset shared by all its channels (``SourceData.temperature_std_k``), or None.
    ``shared_k2`` ``(M, N)``: the part of each row's variance from the reflections'
    errors (K^2), correlated over ``correlation`` neighbouring channels (a VNA sweep
    point's error splined over them, :mod:`calibration.solve.correlated_reflections`).
    """

    features: FloatArray
    weights: FloatArray
    response: FloatArray
    offset_variance: FloatArray | None = None
    shared_k2: FloatArray | None = None
    correlation: float = 1.0


def binned_chi2(rows: Rows, theta: FloatArray, n_coefficients: int) -> tuple[float, float]:
    """The binned residual chi-square of the module docstring and its dof.

    Each bin's weighted residual sum ``u_b = sum_i w_i r_i`` has variance
    ``V_b = sum w + (c - 1) sum w^2 e`` where the rows' reflection share ``e`` of their
    variance is correlated over ``c`` channels (``V_b = sum w`` for independent rows). A
    calibrator's declared temperature offset (variance ``v``) adds ``v W W^T`` with
    ``W_b = sum w``; the inverse is Sherman-Morrison's::

        chi2 = sum u^2/V - v (sum u W/V)^2 / (1 + v sum W^2/V)
    """
    residual = rows.response - np.einsum("mnk,kn->mn", rows.features, theta)
    n = residual.shape[1]
    starts = np.linspace(0, n, min(N_BINS, n) + 1).astype(int)[:-1]
    num = np.add.reduceat(rows.weights * residual, starts, axis=1)
    den = np.add.reduceat(rows.weights, starts, axis=1)
    var = den.copy()
    if rows.shared_k2 is not None and rows.correlation > 1.0:
        var += (rows.correlation - 1.0) * np.add.reduceat(
            rows.weights**2 * rows.shared_k2, starts, axis=1
        )
    dof = max(float(num.size - n_coefficients), 1.0)
    chi2 = float(np.sum(num**2 / var))
    if rows.offset_variance is not None:
        v = np.asarray(rows.offset_variance, dtype=float)
        shared = np.sum(num * den / var, axis=1)
        chi2 -= float(np.sum(v * shared**2 / (1.0 + v * np.sum(den**2 / var, axis=1))))
    return chi2, dof


def excess(chi2: float, dof: float) -> bool:
    """Whether the binned chi-square exceeds its dof by :data:`EXCESS_SIGMA` sds."""
    return chi2 - dof > EXCESS_SIGMA * np.sqrt(2.0 * dof)


def candidate_delays(
    rows: Rows, theta: FloatArray, freq_hz: FloatArray, exclude: tuple[float, ...] = ()
) -> list[float]:
    """Delays (s) of the residuals' largest periodogram peaks (module docstring)."""
    residual = rows.response - np.einsum("mnk,kn->mn", rows.features, theta)
    u = rows.weights * residual
    u = u / np.sqrt(np.sum(rows.weights, axis=1, keepdims=True))
    n = u.shape[1]
    pad = 8 * n
    power = np.sum(np.abs(np.fft.rfft(u, n=pad, axis=1)) ** 2, axis=0)
    step = float(np.median(np.diff(freq_hz)))
    delays = np.fft.rfftfreq(pad, d=step)
    band = float(freq_hz[-1] - freq_hz[0])
    resolution = 1.0 / band
    power[delays < 1.5 * resolution] = 0.0
    for d in exclude:
        power[np.abs(delays - d) < resolution] = 0.0
    found: list[float] = []
    for _ in range(CANDIDATES):
        k = int(np.argmax(power))
        if power[k] <= 0:
            break
        found.append(float(delays[k]))
        power[np.abs(delays - delays[k]) < resolution] = 0.0
    return found


@dataclass
class DelayModel:
    """A fitted model: its basis, orders, posterior and log evidence."""

    basis: PolynomialBasis
    posterior: LinearPosterior
    log_evidence: float
    history: list[str] = field(default_factory=list)

    def curves(self, freq_hz: FloatArray) -> FloatArray:
        """Posterior-mean parameter curves ``(5, N)``."""
        b = self.basis.matrix(freq_hz, max(self.posterior.orders))
        return evaluate_coefficients(self.posterior.mean, b, self.posterior.orders)


def _fit_model(
    rows: Rows, freq_hz: FloatArray, basis: PolynomialBasis, n_terms: int,
    scale_prior: ScalePrior | None,
) -> DelayModel | None:
    orders = as_orders((n_terms,) * 5)
    prior = CoefficientPrior()
    b = basis.matrix(freq_hz, n_terms)
    normal = build_normal_equations(
        rows.features, rows.weights, rows.response, b, orders,
        ridge=1.0 / prior.vectors(orders)[1],
    )
    try:
        post, _ = fit(normal, OrderChoice.fixed(orders), prior, 1.0, scale_prior, True,
                      average=False)
    except (IllPosedError, np.linalg.LinAlgError):
        return None
    return DelayModel(basis, post, float(post.log_evidence))


def _with_delays(
    rows: Rows, freq_hz: FloatArray, poly: PolynomialBasis, delays: tuple[float, ...],
    k: int, scale_prior: ScalePrior | None,
) -> DelayModel | None:
    if not delays:
        return _fit_model(rows, freq_hz, poly, k, scale_prior)
    basis = DelayBasis(poly.kind, poly.f_lo_hz, poly.f_hi_hz, k, delays)
    return _fit_model(rows, freq_hz, basis, k + 2 * len(delays), scale_prior)


def best_model(
    rows: Rows, freq_hz: FloatArray, poly: PolynomialBasis, delays: tuple[float, ...],
    scale_prior: ScalePrior | None,
) -> DelayModel | None:
    """The best model over :data:`POLYNOMIAL_TERMS` (with ``delays``, or none).

    With delays, the last one is then refined by the evidence at that number of
    polynomial terms, within a quarter of the band's delay resolution of where it was
    (the periodogram's grid is an eighth of it: a delay off by that leaves a ripple of a
    few per cent of its amplitude, far above the noise of a long integration).
    """
    best: DelayModel | None = None
    for k in POLYNOMIAL_TERMS:
        model = _with_delays(rows, freq_hz, poly, delays, k, scale_prior)
        if model is not None and (best is None or model.log_evidence > best.log_evidence):
            best = model
    if best is None or not delays:
        return best
    k = best.basis.polynomial_terms if isinstance(best.basis, DelayBasis) else 0
    tau = delays[-1]
    span = 0.25 / float(freq_hz[-1] - freq_hz[0])

    def cost(t: float) -> float:
        model = _with_delays(rows, freq_hz, poly, (*delays[:-1], t), k, scale_prior)
        return np.inf if model is None else -model.log_evidence

    found = minimize_scalar(
        cost, bounds=(max(tau - span, 1e-12), tau + span), method="bounded",
        options={"xatol": 1e-4 * span},
    )
    refined = _with_delays(rows, freq_hz, poly, (*delays[:-1], float(found.x)), k, scale_prior)
    if refined is not None and refined.log_evidence > best.log_evidence:
        return refined
    return best


@dataclass
class Extension:
    """What the search beyond the box found: a model (or none) and what to say."""

    model: DelayModel | None
    chi2_before: float
    dof_before: float
    chi2_after: float
    dof_after: float
    inflation: float = 1.0
    metadata: dict[str, object] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def extend(
    rows: Rows,
    theta: FloatArray,
    n_coefficients: int,
    freq_hz: FloatArray,
    poly: PolynomialBasis,
    scale_prior: ScalePrior | None,
    relinearise: Callable[[FloatArray], Rows],
    search: bool = True,
    at_ceiling: bool = False,
    noise_scale: float = 1.0,
) -> Extension | None:
    """Test the fit of ``theta`` and, where it fails, look beyond the box (docstring).

    ``None`` where the binned residuals are consistent with the radiometer noise.
    ``relinearise(theta)`` gives the Gauss-Newton rows about new curves. Without
    ``search`` (orders the user fixed) no delay is tried: the misfit is only carried.
    ``at_ceiling`` (the search ended at its order ceiling) tries delays even where the
    test passes: the polynomials may be holding a slow ripple at the cost of their terms.
    ``noise_scale`` is the fitted ``s^2`` of the posterior ``theta`` is the mean of: its
    covariance already carries that much misfit, so only the binned excess beyond it
    widens the error bars (else a misfit spread evenly over the channels, which ``s^2``
    measures, would be counted twice).
    """
    chi2, dof = binned_chi2(rows, theta, n_coefficients)
    if not excess(chi2, dof) and not (search and at_ceiling):
        return None
    reference = best_model(rows, freq_hz, poly, (), scale_prior) if search else None
    kept: DelayModel | None = None
    delays: tuple[float, ...] = ()
    current_rows, current_theta = rows, theta
    gains: list[float] = []
    for _ in range(MAX_DELAYS if search else 0):
        tried = []
        for tau in candidate_delays(current_rows, current_theta, freq_hz, delays):
            model = best_model(current_rows, freq_hz, poly, (*delays, tau), scale_prior)
            # A model taking T_NS through zero has no operating point to relinearise about.
            if model is not None and np.all(model.curves(freq_hz)[INDEX["NS"]] > 0):
                tried.append(model)
        if not tried:
            break
        model = max(tried, key=lambda m: m.log_evidence)
        base = kept if kept is not None else reference
        base_z = base.log_evidence if base is not None else -np.inf
        if model.log_evidence - base_z < MIN_GAIN_NATS:
            break
        gains.append(model.log_evidence - base_z)
        for _ in range(RELINEARISE):  # about the new curves, then refit there
            if not np.all(model.curves(freq_hz)[INDEX["NS"]] > 0):
                break
            current_theta = model.curves(freq_hz)
            current_rows = relinearise(current_theta)
            refit = _fit_model(
                current_rows, freq_hz, model.basis, max(model.posterior.orders), scale_prior
            )
            if refit is None:
                break
            model = refit
        if not np.all(model.curves(freq_hz)[INDEX["NS"]] > 0):
            break  # the refit took T_NS through zero: keep what was found before it
        kept, current_theta = model, model.curves(freq_hz)
        assert isinstance(model.basis, DelayBasis)
        delays = model.basis.delays_s
        chi2_now, dof_now = binned_chi2(current_rows, current_theta, model.posterior.mean.size)
        if not excess(chi2_now, dof_now):
            break
    if kept is None and not excess(chi2, dof):
        return None
    if kept is None:
        ext = Extension(None, chi2, dof, chi2, dof)
    else:
        after, dof_after = binned_chi2(current_rows, current_theta, kept.posterior.mean.size)
        ext = Extension(kept, chi2, dof, after, dof_after)
        assert isinstance(kept.basis, DelayBasis)
        periods = ", ".join(f"{1e-6 / d:.3g}" for d in kept.basis.delays_s)
        ext.metadata["delay_terms"] = {
            "delays_ns": [round(1e9 * d, 3) for d in kept.basis.delays_s],
            "polynomial_terms": kept.basis.polynomial_terms,
            "log_evidence_gain": [round(g, 2) for g in gains],
        }
        ext.warnings.append(
            f"the calibrators hold structure no polynomial of the box holds (binned residual "
            f"chi2/dof {chi2 / dof:.2f}): a ripple of period {periods} MHz on the noise "
            f"waves, now modelled by delay terms (evidence +{sum(gains):.0f} nats); a cable "
            "reflection is the usual cause"
        )
    ext.metadata["binned_chi2_per_dof"] = {
        "polynomials": round(chi2 / dof, 4), "final": round(ext.chi2_after / ext.dof_after, 4),
    }
    s2 = float(kept.posterior.noise_variance) if kept is not None else noise_scale
    if excess(ext.chi2_after / s2, ext.dof_after):
        ext.inflation = ext.chi2_after / ext.dof_after / s2
        ext.metadata["misfit_inflation"] = round(ext.inflation, 4)
        ext.warnings.append(
            f"structure beyond the model remains in the binned residuals (chi2/dof "
            f"{ext.chi2_after / ext.dof_after:.2f} against the radiometer noise, "
            f"{ext.inflation:.2f}x what the fitted noise scale s^2 = {s2:.3g} carries): the "
            f"error bars are widened {np.sqrt(ext.inflation):.2f}x more to carry it, but its "
            "shape in frequency is not modelled; check the calibrators' reflections and cables"
        )
    return ext


def inflated(posterior: LinearPosterior, factor: float) -> LinearPosterior:
    """``posterior`` with its scale (and so its covariance) multiplied by ``factor``."""
    from ..choice.averaging import MixturePosterior, mixture_of

    if isinstance(posterior, MixturePosterior):
        parts = [inflated(p, factor) for p in posterior.components]
        return mixture_of(parts, posterior.weights, posterior.log_evidence, posterior.n_rows)
    return replace(posterior, scale=posterior.scale * factor)
