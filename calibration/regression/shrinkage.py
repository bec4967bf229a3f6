"""A coefficient prior whose width the data set: the evidence no longer depends on it.

With one fixed, wide prior ``N(0, sd^2)`` on every polynomial coefficient, each extra
term pays an Occam factor of about ``log(sd / posterior sd)`` in log evidence: some ten
nats for a 3000 K prior on a term measured to 0.1 K. The evidence then drops any term
below about 4-5 posterior sigma, although the bias it leaves is as large as the error
bars (Lindley's paradox), and the choice moves with a width nobody measured.

This prior is hierarchical (Gelman et al., *Bayesian Data Analysis*, ch. 5; the
"automatic relevance" idea of MacKay 1992 with shared scales)::

    c_k0              ~ N(0, constant_sd_k^2)          the level of parameter k = 1..5
    c_kj | tau, rho   ~ N(0, (tau rho^(j-1))^2)        its Legendre term j >= 1 (K)
    log tau           ~ uniform on [log tau_min, log tau_max]  (or tau half-Cauchy: below)
    rho               ~ uniform on ``decays`` (1, 0.7, 0.5, 0.3, 0.2, 0.1, 0.03)

Every model has the five constant terms, so their wide prior is common to all models
and cancels from every Bayes factor (a test holds it); what decides the orders is the
prior of the terms that come and go. ``tau`` (kelvin per basis function) is the size of
the first-order structure across the band, and ``rho`` how fast the terms fall with
order: the Legendre coefficients of a smooth function decay geometrically (at a rate set
by how far from the band its nearest singularity lies), so a receiver whose linear terms
are tens of kelvin is not expected to have quadratic terms as large, and a term near the
noise should be judged against the size its order makes plausible. Both are learnt from
the data by marginalising them on a grid (:func:`log_evidence_scales`). An extra term
then pays about ``log(tau rho^(j-1) / posterior sd)``: a few nats where a fixed 3000 K
width charged ten, and a width nobody chose.

Measured (``python -m benchmarks.model_choice``): with five quadratic terms each at 2-6
posterior sigma, the fixed 3000 K prior dropped a term in every run (calibration-only
coverage 33 %/61 % at 68 %/95 %); one shared ``tau`` without decay, 41 %/71 %; with the
decay, 53 %/83 %, and averaged over models 56 %/86 % (the true orders: 65 %/94 %). On
the default REACH-like receiver, whose terms are all far above the noise, every prior
finds the true orders.

**One scale or five.** The five parameters are different physical quantities (T_NS
about 1000 K, T_sin about 90 K), and their structures need not be alike in size: one
``tau`` follows the largest, and charges the terms of a parameter with less structure
an Occam factor sized for the largest one, so they are dropped and their bias is left
outside the error bars. By default (``per_parameter``) each parameter's ``tau_k`` (and
the shared ``rho``) is set by the data (:mod:`calibration.choice.scale_fit`: at the largest
model for the smooth-function hypothesis, at the best polynomial for the polynomials),
and the orders are chosen and averaged under those widths; this grid then serves as the
fit's start. Measured on the benchmark's ensembles (``benchmarks/README.md``, "What the
model-choice runs showed"), the shared scale's error bars were 15-24 % short where the
data constrain least (8 calibrators, the four EDGES loads, smooth truths), the fitted
scales' 6-14 %.

The noise scale ``s^2`` keeps its inverse-gamma prior
(:class:`~calibration.regression.conjugate.ScalePrior`),
so the coefficient prior, being that of a normal-inverse-gamma model, scales with
``s^2``; with ``s^2`` near 1, as the radiometer equation makes it, that is immaterial.

**The scale's own prior.** Uniform in ``log tau``, the marginal evidence carries the
normalisation ``1 / log(tau_max / tau_min)`` of a range nobody measured, and where the
data cannot bound ``tau`` from below its posterior follows the prior's mass down to the
grid's end. ``scale_hyperprior_k = s`` makes ``tau`` half-Cauchy instead (Gelman 2006,
*Bayesian Analysis* 1, 515): flat in ``tau`` below ``s``, ``1/tau^2`` above, so that the
lower end no longer matters (a test). It is an option, not the default: measured
(``python -m benchmarks.model_choice --runs 100 --seed 100``, the same runs), with
``s = 10 K`` actual/predicted error moved 1.07 -> 1.09 (random truths, 12 calibrators),
1.24 -> 1.28 (four loads), 1.15 -> 1.19 (smooth truths), 1.16 -> 1.16 (8 calibrators),
1.02 -> 1.01 (weak terms): no better. (A first measurement that looked better, 1.22 ->
1.12 with 8 calibrators, had the benchmark's truths drawn with the solver's own prior:
the prior changed the truths, not the error bars.)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_factor, cho_solve

from ..model.polynomial_model import as_orders
from .conjugate import ScalePrior, log_evidence_from
from .normal_equations import NormalEquations

FloatArray = NDArray[np.float64]

#: The highest term's prior is at most this many times narrower than the linear term's:
#: narrower is zero in effect (the lower model, which the search evaluates anyway), and it
#: would only cost the eigendecomposition its accuracy.
MAX_NARROWING = 1e3


def narrowing(decay: float | FloatArray, power: FloatArray) -> FloatArray:
    """Each term's prior sd over its parameter's first-order term's: ``decay^power``.

    ``power`` is the term's order less one (``-1`` on a constant, which gets 1); no term
    is narrower than ``1 /`` :data:`MAX_NARROWING`. Broadcasts ``decay`` against ``power``.
    """
    return np.maximum(np.asarray(decay) ** np.maximum(power, 0.0), 1.0 / MAX_NARROWING)


@dataclass(frozen=True)
class ShrinkagePrior:
    """The hierarchical coefficient prior of the module docstring.

    Parameters
    ----------
    constant_sd_k
        Prior width of each parameter's constant term (K): wide against any physical
        noise temperature; common to every model, so it does not move the choice.
    tau_min_k, tau_max_k
        Range of the higher terms' scale ``tau`` (K): from far below the radiometer's
        reach (1 mK) to far above any physical structure (3000 K).
    n_scales
        Grid points in ``log tau``; their spacing (0.4 in ``ln tau`` by default) is finer
        than the width of ``tau``'s posterior for a handful of terms.
    decays
        The values of ``rho``, the ratio of successive terms' prior widths, from none
        (1) to strong (0.03); a term's width is at most :data:`MAX_NARROWING` times
        narrower than the first-order term's. The grid stands for a continuous prior on
        ``rho``: neighbouring values change no term's width (up to the eighth, clipped
        at :data:`MAX_NARROWING`) by more than 16 times, finest near 1 where the high
        terms feel a step most. The grid 1, 0.3, 0.1, 0.03 changed the eighth term by
        1000 times between its first two values and had nothing for a receiver whose
        terms fall by 0.5-0.7 per order, as a cable's ripple does. Measured on the
        benchmark's earlier ensembles (terms sized in the prior's shrunk sd; docs/results.md)
        (``python -m benchmarks.model_choice --runs 100 --seed 100``, the same runs):
        actual/predicted error 1.17 -> 1.14 on smooth truths, 1.30 -> 1.23 with 8
        calibrators, 1.09 -> 1.04 on the four EDGES loads, 1.15 -> 1.09 on random truths,
        the REACH-like and weak-term rows unchanged. Each model's evidence costs one
        eigendecomposition per decay: the search's share of the solve grows by 7/4.
    per_parameter
        Give each parameter its own ``tau``, set by the data at the largest model
        (:mod:`calibration.choice.scale_fit`; the default), instead of one marginalised ``tau``
        for all five (``False``).
    scale_per_parameter
        With one shared ``tau`` (``per_parameter=False``): offer the averaged posterior a
        third hypothesis beside the polynomials and the smooth functions under that
        scale: smooth functions with a scale per parameter, marginalised
        (:mod:`calibration.choice.parameter_scales`).
    scale_hyperprior_k
        ``None`` (default): ``log tau`` uniform on its range; else the half-Cauchy scale
        ``s`` (K) of ``tau``'s prior (module docstring). For the marginalised scales: the
        shared grid's and the third hypothesis's draws.
    width_hyperprior_k
        The half-Cauchy scale (K) of a prior on each fitted ``tau_k`` (``per_parameter``):
        the widths are then the mode of their posterior in ``log tau_k``
        (:mod:`calibration.choice.scale_fit`). ``None`` (default): set by the data when
        ``width_scale_from_data``, else no prior (type-II maximum likelihood).
    width_scale_from_data
        Set the widths' half-Cauchy scale from the type-II widths of the largest model
        (:func:`calibration.choice.scale_fit.width_scale`): the scale of the structure this
        receiver has, shared by its five parameters.
    """

    constant_sd_k: float = 3000.0
    tau_min_k: float = 1e-3
    tau_max_k: float = 3000.0
    n_scales: int = 38
    decays: tuple[float, ...] = (1.0, 0.7, 0.5, 0.3, 0.2, 0.1, 0.03)
    per_parameter: bool = True
    scale_per_parameter: bool = True
    scale_hyperprior_k: float | None = None
    width_hyperprior_k: float | None = None
    width_scale_from_data: bool = True

    def __post_init__(self) -> None:
        if not (0 < self.tau_min_k < self.tau_max_k and self.constant_sd_k > 0):
            raise ValueError("need 0 < tau_min_k < tau_max_k and constant_sd_k > 0")
        if self.n_scales < 2:
            raise ValueError("n_scales must be at least 2")
        for name in ("scale_hyperprior_k", "width_hyperprior_k"):
            value = getattr(self, name)
            if value is not None and not value > 0:
                raise ValueError(f"{name} must be positive (or None)")
        if not self.decays or not all(0 < r <= 1 for r in self.decays):
            raise ValueError("decays must be in (0, 1]")

    @property
    def scales_k(self) -> FloatArray:
        """The grid of ``tau`` (K)."""
        return 1.0 / np.sqrt(_precisions(self))

    @property
    def log_grid_weights(self) -> FloatArray:
        """``(G,)``: each grid point's log prior mass times ``G`` (0 everywhere: uniform).

        Added to the grid's log evidences, it makes their mean
        (:func:`marginal_log_evidence`) the evidence under ``tau``'s prior; the decays stay
        equally likely. The grid is even in ``log tau``, so a point's mass is the density
        of ``log tau`` there, normalised over the grid.
        """
        density = log_scale_density(np.log(self.scales_k), self, self.scale_hyperprior_k)
        mass = np.exp(density - np.max(density))
        return np.tile(np.log(self.n_scales * mass / mass.sum()), len(self.decays))

    @property
    def n_grid(self) -> int:
        """Points of the hyperparameter grid: every decay times every scale."""
        return len(self.decays) * self.n_scales

    def widest_variances(self, orders: Sequence[int]) -> FloatArray:
        """The grid's widest prior (no decay, ``tau_max``): a weak ridge for a reference fit."""
        orders = as_orders(orders)
        power = np.concatenate([np.arange(n) - 1.0 for n in orders])
        return np.where(power >= 0, self.tau_max_k**2, self.constant_sd_k**2)

    def variances(self, orders: Sequence[int]) -> FloatArray:
        """Prior variance of every coefficient of ``orders`` at every grid point: ``(G, P)``.

        Grid point ``g = i_decay * n_scales + i_tau``; term ``j >= 1`` has the sd
        ``tau * decay^(j - 1)``.
        """
        orders = as_orders(orders)
        power = np.concatenate([np.arange(n) - 1.0 for n in orders])  # -1 on constants
        higher = power >= 0
        narrowed = narrowing(np.asarray(self.decays)[:, None, None], power[higher])  # (D, 1, H)
        out = np.full((len(self.decays), self.n_scales, power.size), self.constant_sd_k**2)
        out[:, :, higher] = (self.scales_k[None, :, None] * narrowed) ** 2
        return out.reshape(self.n_grid, power.size)


