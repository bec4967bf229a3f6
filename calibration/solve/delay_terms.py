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
2. **Delays.** Candidates are the peaks of periodograms (delays above 1.5 / band: slower
   structure is the polynomials' own) of the residuals of the search's fit and of a fit
   at the box's starting size (:data:`START_TERMS`: a box grown to 16 terms holds part
   of a ripple of a few periods, and its residuals then point elsewhere): the rows'
   (``sum_i |FFT_f(w_i r_i)|^2``) and the noise waves' own, solved channel by channel
   (:func:`parameter_candidates`; the rows' are turned by each calibrator's cable). For
   each, with ``K`` polynomial terms, every parameter gets ``cos``/``sin(2 pi nu tau)``
   (:class:`~calibration.model.basis.DelayBasis`); the evidence of that model under the
   fixed wide prior (eq. 3.35) is set against the best polynomial model under the same
   prior, over ``K``. The best candidate's delay is refined by the evidence and ``K``
   chosen again there (:func:`refined`). A delay model is kept only where its evidence
   exceeds the polynomials' by :data:`MIN_GAIN_NATS`; up to :data:`MAX_DELAYS` delays.
   Where the order search ended at its ceiling the delays are tried even if the test
   passes (a slow ripple the polynomials hold only with every term they have). The
   delay's own uncertainty is carried into the posterior (:func:`marginal_model`).
3. **What remains.** If the test still fails, the posterior's scale is multiplied by
   ``chi2_bin / dof`` beyond the fitted ``s^2`` (its error bars carry the misfit that
   remains, spread over the band) and a warning says so.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from ..choice.model_fit import OrderChoice, fit
from ..core.errors import IllPosedError
from ..model.basis import DelayBasis, PolynomialBasis
from ..model.noise_waves import INDEX
from ..model.polynomial_model import Orders, as_orders, coefficient_slices
from ..regression.conjugate import CoefficientPrior, LinearPosterior, ScalePrior
from ..regression.normal_equations import build_normal_equations, evaluate_coefficients
from .delay_candidates import candidate_delays, parameter_candidates, union

FloatArray = NDArray[np.float64]
#: Frequency bins of the residual test.
N_BINS = 64
#: The binned chi-square's excess over its dof, in its sds, that counts as structure.
EXCESS_SIGMA = 5.0
#: Evidence a delay model must gain over the polynomials (nats).
MIN_GAIN_NATS = 10.0
#: Delays at most.
MAX_DELAYS = 2
#: Polynomial terms tried beside the delays.
POLYNOMIAL_TERMS = tuple(range(3, 13))
#: Polynomial terms of the fit whose residuals also propose delays: the automatic box's
#: start (``model_fit.DEFAULT_MAX_ORDERS``), before its growth absorbs part of a ripple.
START_TERMS = 8
#: A parameter's ripple is measured where a delay term is this many sd from zero.
MEASURED_SIGMAS = 3.0
#: Rounds of a delay's refinement and its polynomial terms' choice (:func:`refined`).
REFINE_ROUNDS = 4
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
    scale_prior: ScalePrior | None, orders: Orders | None = None,
) -> DelayModel | None:
    """The model of ``n_terms`` a parameter (or ``orders``) under the fixed wide prior."""
    orders = as_orders((n_terms,) * 5) if orders is None else orders
    prior = CoefficientPrior()
    b = basis.matrix(freq_hz, max(orders))
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
    scale_prior: ScalePrior | None, refine: bool = True,
) -> DelayModel | None:
    """The best model over :data:`POLYNOMIAL_TERMS` (with ``delays``, or none).

    With delays and ``refine``, the last one is then refined by the evidence
    (:func:`refined`).
    """
    best: DelayModel | None = None
    for k in POLYNOMIAL_TERMS:
        model = _with_delays(rows, freq_hz, poly, delays, k, scale_prior)
        if model is not None and (best is None or model.log_evidence > best.log_evidence):
            best = model
    if best is None or not delays or not refine:
        return best
    return refined(rows, freq_hz, poly, best, scale_prior)


