"""Frequency-by-frequency noise-wave solvers (thesis sections 4.7 and 4.8).

Instead of polynomials in frequency, the five parameters ``theta = (T_unc, T_cos, T_sin,
T_NS, T_L)`` (order :data:`~calibration.model.noise_waves.PARAMETERS`) are solved independently
at every channel from the ``M`` calibrator equations (eqs. 3.27, 3.28)::

    T_i = x_i^T theta,    x_i = (X_unc, X_cos, X_sin, X_NS, X_L)_i,    i = 1..M

:func:`solve_least_squares_per_channel` is the MATLAB pipeline of section 4.7,
:func:`solve_bayesian_per_channel` the Bayesian solver of section 4.8 (eqs. 4.12-4.24) with
the radiometer-equation covariance of :mod:`calibration.solve.radiometric_solver`. Both are
vectorised over channels (stacked numpy linear algebra on ``(N, M, 5)`` arrays) and need
``M >= 5`` calibrators. A :class:`ChannelSolution` holds one Gaussian per channel; channels
are independent, so between two channels a parameter is ``(1 - t) theta_a + t theta_b``
with covariance ``(1 - t)^2 Sigma_a + t^2 Sigma_b``. Nothing is extrapolated.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import IllPosedError, InvalidDataError
from ..model.data import CalibrationData, SourceData, check_source
from ..model.noise_waves import INDEX, N_PARAMETERS, PARAMETERS, design_terms
from ..model.reflection_noise import reflection_variance
from .radiometric_solver import LinearisedProblem, linearise
from .solution import CalibratedSpectrum

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
Pair = tuple[FloatArray, FloatArray]
LOG_2PI = float(np.log(2 * np.pi))


@dataclass(frozen=True)
class ChannelSolution:
    """Noise-wave parameters solved channel by channel, Gaussian at each channel.

    Attributes
    ----------
    freq_hz
        Solved channels ``(N,)``, strictly increasing.
    mean
        Posterior mean (Bayesian) or least-squares estimate, ``(5, N)`` in K.
    covariance
        Parameter covariance per channel, ``(N, 5, 5)`` in K^2. Infinite on the diagonal
        (zero elsewhere) where it is undefined (least squares with exactly 5 calibrators).
    log_evidence
        Log evidence per channel (eq. 4.22), or ``None`` (least squares).
    method
        ``"least_squares"`` or ``"bayesian"``.
    calibrators
        Names of the calibrators used.
    metadata
        What the solve was made from and how (the run file, the preparation), as for
        :attr:`calibration.solve.solution.Solution.metadata`.
    """

    freq_hz: FloatArray
    mean: FloatArray
    covariance: FloatArray
    log_evidence: FloatArray | None
    method: str
    calibrators: tuple[str, ...] = ()
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        freq = np.asarray(self.freq_hz, dtype=float)
        if freq.ndim != 1 or freq.size < 2 or np.any(~(np.diff(freq) > 0)):
            raise ValueError("freq_hz must be a strictly increasing 1-D array of >= 2 channels")
        n, p = freq.size, N_PARAMETERS
        mean = np.array(self.mean, dtype=float)
        cov = np.array(self.covariance, dtype=float)
        if mean.shape != (p, n) or cov.shape != (n, p, p):
            raise ValueError(
                f"mean {mean.shape}, covariance {cov.shape}: need ({p}, {n}), ({n}, {p}, {p})"
            )
        for name, value in (("freq_hz", freq), ("mean", mean), ("covariance", cov)):
            object.__setattr__(self, name, value)

    @property
    def band_hz(self) -> tuple[float, float]:
        """The first and last solved channel (Hz): the range a calibration may use."""
        return float(self.freq_hz[0]), float(self.freq_hz[-1])

    @property
    def dof(self) -> float:
        """Degrees of freedom of the calibration error's Student-t: ``M - 5`` for least squares.

        The least-squares covariance scales ``(X^T X)^-1`` by the residual variance ``s^2``
        estimated from ``M - 5`` residuals, so its standardised errors are ``t_{M-5}``
        (heavy-tailed for few calibrators); the Bayesian posterior is Gaussian (``inf``).
        """
        m = len(self.calibrators)
        return float(m - N_PARAMETERS) if self.method == "least_squares" and m > 5 else np.inf

    @property
    def finite_covariance(self) -> bool:
        """Whether every channel's covariance is finite (sampling needs it)."""
        return bool(np.all(np.isfinite(self.covariance)))

    def _bracket(self, freq_hz: ArrayLike) -> tuple[FloatArray, IntArray, FloatArray]:
        """Check ``freq_hz``; return it, the solved channel below each, and the weight ``t``."""
        f = np.atleast_1d(np.asarray(freq_hz, dtype=float))
        if f.ndim != 1:
            raise ValueError("frequencies must be a 1-D array")
        lo_hz, hi_hz = float(self.freq_hz[0]), float(self.freq_hz[-1])
        outside = ~((f >= lo_hz) & (f <= hi_hz))
        if np.any(outside):
            raise ValueError(
                f"{int(np.count_nonzero(outside))} frequencies (e.g. "
                f"{float(f[outside][0]) / 1e6:.6f} MHz) lie outside the solved channels "
                f"{lo_hz / 1e6:.6f}-{hi_hz / 1e6:.6f} MHz: a per-channel solution is "
                "interpolated, never extrapolated"
            )
        lo = np.clip(np.searchsorted(self.freq_hz, f, side="right") - 1, 0, self.freq_hz.size - 2)
        t = (f - self.freq_hz[lo]) / (self.freq_hz[lo + 1] - self.freq_hz[lo])
        return f, lo, t

    def _mean_at(self, lo: IntArray, t: FloatArray) -> FloatArray:
        return np.asarray(self.mean[:, lo] * (1.0 - t) + self.mean[:, lo + 1] * t)

    def _covariance_at(self, lo: IntArray, t: FloatArray) -> FloatArray:
        a, b = ((1.0 - t) ** 2)[:, None, None], (t**2)[:, None, None]
        return np.asarray(a * self.covariance[lo] + b * self.covariance[lo + 1])

    def evaluate(self, freq_hz: ArrayLike) -> FloatArray:
        """Parameters ``(5, n)`` in K, linearly interpolated between solved channels.

        Raises ``ValueError`` (naming the solved range) for frequencies outside it.
        """
        _, lo, t = self._bracket(freq_hz)
        return self._mean_at(lo, t)

    def parameter_std(self, freq_hz: ArrayLike) -> FloatArray:
        """Return the std of each interpolated parameter, ``(5, n)`` (``inf`` if undefined)."""
        _, lo, t = self._bracket(freq_hz)
        if not self.finite_covariance:
            return np.full((N_PARAMETERS, lo.size), np.inf)
        cov = self._covariance_at(lo, t)
        return np.asarray(np.sqrt(np.diagonal(cov, axis1=1, axis2=2).T))

    def sample_parameters(self, freq_hz: ArrayLike, n: int, rng: np.random.Generator) -> FloatArray:
        """``n`` draws of the parameters, ``(n, 5, n_freq)``.

        Each solved channel is drawn from its own Gaussian, independently of the others;
        requested frequencies between channels interpolate the draws of their two
        neighbours (so two frequencies sharing a neighbour are correlated, as they should).
        """
        _, lo, t = self._bracket(freq_hz)
        if not self.finite_covariance:
            raise ValueError("the covariance is undefined (infinite): cannot sample")
        needed, pos = np.unique(np.concatenate([lo, lo + 1]), return_inverse=True)
        values, vectors = np.linalg.eigh(self.covariance[needed])
        root = vectors * np.sqrt(np.clip(values, 0.0, None))[:, None, :]
        z = rng.standard_normal((n, needed.size, N_PARAMETERS))
        draws = self.mean[:, needed].T + np.einsum("kpq,nkq->nkp", root, z)
        lo_pos, hi_pos = pos[: lo.size], pos[lo.size :]
        out = draws[:, lo_pos] * (1.0 - t)[:, None] + draws[:, hi_pos] * t[:, None]
        return np.asarray(np.moveaxis(out, 2, 1))

    def calibrate(
        self,
        freq_hz: ArrayLike,
        gamma_rec: ArrayLike,
        source: SourceData,
        channel_width_hz: float | None = None,
        gamma_rec_std: ArrayLike | None = None,
    ) -> CalibratedSpectrum:
        """Calibrate ``source`` (eq. 3.27) channel by channel with its uncertainty.

        ``freq_hz`` are the source's channels: the solution's own or any inside its band
        (the parameters are then linearly interpolated, see :meth:`evaluate`).
        ``T_src = x_src^T theta`` with ``x_src`` the source's design row (eqs. 3.22-3.26);
        ``std_calibration = sqrt(x_src^T Sigma x_src)``. The measurement noise is the
        radiometer model of :meth:`calibration.solve.solution.Solution.calibrate`,
        ``|X_L T_NS| sqrt(var Q_src)``, and zero when ``channel_width_hz`` is ``None``.
        ``gamma_rec_std`` (the run's :attr:`CalibrationData.gamma_rec_std`) and the
        source's own ``gamma_std`` add the VNA's random reflection errors to the
        measurement part, exactly as :meth:`~calibration.solve.solution.Solution.calibrate` does
        (:func:`calibration.model.reflection_noise.reflection_variance`, first order in the
        errors, at the interpolated parameters).
        """
        f, lo, t = self._bracket(freq_hz)
        source = check_source(source, f.size)
        g_rec = np.asarray(gamma_rec, dtype=complex)
        if g_rec.shape != f.shape:
            raise InvalidDataError("gamma_rec does not match freq_hz", source.name)
        terms = design_terms(source.gamma, g_rec)
        rows = terms.matrix(source.q)
        theta = self._mean_at(lo, t)
        mean = np.einsum("fp,pf->f", rows, theta)
        if self.finite_covariance:
            cov = self._covariance_at(lo, t)
            std_cal = np.sqrt(np.einsum("fp,fpq,fq->f", rows, cov, rows))
        else:
            std_cal = np.full(f.shape, np.inf)
        if channel_width_hz is None:
            std_meas = np.zeros(f.shape)
        else:
            var_q = source.q_variance(channel_width_hz)
            std_meas = np.abs(terms.x_l * theta[INDEX["NS"]]) * np.sqrt(var_q)
        radiometer = std_meas
        if source.gamma_std is not None or gamma_rec_std is not None:
            var_gamma = reflection_variance(
                theta, source.gamma, g_rec, source.q, source.gamma_std, gamma_rec_std
            )
            std_meas = np.sqrt(std_meas**2 + var_gamma)

        def draw(n: int, rng: np.random.Generator) -> FloatArray:
            theta = self.sample_parameters(f, n, rng)
            return np.asarray(np.einsum("npf,fp->nf", theta, rows))

        return CalibratedSpectrum(
            f, mean, std_cal, std_meas, self.dof, rows, draw, std_radiometer=radiometer
        )

    def summary(self) -> dict[str, Any]:
        """Plain-data summary, as :meth:`calibration.solve.solution.Solution.summary`.

        ``band_mean_k``: each parameter averaged over the solved channels;
        ``channel_std_k``: the RMS over channels of its per-channel std (the error of one
        channel; channels are independent, so the band average's own std is
        ``sqrt(sum sigma_n^2) / N``, ``band_mean_std_k``); ``log_evidence``: the sum over
        channels of eq. 4.22 (Bayesian; ``None`` for least squares).
        """
        variance = np.diagonal(self.covariance, axis1=1, axis2=2).T  # (5, N)
        n = self.freq_hz.size
        return {
            "method": self.method,
            "kind": "per-channel",
            "band_hz": list(self.band_hz),
            "n_channels": n,
            "calibrators": list(self.calibrators),
            "band_mean_k": dict(zip(PARAMETERS, map(float, self.mean.mean(axis=1)), strict=True)),
            "channel_std_k": dict(
                zip(PARAMETERS, map(float, np.sqrt(variance.mean(axis=1))), strict=True)
            ),
            "band_mean_std_k": dict(
                zip(PARAMETERS, map(float, np.sqrt(variance.sum(axis=1)) / n), strict=True)
            ),
            "log_evidence": None if self.log_evidence is None else float(np.sum(self.log_evidence)),
        }