def log_evidence_scales(
    normal: NormalEquations,
    orders: Sequence[int],
    prior: ShrinkagePrior,
    scale_prior: ScalePrior | None,
) -> FloatArray:
    """Log evidence of the sub-model ``orders`` at every point of the prior's grid.

    One model's row of :meth:`EvidenceGrid.of`; a search over many models builds one
    :class:`EvidenceGrid` and scores them in batches.
    """
    return EvidenceGrid(normal, prior, scale_prior).of([orders])[0]


class EvidenceGrid:
    """Log evidences of sub-models of one set of normal equations, many at once.

    The same evidence as :func:`calibration.regression.conjugate.solve` (eq. 3.35, zero prior mean)
    at each point of the prior's grid. Relative to the reference fit ``c_ref`` of the
    normal equations, with ``O`` the coefficients the model leaves out and ``e = c - c_ref``
    on the rest (``S``)::

        r'Wr' = chi_ref + 2 c_ref,O . g_O + c_ref,O^T G_OO c_ref,O
        Lambda = G_SS + V_0^-1,      u = g_S + G_SO c_ref,O - V_0^-1 c_ref,S
        Q_min = r'Wr' + c_ref,S^T V_0^-1 c_ref,S - u^T Lambda^-1 u

    With the constant terms ``C`` (fixed width ``v_C``) eliminated first, the higher terms
    ``H`` see ``S = G_HH - G_HC K^-1 G_CH`` (``K = G_CC + V_C^-1``) and the prior precision
    ``t = 1 / tau^2`` times the identity, so ``S = U diag(lambda) U^T`` gives every width at
    once (``p`` and ``r`` are the linear term and ``c_ref,H`` in the eigenbasis)::

        log|Lambda| = log|K| + sum_i log(lambda_i + t)
        Q_min = r'Wr' + c_ref,C^T V_C^-1 c_ref,C - u_C^T K^-1 u_C
                + sum_i (t lambda_i r_i^2 + 2 t p_i r_i - p_i^2) / (lambda_i + t)

    the last line written without the ``t^2`` terms that cancel. Models that share their
    constant terms (every model with at least one term per parameter) share ``K`` and the
    Schur complement of the whole largest model, of which each model's ``S`` is a
    sub-block: those are computed once, and models with the same number of higher terms
    are decomposed in one stacked ``eigh``. It agrees with the conjugate solver point by
    point (a test), at a fraction of the cost of one Cholesky factorisation per grid
    point. A width at which ``Lambda`` is not positive definite gets ``-inf``.
    """

    def __init__(
        self, normal: NormalEquations, prior: ShrinkagePrior, scale_prior: ScalePrior | None
    ) -> None:
        self.normal, self.prior, self.scale_prior = normal, prior, scale_prior
        largest = normal.max_orders
        self._power = np.concatenate([np.arange(n) - 1.0 for n in largest])  # -1: constants
        self._offsets = np.concatenate([[0], np.cumsum(largest)[:-1]]).astype(np.intp)
        self._constants: dict[tuple[int, ...], _ConstantPart | None] = {}

    def of(self, models: Sequence[Sequence[int]]) -> FloatArray:
        """``(len(models), G)``: every model's log evidence at every grid point."""
        out = np.empty((len(models), self.prior.n_grid))
        groups: dict[tuple[tuple[int, ...], int], list[int]] = {}
        layouts = []
        for i, orders in enumerate(models):
            orders = as_orders(orders)
            idx = self.normal.indices(orders)
            constants = tuple(int(self._offsets[k]) for k, n in enumerate(orders) if n > 0)
            layouts.append(idx)
            groups.setdefault((constants, idx.size - len(constants)), []).append(i)
        for (constants, n_h), members in groups.items():
            part = self._constant_part(constants)
            if part is None:
                out[members] = -np.inf
                continue
            out[members] = self._group(part, [layouts[i] for i in members], n_h)
        return out

    def _constant_part(self, constants: tuple[int, ...]) -> _ConstantPart | None:
        if constants not in self._constants:
            self._constants[constants] = _ConstantPart.of(
                self.normal.gram, np.asarray(constants, dtype=np.intp), self.prior.constant_sd_k**2
            )
        return self._constants[constants]

    def _group(self, part: _ConstantPart, layouts: list[NDArray[np.intp]], n_h: int) -> FloatArray:
        """Evidences of models sharing the constant terms and the number of higher terms."""
        normal, prior = self.normal, self.prior
        gram, ref, v_c = normal.gram, normal.reference, self.prior.constant_sd_k**2
        kept = np.zeros((len(layouts), ref.size), dtype=bool)
        for b, idx in enumerate(layouts):
            kept[b, idx] = True
        left_out = np.where(kept, 0.0, ref)  # c_ref,O padded with zeros
        linear = normal.cross + left_out @ gram  # g + G c_ref,O: u's data part, every index
        rr = normal.chi2_ref + 2.0 * left_out @ normal.cross + np.sum(
            (left_out @ gram) * left_out, axis=1
        )
        c = part.indices
        u_c = linear[:, c] - ref[c] / v_c
        k_inv_u = cho_solve(part.factor, u_c.T, check_finite=False).T
        q_c = rr + float(ref[c] @ ref[c]) / v_c - np.sum(u_c * k_inv_u, axis=1)
        t = np.tile(_precisions(prior), len(prior.decays))
        log_v0 = c.size * np.log(v_c) - n_h * np.log(t)  # log|D| cancels against log|Lambda_H|
        if n_h:
            is_higher = kept.copy()
            is_higher[:, c] = False
            h = np.nonzero(is_higher)[1].reshape(len(layouts), n_h)
            schur = part.schur[h[:, :, None], h[:, None, :]]
            p_h = np.take_along_axis(linear - k_inv_u @ gram[c], h, axis=1)
            q_h, log_det_h, bad = _higher_terms(schur, p_h, ref[h], self._power[h], prior)
        else:
            q_h = log_det_h = np.zeros((len(layouts), t.size))
            bad = np.zeros(q_h.shape, dtype=bool)
        q_min = np.maximum(q_c[:, None] + q_h, 0.0)
        occam = -0.5 * (part.log_det + log_det_h) - 0.5 * log_v0
        return np.where(bad, -np.inf, log_evidence_from(normal, q_min, occam, self.scale_prior))