def refined(
    rows: Rows, freq_hz: FloatArray, poly: PolynomialBasis, model: DelayModel,
    scale_prior: ScalePrior | None,
) -> DelayModel:
    """``model``'s last delay refined by the evidence, then its polynomial terms again.

    At the model's number of polynomial terms, within a quarter of the band's delay
    resolution of where it was (the periodogram's grid is an eighth of it: a delay off by
    that leaves a ripple of a few per cent of its amplitude, far above the noise of a long
    integration); the terms are then chosen again at the refined delay (off the true
    delay, more terms soak up what the ripple's misfit leaves), and the delay refined at
    those, until the terms stay and the delay is inside its window (a candidate from the
    noise waves' periodogram can be off by more than the window: 204 ns for a 200 ns
    ripple stopped at the window's edge, 620 nats below the peak), at most
    :data:`REFINE_ROUNDS` rounds.
    """
    from scipy.optimize import minimize_scalar
    span = 0.25 / float(freq_hz[-1] - freq_hz[0])
    for _ in range(REFINE_ROUNDS):
        assert isinstance(model.basis, DelayBasis)
        k, delays = model.basis.polynomial_terms, model.basis.delays_s
        tau = delays[-1]

        def cost(t: float, k: int = k, delays: tuple[float, ...] = delays) -> float:
            fitted = _with_delays(rows, freq_hz, poly, (*delays[:-1], t), k, scale_prior)
            return np.inf if fitted is None else -fitted.log_evidence

        found = minimize_scalar(
            cost, bounds=(max(tau - span, 1e-12), tau + span), method="bounded",
            options={"xatol": 1e-4 * span},
        )
        again = best_model(
            rows, freq_hz, poly, (*delays[:-1], float(found.x)), scale_prior, refine=False
        )
        if again is None or again.log_evidence <= model.log_evidence:
            return model
        model = again
        assert isinstance(model.basis, DelayBasis)
        at_edge = abs(float(found.x) - tau) > 0.9 * span  # the peak lies further: go on
        if model.basis.polynomial_terms == k and not at_edge:
            return model
    return model


def delay_sd(
    rows: Rows, freq_hz: FloatArray, poly: PolynomialBasis, model: DelayModel,
    scale_prior: ScalePrior | None,
) -> tuple[float, ...]:
    """Each delay's posterior sd (s): Laplace's, from the evidence's curvature in it.

    ``sd^-2 = -d^2 log Z / d tau^2`` by central differences at the model's own terms;
    where the curvature is not negative (a delay the evidence does not bound) the band's
    resolution stands in.
    """
    assert isinstance(model.basis, DelayBasis)
    k, delays = model.basis.polynomial_terms, model.basis.delays_s
    resolution = 1.0 / float(freq_hz[-1] - freq_hz[0])
    h = 1e-2 * resolution
    out = []
    for j, tau in enumerate(delays):
        z = []
        for t in (tau - h, tau + h):
            moved = (*delays[:j], t, *delays[j + 1 :])
            fitted = _with_delays(rows, freq_hz, poly, moved, k, scale_prior)
            z.append(-np.inf if fitted is None else fitted.log_evidence)
        curvature = (2.0 * model.log_evidence - z[0] - z[1]) / h**2
        out.append(float(1.0 / np.sqrt(curvature)) if curvature > 0 else resolution)
    return tuple(out)


