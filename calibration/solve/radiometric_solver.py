"""The radiometric solver: the likelihood of what the receiver actually measured.

The measured quantity is ``Q`` (eq. 3.9), built from three spectra whose noise the
radiometer equation gives, ``sigma_P = P / sqrt(B tau)``. Its variance ``var(Q_if)``
differs per calibrator ``i`` and channel ``f`` (:func:`calibration.model.noise_waves.q_variance`).
Eq. 3.27 solved for Q is the model::

    Q_if(Theta) = (T_i - X_unc T_unc - X_cos T_cos - X_sin T_sin - X_L T_L) / (X_L T_NS)
    Q_if(measured) ~ N(Q_if(Theta), s^2 var(Q_if))

It is linear in every parameter but ``T_NS``. One Gauss-Newton step about a current
estimate ``Theta_0`` (with ``Q_0 = Q(Theta_0)``) is exactly a weighted linear regression
in the thesis's own variables::

    y_if = T_i - X_L T_NS0 (Q_if - Q0_if)                 (temperature, noise moved out of X)
    x_if = (X_unc, X_cos, X_sin, Q0_if X_L, X_L)          (design: eq. 3.28 with the *model* Q)
    w_if = 1 / (X_L T_NS0)^2 var(Q_if)                    (radiometer weights)

so the thesis's conjugate machinery (eqs. 3.34-3.36,
:mod:`calibration.regression.conjugate`) applies
unchanged to whitened rows. Because ``x`` holds the noiseless ``Q_0``, there is no
errors-in-variables bias, and because ``w`` follows the radiometer equation, the estimate
is efficient: its error reaches the Cramer-Rao floor (:mod:`calibration.solve.noise_floor`).
The iteration runs to a stated criterion (:mod:`calibration.solve.convergence`): with the hot
load among the calibrators two or three steps converge; calibrators spanning a few
kelvin need more, and a step that raises the misfit is halved.

Calibrator temperatures with a stated uncertainty (``SourceData.temperature_std_k``) have
their per-source offset marginalised in the normal equations, so the posterior, the
evidence and the predictive include the thermometry's error.

``s^2`` either has an inverse-gamma prior with mode 1 (default: the radiometer equation
is trusted but can be found wrong, which inflates the error bars) or is fixed at 1.

The coefficients' prior is by default hierarchical (:mod:`calibration.regression.shrinkage`): each
parameter's level is free, the higher terms share a scale that the data set, so that the
choice of orders does not depend on an arbitrary width. The posterior is then the
evidence-weighted mixture of the models that carry the weight (:mod:`calibration.choice.averaging`);
``average=False`` keeps the single best model. Every entry of the evidence table comes
from the same normal equations, linearised at the largest model's fit: the chosen
model's own fit is within the noise of it, so the Gauss-Newton step from there is exact
to second order in that difference (about 1e-8 of T_NS).

Where the reflections' errors are known, the rows' dependence on them is taken out of
the normal equations, and the search is kept to the models the calibrators identify
above them (:mod:`calibration.regression.errors_in_variables`): few calibrators otherwise let the
fit trade those errors' variance for a wrong model.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np
from numpy.typing import NDArray

from ..choice.averaging import MixturePosterior
from ..choice.model_fit import OrderChoice, fit
from ..choice.model_size import fit_extending, model_size_metadata
from ..core.blas_threads import with_one_blas_thread
from ..core.errors import IllPosedError
from ..model.basis import BasisKind, PolynomialBasis
from ..model.data import CalibrationData
from ..model.noise_waves import INDEX, design_terms
from ..model.polynomial_model import Orders, as_orders
from ..model.reflection_noise import reflection_variance, temperature_variance
from ..regression.conjugate import CoefficientPrior, ScalePrior
from ..regression.errors_in_variables import (
    MU_MAX,
    Identified,
    corrected,
    error_moments,
    identified_orders,
    row_errors,
)
from ..regression.normal_equations import (
    NormalEquations,
    build_normal_equations,
    evaluate_coefficients,
)
from ..regression.shrinkage import ShrinkagePrior
from .beyond_box import beyond_box
from .convergence import (
    MAX_STEPS,
    TOLERANCE,
    ChiSquare,
    Convergence,
    curve_std,
    damped,
    relative_change,
)
from .correlated_reflections import shared_error_excess, widen
from .delay_terms import inflated
from .identifiability import (
    CUT_REFLECTIONS,
    CUT_T_NS,
    UndeterminedError,
    check_determined,
    require_matched_contrast,
    require_positive_ns,
    require_temperature_contrast,
)
from .linearisation import LinearisedProblem, linearise
from .solution import Solution

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RadiometricPrior:
    """Priors of the radiometric solver: coefficients (K) and the noise scale ``s^2``.

    ``coefficients`` is the hierarchical :class:`ShrinkagePrior` by default; a fixed
    :class:`CoefficientPrior` gives the single-width prior of the thesis (whose choice of
    orders depends on that width). ``scale=None`` fixes ``s^2 = 1`` (Gaussian posterior);
    the default ``IG(1, 2)`` has its mode at 1.
    """

    coefficients: CoefficientPrior | ShrinkagePrior = field(default_factory=ShrinkagePrior)
    scale: ScalePrior | None = field(default_factory=lambda: ScalePrior(1.0, 2.0))


@dataclass
class _LastRows:
    """The last linearisation's rows, reflection variances, operating point and layout.

    Read twice: by the posterior's widening for reflection errors shared between
    channels (:func:`_shared_errors`) and for the moment correction's own variance
    (``error_gram``), and by ``build`` when the order limits are raised, whose first
    relinearisation starts from ``theta`` (``problem is None``: no earlier
    linearisation, so the thesis's start is used).
    """

    problem: LinearisedProblem | None = None
    theta: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    basis: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    largest: Orders = ()  # type: ignore[assignment]
    #: ``C`` of :mod:`calibration.regression.errors_in_variables` where the rows were corrected.
    error_gram: FloatArray | None = None
    #: ``mu`` of fixed orders solved uncorrected although the reflections' errors decide
    #: them (``allow_prior_dominated``).
    uncorrected_share: float | None = None


def _shared_errors(
    data: CalibrationData, last: _LastRows, gammas: NDArray[np.complex128], q: FloatArray,
    gamma_std: FloatArray,
) -> FloatArray:
    """The posterior's share of the sources' reflection errors shared between channels."""
    assert last.problem is not None
    theta = last.theta[:, None, :]
    source = temperature_variance(theta, gammas, data.gamma_rec, q, gamma_std)
    offsets = data.temperature_variances()
    return shared_error_excess(
        last.problem.features, last.problem.weights, last.basis, last.largest,
        data.reflection_correlation_channels, source, offsets if np.any(offsets > 0) else None,
    )


def _normal_equations(
    problem: LinearisedProblem,
    basis: FloatArray,
    orders: Orders,
    ridge: FloatArray,
    offset_variance: FloatArray | None = None,
) -> NormalEquations:
    return build_normal_equations(
        problem.features,
        problem.weights,
        problem.response,
        basis,
        orders,
        ridge=ridge,
        offset_variance=offset_variance,
    )


def _rows(
    gamma: NDArray[np.complex128], gamma_rec: NDArray[np.complex128], *, temps: FloatArray,
    q: FloatArray, var_q: FloatArray, theta: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """The Gauss-Newton rows' features and response about ``theta`` at given reflections."""
    problem = linearise(design_terms(gamma, gamma_rec[None, :]), temps, q, var_q, theta)
    return problem.features, problem.response


@with_one_blas_thread
def solve_radiometric(
    data: CalibrationData,
    orders: OrderChoice | None = None,
    prior: RadiometricPrior | None = None,
    basis_kind: BasisKind = "legendre",
    max_steps: int = MAX_STEPS,
    average: bool = True,
    allow_prior_dominated: bool = False,
    delay_terms: bool = True,
) -> Solution:
    """Noise-wave parameters from the radiometer-noise likelihood of Q.

    ``orders=None`` chooses the orders by evidence. Gauss-Newton steps are taken at the
    largest model before the search until no parameter moves by more than
    :data:`~calibration.solve.convergence.TOLERANCE` of its posterior sd, at most
    ``max_steps`` (:mod:`calibration.solve.convergence`); ``metadata["convergence"]`` says how
    it ended, and a fit that did not converge adds a sentence to ``metadata["warnings"]``
    (the list of sentences a user should read). ``average`` (with the default prior)
    mixes the models by evidence; the solution's metadata lists the leading models and
    their weights either way.

    Parameters the data leave to the prior (:mod:`calibration.solve.identifiability`) are listed
    in ``metadata["prior_dominated"]``; an undetermined T_NS raises
    :class:`~calibration.solve.identifiability.UndeterminedError` naming it and why, unless
    ``allow_prior_dominated`` (which also lets fixed orders exceed what the data constrain).

    With ``delay_terms`` the fit is tested against the radiometer noise in binned
    residuals; structure beyond the box is modelled by delay terms where the evidence
    wants them, and what remains widens the error bars (:mod:`calibration.solve.delay_terms`),
    with a sentence in ``metadata["warnings"]`` either way.
    """
    if max_steps < 1:
        raise ValueError("max_steps must be >= 1")
    choice = orders or OrderChoice()
    prior = prior or RadiometricPrior()
    if len(data.sources) < 2:
        raise IllPosedError(
            f"one calibrator ({data.names[0]!r}) cannot separate T_NS from T_L: "
            "at least two are needed (e.g. ambient and hot loads)"
        )
    require_temperature_contrast(data)
    if not allow_prior_dominated:
        require_matched_contrast(data)
    basis = PolynomialBasis.for_frequencies(data.freq_hz, basis_kind)
    terms = data.terms()
    temps, q, var_q = data.stacked()
    offsets = data.temperature_variances()
    gamma_std = data.reflection_errors()
    gammas = np.stack([s.gamma for s in data.sources.values()])
    offset_var = offsets if np.any(offsets > 0) else None
    coefficient_prior = prior.coefficients

    def ridge(orders: Orders) -> FloatArray:
        if isinstance(coefficient_prior, ShrinkagePrior):  # its widest: the data decide
            return 1.0 / coefficient_prior.widest_variances(orders)
        return 1.0 / coefficient_prior.vectors(orders)[1]

    # The last linearisation's rows and reflection variances, for the posterior's share
    # of reflection errors shared by neighbouring channels (correlated_reflections).
    last = _LastRows()
    # Order boxes cut to what the calibrators determine: (asked, kept, why).
    cuts: list[tuple[Orders, Orders, str]] = []

    def linearised(largest: Orders) -> NormalEquations:
        """Gauss-Newton at ``largest`` to :data:`~calibration.solve.convergence.TOLERANCE`."""
        b = basis.matrix(data.freq_hz, max(largest))
        r = ridge(largest)
        record = Convergence()
        convergence[0] = record
        # Limits raised (fit_extending): the last operating point is the better start.
        if last.problem is not None:
            theta = last.theta
        else:
            # Start: the thesis's design (measured Q) with radiometer weights, T_NS ~ 1000 K.
            start = LinearisedProblem(terms.matrix(q), 1.0 / (terms.x_l**2 * 1e6 * var_q), temps)
            theta = operating_point(_normal_equations(start, b, largest, r), b, largest)
        while True:
            extra = reflection_variance(
                theta[:, None, :], gammas, data.gamma_rec, q, gamma_std, data.gamma_rec_std
            )
            problem = linearise(terms, temps, q, var_q, theta, extra)
            normal = _normal_equations(problem, b, largest, r, offset_var)
            last.problem, last.theta, last.basis, last.largest = problem, theta, b, largest
            record.steps += 1
            proposal = operating_point(normal, b, largest)
            record.change = relative_change(proposal, theta, curve_std(normal, r, b, largest))
            record.history.append(record.change)
            if record.change < TOLERANCE:
                record.converged = True
                return normal
            if record.steps >= max_steps:
                return normal
            if not largest_physical[0]:  # the evidence's models: another objective
                theta = proposal
                continue
            gain = terms.x_l * theta[INDEX["NS"]]
            theta = damped(
                theta, proposal, record, ChiSquare(terms, temps, q, problem.weights, gain)
            )

    def build(largest: Orders) -> NormalEquations:
        """The normal equations at ``largest``, or within it.

        Corrected for the reflections' errors' bias where those are known
        (:mod:`calibration.regression.errors_in_variables`). The operating point is fitted in the
        largest box within ``largest`` that the calibrators identify above those errors;
        the equations span ``largest``, and say which of its models beyond that box are
        identified too (``identified``). Where even the largest models' fits take T_NS
        through zero, ``largest`` itself loses its top terms.
        """
        box = largest  # where the operating point is fitted
        last.uncorrected_share = None
        while True:
            try:
                normal = linearised(box)
            except UndeterminedError:
                # The largest models' fits take T_NS through zero (operating_point): the
                # box's top terms are what the calibrators leave free; try without them.
                top = max(box)
                smallest = choice.min_orders
                fewer = as_orders([
                    n - (n == top and n > m) for n, m in zip(box, smallest, strict=True)
                ])
                if fewer == box:
                    raise
                cuts.append((box, fewer, CUT_T_NS))
                largest = box = fewer
                last.problem = None
                continue
            last.error_gram = None
            if last.problem is None:
                return normal
            theta = last.theta
            errors = row_errors(
                partial(_rows, temps=temps, q=q, var_q=var_q, theta=theta),
                gammas, data.gamma_rec, gamma_std, data.gamma_rec_std,
            )
            if errors is None:
                return normal
            weights = last.problem.weights
            moments = error_moments(errors, weights, last.basis, box)
            fewer, mu = identified_orders(
                normal.gram, moments.gram, box, choice.min_orders, MU_MAX
            )
            if fewer != box:  # restart at the smaller box from the thesis's start
                cuts.append((box, fewer, CUT_REFLECTIONS))
                box, last.problem = fewer, None
                continue
            if mu > MU_MAX:
                if allow_prior_dominated:
                    last.uncorrected_share = mu
                    return normal
                raise IllPosedError(
                    f"the calibrators {list(data.names)} do not identify a model with orders "
                    f"{box} above their reflections' errors: in one direction those "
                    f"errors carry {mu:.2f} of the apparent information (at most {MU_MAX}); "
                    "lower the orders, add calibrators or measure the reflections better"
                )
            identified = None
            if box != largest:  # the same rows, over every model of the whole box
                b = basis.matrix(data.freq_hz, max(largest))
                normal = _normal_equations(last.problem, b, largest, ridge(largest), offset_var)
                moments = error_moments(errors, weights, b, largest)
                identified = Identified(box, normal.gram, moments.gram, largest)
                last.basis, last.largest = b, largest
            last.error_gram = moments.gram
            fixed = corrected(normal, moments, errors, weights, last.basis, theta)
            return replace(fixed, identified=identified)

    # Whether the largest model's fit keeps T_NS positive: only then may it join the
    # average as the smooth-function hypothesis (a model that takes T_NS through zero is
    # unphysical there, and it is what the fallback below steps around).
    largest_physical = [True]
    convergence = [Convergence()]  # the last box's iteration

    def operating_point(normal: NormalEquations, b: FloatArray, largest: Orders) -> FloatArray:
        theta = evaluate_coefficients(normal.reference, b, largest)
        largest_physical[0] = bool(np.all(theta[INDEX["NS"]] > 0))
        if largest_physical[0]:
            return theta
        # Few calibrators leave the largest model free to take T_NS through zero where the
        # data pin it weakly; the evidence's models, fitted on the same equations, are the
        # smoother point to linearise about. If they too cross zero, T_NS is undetermined.
        within = choice if choice.orders is not None else replace(choice, max_orders=largest)
        post, _ = fit(
            normal, within, coefficient_prior, 1.0, prior.scale, allow_prior_dominated,
            average=average, smooth=False,
        )
        theta = evaluate_coefficients(post.mean, b, post.orders)
        require_positive_ns(theta[INDEX["NS"]], data)
        return theta

    result = fit_extending(
        build, choice, coefficient_prior, 1.0, prior.scale, allow_prior_dominated, average,
        smooth=lambda: largest_physical[0],
    )
    posterior, table = result.posterior, result.table
    metadata: dict[str, object] = dict(result.limits_metadata())
    if cuts:
        metadata["order_box_cuts"] = [
            {"asked": list(a), "kept": list(b), "why": why} for a, b, why in cuts
        ]
    metadata["convergence"] = convergence[0].metadata()
    warnings: list[str] = result.warnings()  # the fit's own (model_size), then ours
    if (sentence := convergence[0].warning()) is not None:
        warnings.append(sentence)
    if last.uncorrected_share is not None:
        metadata["reflection_errors_uncorrected"] = round(last.uncorrected_share, 4)
    shared = data.reflection_correlation_channels
    excess = last.error_gram  # the corrected fit's own sandwich (errors_in_variables)
    if last.problem is not None and gamma_std is not None and shared > 1:
        share = _shared_errors(data, last, gammas, q, gamma_std)
        excess = share if excess is None else excess + share
        metadata["reflection_correlation_channels"] = data.reflection_correlation_channels
    if excess is not None:
        posterior = widen(posterior, excess, last.largest)
    best = max(table, key=table.__getitem__)
    used_basis: PolynomialBasis = basis
    inflation = 1.0
    if delay_terms and last.problem is not None:
        posterior, used_basis, inflation = beyond_box(
            data, posterior, basis, last.problem, prior.scale, choice.orders is None,
            metadata, warnings,
            grew=any(m > n for m, n in zip(result.max_orders, choice.limits, strict=True)),
        )
        if used_basis is not basis:  # a delay model: it is the model used, not the search's
            best = posterior.orders
            metadata.update(model_size_metadata(posterior))
    metadata["best_orders"] = list(best)
    if isinstance(posterior, MixturePosterior):
        weights = posterior.model_weights()
        metadata["averaged"] = average
        metadata["model_weights"] = [
            {"orders": list(o), "weight": round(w, 6)} for o, w in list(weights.items())[:10]
        ]
    solution = Solution(
        method="radiometric",
        basis=used_basis,
        posterior=posterior,
        measurement_model="radiometer",
        evidence_table=table,
        calibrators=tuple(data.names),
        metadata=metadata,
    )
    metadata["prior_dominated"] = check_determined(
        solution, data, coefficient_prior, allow_prior_dominated
    )
    metadata["warnings"] = warnings
    if inflation > 1.0:
        solution = replace(solution, posterior=inflated(solution.posterior, inflation))
    return replace(solution, metadata=metadata)