def solve_least_squares_per_channel(data: CalibrationData) -> ChannelSolution:
    """Ordinary least squares at every channel: the MATLAB pipeline (thesis 4.7).

    At each channel the ``M`` rows ``x_i = (X_unc, X_cos, X_sin, Q_i X_L, X_L)`` of eq.
    3.28 (measured ``Q``, eqs. 3.22-3.26) and the calibrator temperatures ``T_i`` give
    ``theta = X^+ T`` with the Moore-Penrose pseudo-inverse ``X^+`` (from one SVD per
    channel, MATLAB's ``pinv`` tolerance ``max(M, 5) |X| eps``). The covariance is the
    classical OLS one, ``s^2 (X^T X)^-1`` with ``s^2 = |T - X theta|^2 / (M - 5)``:
    unweighted, so it ignores the radiometer noise's differences between calibrators.
    With ``M = 5`` the fit is exact and ``s^2`` undefined: the covariance is then ``inf`` on
    the diagonal (``parameter_std`` is ``inf``, never NaN). ``log_evidence`` is ``None``.

    Raises
    ------
    IllPosedError
        Fewer than 5 calibrators, or a rank-deficient design at some channel.
    """
    if len(data.sources) < N_PARAMETERS:
        got = f"{len(data.sources)} ({', '.join(data.names)})"
        raise IllPosedError(f"a per-channel solution needs at least 5 calibrators; got {got}")
    temps, q, _ = data.stacked()
    x = np.moveaxis(data.terms().matrix(q), 0, 1)  # (N, M, 5)
    y = temps.T  # (N, M)
    u, s, vt = np.linalg.svd(x, full_matrices=False)
    tol = s[:, 0] * max(x.shape[1:]) * np.finfo(float).eps
    deficient = s[:, -1] <= tol
    if np.any(deficient):
        first = float(data.freq_hz[np.argmax(deficient)]) / 1e6
        raise IllPosedError(
            f"the calibrators do not constrain all 5 parameters in {int(deficient.sum())} "
            f"channels (first at {first:.6f} MHz): their design rows are linearly dependent"
        )
    mean = np.einsum("nqp,nq->np", vt, np.einsum("nmq,nm->nq", u, y) / s)
    gram_inverse = np.einsum("nkp,nk,nkq->npq", vt, 1.0 / s**2, vt)
    m = x.shape[1]
    if m > N_PARAMETERS:
        resid = y - np.einsum("nmp,np->nm", x, mean)
        s2 = np.sum(resid**2, axis=1) / (m - N_PARAMETERS)
        cov = s2[:, None, None] * gram_inverse
    else:
        cov = np.broadcast_to(np.diag(np.full(N_PARAMETERS, np.inf)), gram_inverse.shape)
    return ChannelSolution(data.freq_hz, mean.T, cov, None, "least_squares", tuple(data.names))