@dataclass(frozen=True)
class _ConstantPart:
    """``K = G_CC + I / v_C`` factored, and the Schur complement of ``G`` about it."""

    indices: NDArray[np.intp]
    factor: tuple[FloatArray, bool]
    log_det: float
    schur: FloatArray

    @classmethod
    def of(cls, gram: FloatArray, c: NDArray[np.intp], v_c: float) -> _ConstantPart | None:
        k = gram[np.ix_(c, c)] + np.eye(c.size) / v_c
        try:
            factor = cho_factor(k, lower=True, check_finite=False)
        except np.linalg.LinAlgError:
            return None
        schur = gram - gram[:, c] @ cho_solve(factor, gram[c], check_finite=False)
        return cls(
            indices=c,
            factor=factor,
            log_det=2.0 * float(np.sum(np.log(np.diag(factor[0])))),
            schur=0.5 * (schur + schur.T),
        )


def _higher_terms(
    schur: FloatArray, p_h: FloatArray, ref_h: FloatArray, power: FloatArray,
    prior: ShrinkagePrior,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The higher terms' ``Q_min`` part, ``log|Lambda_H|`` and bad widths: ``(B, G)`` each.

    ``schur (B, n, n)``, ``p_h``, ``ref_h`` and ``power`` (each term's order less one)
    ``(B, n)``. The prior precision ``t D`` with ``D^(1/2) = d`` gives
    ``S + t D = d (S / d d^T + t I) d``: one eigendecomposition per model and decay, all
    in one call.
    """
    decays = np.asarray(prior.decays)
    d = 1.0 / narrowing(decays[None, :, None], power[:, None, :])  # (B, D, n)
    values, vectors = np.linalg.eigh(schur[:, None] / (d[..., :, None] * d[..., None, :]))
    # Rounding leaves eigenvalues uncertain by ~eps * the largest; below that they are
    # zero (the data leave the direction to the prior), never negative.
    floor = 64 * np.finfo(float).eps * np.maximum(values[..., -1:], 0.0)
    lam = np.maximum(values, floor)[:, :, None, :]  # (B, D, 1, n)
    stacked = np.stack((p_h[:, None] / d, ref_h[:, None] * d), axis=-1)  # (B, D, n, 2)
    rotated = np.swapaxes(vectors, -1, -2) @ stacked
    p, r = rotated[:, :, None, :, 0], rotated[:, :, None, :, 1]
    tt = _precisions(prior)[None, None, :, None]
    denominator = lam + tt  # (B, D, S, n), positive: lam >= 0 and t > 0
    # t lam r^2 + 2 t p r - p^2, with the t-free factors formed before broadcasting over t
    terms = tt * (lam * r * r + 2.0 * p * r) - p * p
    q_h = np.sum(terms / denominator, axis=-1)
    log_det_h = np.sum(np.log(denominator), axis=-1)
    bad = ~np.isfinite(q_h + log_det_h)  # only where the Schur complement held a NaN
    n_models = schur.shape[0]
    return (
        q_h.reshape(n_models, -1), log_det_h.reshape(n_models, -1), bad.reshape(n_models, -1)
    )


def log_scale_density(
    log_tau: FloatArray, prior: ShrinkagePrior, s: float | None
) -> FloatArray:
    """The log density of ``log tau`` under a hyperprior on the prior's range.

    Half-Cauchy of scale ``s`` (K), ``p(tau) = 1 / (1 + (tau/s)^2)`` up to its
    normalisation ``s (atan(tau_max/s) - atan(tau_min/s))``, times the Jacobian ``tau`` of
    ``log tau``; uniform in ``log tau`` where ``s`` is ``None``. ``s`` is
    ``prior.scale_hyperprior_k`` for the marginalised scales, ``width_hyperprior_k`` for
    the fitted ones.
    """
    log_tau = np.asarray(log_tau, dtype=float)
    if s is None:
        return np.full(log_tau.shape, -np.log(np.log(prior.tau_max_k / prior.tau_min_k)))
    mass = s * (np.arctan(prior.tau_max_k / s) - np.arctan(prior.tau_min_k / s))
    return log_tau - np.log1p(np.exp(2.0 * log_tau) / s**2) - np.log(mass)


def log_scale_density_gradient(log_tau: FloatArray, s: float | None) -> FloatArray:
    """The derivative of :func:`log_scale_density` in ``log tau``."""
    log_tau = np.asarray(log_tau, dtype=float)
    if s is None:
        return np.zeros(log_tau.shape)
    r2 = np.exp(2.0 * log_tau) / s**2
    return 1.0 - 2.0 * r2 / (1.0 + r2)


def marginal_log_evidence(grid: FloatArray) -> float:
    """The evidence with ``tau`` marginalised: the mean of the grid's evidences."""
    top = float(np.max(grid))
    if not np.isfinite(top):
        return -np.inf
    return top + float(np.log(np.sum(np.exp(grid - top)) / grid.size))


@lru_cache(maxsize=16)
def _precisions_of(tau_min_k: float, tau_max_k: float, n_scales: int) -> FloatArray:
    return 1.0 / np.geomspace(tau_min_k, tau_max_k, n_scales) ** 2


def _precisions(prior: ShrinkagePrior) -> FloatArray:
    """``t = 1 / tau^2`` on the prior's grid (cached: the search asks for it per model)."""
    return _precisions_of(prior.tau_min_k, prior.tau_max_k, prior.n_scales)
