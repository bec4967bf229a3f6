"""Credible intervals of a model-averaged spectrum: the mixture's quantiles, per channel.

Under model averaging (:mod:`calibration.choice.averaging`) the calibrated temperature of a
channel ``i`` is not one Student-t but a mixture of one per model ``m``, each linear in
that model's coefficients (``T_i = r_i . c``)::

    F_i(x) = sum_m w_m T_nu_m((x - mu_mi) / s_mi)

with ``mu_mi = r_i . mu_m`` and ``s_mi`` the component's scale on that channel. Its
central interval at level ``L`` is ``[F_i^-1((1 - L)/2), F_i^-1((1 + L)/2)]`` (Gelman et
al. 2013, *Bayesian Data Analysis*, 3rd ed., sec. 2.3). The moment summary
``mean +- z sd`` is that interval only for one component: where the models disagree the
mixture is heavier-tailed than its moments' Gaussian (or bimodal), and the 68 % interval
of the moments is too wide, the 95 % one wrong either way.

Errors beside the calibration's (the source's own noise, the VNA's), independent of the
model, widen every component: each keeps its degrees of freedom and takes the summed
variance, as the single-model interval does (:meth:`CalibratedSpectrum.interval
<calibration.solve.solution.CalibratedSpectrum.interval>`), to which this reduces for one
component. The quantile is found per channel by Newton's method on ``F_i`` kept inside a
bracket that always holds it: ``F_i`` lies between the components' own CDFs, so the
quantile lies between the smallest and the largest component quantile.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..model.polynomial_model import full_indices
from .averaging import MixturePosterior

FloatArray = NDArray[np.float64]

#: Newton's iterations at most (each halves the bracket at worst; 60 reach machine precision).
MAX_ITERATIONS = 60
#: Stop where ``|F(x) - q|`` is below this...
TOLERANCE = 1e-12
#: ...or where the step is below this share of ``|x| + 1 K``: machine precision.
RESOLUTION = 1e-13


@dataclass(frozen=True)
class ChannelMixture:
    """Per-channel components: weights ``(M,)``, means and variances ``(M, N)``, dofs ``(M,)``.

    ``variances`` are the calibration error's alone; ``dofs`` may be ``inf`` (Gaussian).
    """

    weights: FloatArray
    means: FloatArray
    variances: FloatArray
    dofs: FloatArray

    def quantile(self, q: float, extra_variance: FloatArray) -> FloatArray:
        """``F_i^-1(q)`` per channel, every component widened by ``extra_variance`` ``(N,)``."""
        scales = self._scales(extra_variance)
        standard = np.array([_ppf(q, nu) for nu in self.dofs])[:, None]
        component_quantiles = self.means + standard * scales
        lo, hi = component_quantiles.min(axis=0), component_quantiles.max(axis=0)
        x = self.weights @ component_quantiles  # a start inside the bracket
        active = np.flatnonzero(hi > lo)  # one component, or all alike: x is the answer
        for _ in range(MAX_ITERATIONS):
            if active.size == 0:
                break
            cdf, pdf = self._cdf_pdf(x[active], self.means[:, active], scales[:, active])
            miss = cdf - q
            xa, la, ha = x[active], lo[active], hi[active]
            ha = np.where(miss > 0, xa, ha)
            la = np.where(miss < 0, xa, la)
            with np.errstate(divide="ignore", invalid="ignore"):
                step = xa - miss / pdf
            inside = np.isfinite(step) & (step >= la) & (step <= ha)
            converged = np.abs(miss) < TOLERANCE
            new = np.where(converged, xa, np.where(inside, step, 0.5 * (la + ha)))
            x[active], lo[active], hi[active] = new, la, ha
            done = converged | (np.abs(new - xa) <= RESOLUTION * (np.abs(xa) + 1.0))
            active = active[~done]
        return x

    def between_variance(self) -> FloatArray:
        """The spread of the components' means, ``sum_m w_m (mu_mi - mu_i)^2`` ``(N,)``.

        The part of the mixture's variance that is the choice of model: the rest,
        ``sum_m w_m s_mi^2`` (``variances``), each model's own (the law of total variance).
        """
        centre = self.weights @ self.means
        return np.asarray(self.weights @ (self.means - centre[None, :]) ** 2)

    def _scales(self, extra_variance: FloatArray) -> FloatArray:
        """Each component's Student-t scale with the extra variance joined: ``(M, N)``."""
        total = self.variances + np.asarray(extra_variance)[None, :]
        finite = np.isfinite(self.dofs) & (self.dofs > 2.0)  # variance = scale^2 nu/(nu-2)
        ratio = np.ones_like(self.dofs)
        ratio[finite] = (self.dofs[finite] - 2.0) / self.dofs[finite]
        return np.sqrt(np.maximum(total, 0.0) * ratio[:, None])

    def _cdf_pdf(
        self, x: FloatArray, means: FloatArray, scales: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """The mixture's CDF and density at ``x`` ``(n,)`` from components ``(M, n)``."""
        from scipy import special, stats
        point = scales == 0.0  # a component with no spread: a step at its mean
        safe = np.where(point, 1.0, scales)
        t = np.where(point, np.where(x >= means, np.inf, -np.inf), (x - means) / safe)
        nu = self.dofs[:, None]
        gaussian = np.isinf(nu)
        finite_nu = np.where(gaussian, 1.0, nu)
        cdf = np.where(gaussian, special.ndtr(t), special.stdtr(finite_nu, t))
        density = np.where(gaussian, stats.norm.pdf(t), stats.t.pdf(t, finite_nu))
        density = np.where(point, 0.0, density / safe)
        return self.weights @ cdf, self.weights @ density


def _ppf(q: float, nu: float) -> float:
    from scipy import stats
    return float(stats.norm.ppf(q) if np.isinf(nu) else stats.t.ppf(q, nu))


def channel_mixture(posterior: MixturePosterior, rows: FloatArray) -> ChannelMixture:
    """The components of ``posterior`` on the channels whose design rows are ``rows``.

    ``rows`` ``(N, P)`` in the envelope's layout (``posterior.orders``); each component
    reads its own coefficients' columns.
    """
    means, variances = [], []
    for component in posterior.components:
        r = rows[:, full_indices(component.orders, posterior.orders)]
        means.append(r @ component.mean)
        variances.append(np.sum((r @ component.covariance) * r, axis=1))
    return ChannelMixture(
        np.asarray(posterior.weights, dtype=float),
        np.array(means),
        np.maximum(np.array(variances), 0.0),
        np.array([c.dof for c in posterior.components], dtype=float),
    )


def central_interval(
    mixture: ChannelMixture, extra_variance: FloatArray, level: float
) -> tuple[FloatArray, FloatArray]:
    """The central interval at ``level`` per channel (module docstring)."""
    tail = 0.5 * (1.0 - level)
    return mixture.quantile(tail, extra_variance), mixture.quantile(1.0 - tail, extra_variance)