def marginal_model(
    rows: Rows, freq_hz: FloatArray, poly: PolynomialBasis, model: DelayModel,
    scale_prior: ScalePrior | None,
) -> tuple[DelayModel, tuple[float, ...]]:
    """``model`` with its delays' own uncertainty carried, and those delays' sds.

    A delay found by the evidence is known to ``sd`` (:func:`delay_sd`); the ripple's
    curves at ``tau + d`` differ from those at ``tau`` by ``d`` times their derivative,
    ``2 pi (nu - nu_c) A sin(...)``, which no column of the model holds, so a posterior
    at the found delay alone is too sure of the ripple far from the band's centre (at a
    20 MHz period and 0.3-3 K, 1.2-2x its error bars). Each delay becomes the pair
    ``tau, tau + sd``: their cos/sin columns span those at ``tau`` and the derivative's to
    second order in ``sd``, so the fit (under the same wide prior) measures the shift
    the data allow and the posterior carries it: the delay linearised and marginalised,
    with a shift of its own per parameter. The pair's spacing is kept within
    ``[1e-3, 0.25]`` of the band's delay resolution (columns apart enough to solve, close
    enough for the expansion). Only parameters whose ripple the model measures (a delay
    term :data:`MEASURED_SIGMAS` sd from zero) get the pair's second delay: the rest keep
    ``tau`` alone (the basis's delays are ``tau`` then ``tau + sd``), else ``T_NS``'s
    unmeasured shift left it to the prior (328 K sd at 130 MHz, refused).
    """
    assert isinstance(model.basis, DelayBasis)
    sds = delay_sd(rows, freq_hz, poly, model, scale_prior)
    resolution = 1.0 / float(freq_hz[-1] - freq_hz[0])
    delays = model.basis.delays_s
    shifted = [
        tau + float(np.clip(sd, 1e-3 * resolution, 0.25 * resolution))
        for tau, sd in zip(delays, sds, strict=True)
    ]
    k, d = model.basis.polynomial_terms, len(delays)
    post = model.posterior
    z = np.abs(post.mean) / np.sqrt(np.maximum(np.diag(post.covariance), 1e-300))
    orders = as_orders([
        k + 2 * d + 2 * d * bool(np.any(z[part][k:] >= MEASURED_SIGMAS))
        for part in coefficient_slices(post.orders)
    ])
    basis = DelayBasis(poly.kind, poly.f_lo_hz, poly.f_hi_hz, k, (*delays, *shifted))
    wide = _fit_model(rows, freq_hz, basis, max(orders), scale_prior, orders)
    return (model if wide is None else wide), sds


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
    # The box's starting size sees a ripple before growth absorbs it (module docstring).
    start = _fit_model(rows, freq_hz, poly, START_TERMS, scale_prior) if search else None
    seen = [start.curves(freq_hz)] if start is not None else []
    for _ in range(MAX_DELAYS if search else 0):
        tried = []
        # The start's residuals first: a grown box's fit has absorbed part of a ripple and
        # its residual's peak sits above the delay (56 ns for 50). Candidates a refinement
        # window apart are tried apart (delay_candidates.union).
        for tau in union(
            [find(current_rows, t, freq_hz, delays)
             for t in [*seen, current_theta]
             for find in (parameter_candidates, candidate_delays)],
            0.25 / float(freq_hz[-1] - freq_hz[0]),
        ):
            model = best_model(
                current_rows, freq_hz, poly, (*delays, tau), scale_prior, refine=False
            )
            # A model taking T_NS through zero has no operating point to relinearise about.
            if model is not None and np.all(model.curves(freq_hz)[INDEX["NS"]] > 0):
                tried.append(model)
        if not tried:
            break
        model = max(tried, key=lambda m: m.log_evidence)
        better = refined(current_rows, freq_hz, poly, model, scale_prior)
        if np.all(better.curves(freq_hz)[INDEX["NS"]] > 0):
            model = better
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
        seen = []
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
        marginal, sds = marginal_model(current_rows, freq_hz, poly, kept, scale_prior)
        ext = Extension(marginal, chi2, dof, after, dof_after)
        assert isinstance(kept.basis, DelayBasis)
        periods = ", ".join(f"{1e-6 / d:.3g}" for d in kept.basis.delays_s)
        ext.metadata["delay_terms"] = {
            "delays_ns": [round(1e9 * d, 3) for d in kept.basis.delays_s],
            "delay_sd_ns": [round(1e9 * d, 4) for d in sds],
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