def _prior_arrays(prior_mean: ArrayLike | None, prior_sd: ArrayLike | None, n: int) -> Pair | None:
    """Prior mean and precision as ``(N, 5)`` arrays, or ``None`` for the uniform prior."""
    if prior_sd is None:
        if prior_mean is not None:
            raise ValueError("a prior mean needs prior_sd (the Gaussian prior's widths)")
        return None
    shape = (N_PARAMETERS, n)

    def expand(value: ArrayLike, what: str) -> FloatArray:
        arr = np.asarray(value, dtype=float)
        if arr.ndim == 0 or arr.shape == (N_PARAMETERS,):
            arr = np.broadcast_to(arr, (N_PARAMETERS,))[:, None]
        if arr.shape not in ((N_PARAMETERS, 1), shape) or not np.all(np.isfinite(arr)):
            raise ValueError(
                f"{what} must be finite, of shape (), (5,) or (5, {n}); got {arr.shape}"
            )
        return np.asarray(np.broadcast_to(arr, shape).T)

    sd = expand(prior_sd, "prior_sd")
    if np.any(sd <= 0):
        raise ValueError("prior_sd must be > 0")
    mean = np.zeros((n, N_PARAMETERS)) if prior_mean is None else expand(prior_mean, "prior_mean")
    return mean, 1.0 / sd**2


def _gaussian_posterior(
    problem: LinearisedProblem, prior: Pair | None
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Mean ``(N, 5)``, covariance ``(N, 5, 5)`` and log evidence ``(N,)`` per channel."""
    x = np.moveaxis(problem.features, 0, 1)  # (N, M, 5)
    w, y = problem.weights.T, problem.response.T  # (N, M): C^-1 = diag(w)
    precision = np.einsum("nmp,nm,nmq->npq", x, w, x)  # eq. 4.15
    rhs = np.einsum("nmp,nm,nm->np", x, w, y)
    if prior is not None:
        precision = precision + prior[1][:, :, None] * np.eye(N_PARAMETERS)
        rhs = rhs + prior[1] * prior[0]
    jacobi = np.sqrt(np.diagonal(precision, axis1=1, axis2=2))
    if not np.all(jacobi > 0):
        raise IllPosedError("a noise-wave parameter has no data constraint at some channel")
    outer = jacobi[:, :, None] * jacobi[:, None, :]
    try:
        chol = np.linalg.cholesky(precision / outer)
    except np.linalg.LinAlgError as err:
        raise IllPosedError(
            "the calibrators do not constrain all 5 parameters at some channel "
            "(posterior precision not positive definite)"
        ) from err
    chol_inv = np.linalg.solve(chol, np.broadcast_to(np.eye(N_PARAMETERS), chol.shape))
    cov = np.einsum("nkp,nkq->npq", chol_inv, chol_inv) / outer
    mean = np.einsum("nkp,nk->np", chol_inv, np.einsum("nkp,np->nk", chol_inv, rhs / jacobi))
    mean = mean / jacobi  # eq. 4.16
    resid = y - np.einsum("nmp,np->nm", x, mean)
    chi2 = np.sum(w * resid**2, axis=1)
    log_det = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)) + np.log(jacobi), axis=1)
    log_z = -0.5 * (x.shape[1] * LOG_2PI - np.sum(np.log(w), axis=1) + chi2 + log_det)
    if prior is None:
        log_z = log_z + 0.5 * N_PARAMETERS * LOG_2PI
    else:
        log_z = log_z - 0.5 * np.sum(prior[1] * (mean - prior[0]) ** 2 - np.log(prior[1]), axis=1)
    return mean, cov, np.asarray(log_z)


def _positive_ns(theta: FloatArray) -> FloatArray:
    """``theta`` as an operating point: a ``T_NS <= 0`` channel takes the others' median.

    A channel learnt from itself alone can be noisy enough for its estimate of ``T_NS``
    to cross zero (few calibrators, short integrations, spectra missing from a cycle);
    linearising there is impossible (:func:`~calibration.solve.radiometric_solver.linearise`),
    yet the diode's ``T_NS`` is ~1000 K and smooth, so the band's median is a start from
    which the Gauss-Newton step finds the channel's own posterior.
    """
    t_ns = theta[INDEX["NS"]]
    bad = ~(t_ns > 0)
    if not np.any(bad):
        return theta
    if np.all(bad):
        raise IllPosedError(
            "the calibrators give T_NS <= 0 K at every channel: no operating point"
        )
    out = theta.copy()
    out[INDEX["NS"], bad] = np.median(t_ns[~bad])
    return out


def solve_bayesian_per_channel(
    data: CalibrationData,
    prior_mean: ArrayLike | None = None,
    prior_sd: ArrayLike | None = None,
    iterations: int = 2,
) -> ChannelSolution:
    """Solve for the parameters channel by channel with the Bayesian solver of thesis 4.8.

    At each channel the likelihood is Gaussian (eqs. 4.12, 4.13),
    ``y ~ N(X theta, C)``, with ``C = diag(1/w)`` an ``M x M`` diagonal covariance (one row
    per calibrator) from the radiometer equation: the Gauss-Newton rows of
    :func:`calibration.solve.radiometric_solver.linearise` about the current estimate
    ``theta_0``::

        y_i = T_i - X_L T_NS0 (Q_i - Q0_i),   x_i = (X_unc, X_cos, X_sin, Q0_i X_L, X_L),
        w_i = 1 / ((X_L T_NS0)^2 var Q_i)

    The start ``theta_0`` is :func:`solve_least_squares_per_channel` (a channel whose
    estimate of T_NS is not positive starts from the other channels' median);
    ``iterations`` Gauss-Newton steps follow (T_NS converges after one or two). The posterior
    (eqs. 4.15, 4.16, 4.24) is Gaussian with::

        Sigma^-1 = X^T C^-1 X + P_0,       mu = Sigma (X^T C^-1 y + P_0 m_0)

    where ``P_0 = diag(1 / prior_sd^2)`` and ``m_0 = prior_mean`` for the optional Gaussian
    prior, and ``P_0 = 0`` for the thesis's uniform prior. Everything is solved by a
    Jacobi-scaled Cholesky factor per channel (no explicit inverse or determinant).

    The log evidence per channel (eq. 4.22, residual form ``y^T C^-1 y - mu^T Sigma^-1 mu
    = chi2 + prior term``) is the evidence of the linearised temperature data ``y``:

    * Gaussian prior: exact, ``log N(y; X m_0, C + X P_0^-1 X^T)``;
    * no prior: the likelihood maximum times its Laplace volume,
      ``log L_max + (5/2) log 2 pi - (1/2) log |Sigma^-1|``, i.e. eq. 4.22 with ``V = 1``.
      The thesis's uniform prior is improper, so this value is only defined up to
      ``-log V`` (V the prior volume in K^5): compare it only between fits sharing V.

    Parameters
    ----------
    data
        The calibration run; needs ``M >= 5`` calibrators (the least-squares start needs
        them, with or without a prior).
    prior_mean, prior_sd
        Gaussian prior of the parameters, each a scalar, ``(5,)`` or ``(5, N)`` (K);
        ``prior_mean`` defaults to zero when only ``prior_sd`` is given. Both ``None``: the
        uniform prior of the thesis.
    iterations
        Gauss-Newton steps (>= 1).
    """
    if iterations < 1:
        raise ValueError("iterations must be >= 1")
    prior = _prior_arrays(prior_mean, prior_sd, data.n_channels)
    theta = solve_least_squares_per_channel(data).mean
    terms = data.terms()
    temps, q, var_q = data.stacked()
    for _ in range(iterations):
        problem = linearise(terms, temps, q, var_q, _positive_ns(theta))
        mean, cov, log_z = _gaussian_posterior(problem, prior)
        theta = mean.T
    return ChannelSolution(data.freq_hz, theta, cov, log_z, "bayesian", tuple(data.names))
