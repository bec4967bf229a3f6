"""The calibration solution file: its layout, written atomically and read back with every check.

A solution file holds one fitted calibration (a polynomial ``Solution`` or a per-channel
``ChannelSolution``); ``read_solution`` refuses, naming the file and what is wrong, any file
whose layout, numbers or metadata do not hold up. The calibrated spectra written from a
solution (``format = "reach-calibrated-spectrum"``) are here too. The run files, the common
root attributes and the atomic writes they share are in :mod:`calibration.io.hdf5_io`.

Solution files (``format = "reach-calibration-solution"``): root attributes ``method``,
``measurement_model``, ``calibrators``, ``metadata`` (JSON); ``/basis`` attributes ``kind``,
``f_lo_hz``, ``f_hi_hz``; ``/posterior`` datasets ``orders`` (5 ints: unc, cos, sin, NS, L),
``mean`` (K), ``scale`` (K^2), attributes ``dof``, ``log_evidence``, ``noise_variance``,
``chi2``, ``n_rows``; ``/evidence`` datasets ``orders`` (n_models, 5) and ``log_evidence``.
A model-averaged posterior (:class:`~calibration.choice.averaging.MixturePosterior`) also has
``/posterior/components``: dataset ``weights`` and one group ``0``, ``1``, ... per component,
each laid out as ``/posterior`` itself (its own orders), so that draws read back come from
the mixture, not from a Gaussian with its moments. The root attribute ``solution_kind`` is
``"polynomial"`` for this layout (files without it are polynomial) and ``"per-channel"``
for a :class:`~calibration.solve.per_frequency.ChannelSolution`: root attributes ``method``
(``least_squares`` or ``bayesian``), ``calibrators``, ``metadata``; ``/channels`` datasets
``frequencies`` (Hz, ``(N,)``), ``mean`` (K, ``(5, N)``), ``covariance`` (K^2,
``(N, 5, 5)``, ``inf`` on the diagonal where undefined) and, for the Bayesian solver,
``log_evidence`` (nats, ``(N,)``); attribute ``parameters`` (the order of the five).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..choice.averaging import MixturePosterior
from ..core.errors import FileFormatError
from ..model.basis import DelayBasis, PolynomialBasis
from ..model.noise_waves import N_PARAMETERS, PARAMETERS
from ..regression.conjugate import LinearPosterior
from ..solve.per_frequency import ChannelSolution
from ..solve.solution import (
    CalibratedSpectrum,
    Solution,
    metadata_problems,
    posterior_problems,
)
from .hdf5_io import (
    _POSTERIOR_FLOATS,
    CALIBRATED_FORMAT,
    INTERVAL_DESCRIPTION,
    PER_CHANNEL_KIND,
    POLYNOMIAL_KIND,
    SOLUTION_FORMAT,
    PathLike,
    _array,
    _atomic_h5,
    _attr,
    _basis,
    _dataset,
    _group,
    _json,
    _metadata,
    _names,
    _number,
    _open,
    _orders,
    attr_text,
)


def write_solution(path: PathLike, solution: Solution | ChannelSolution) -> None:
    """Write a solution of any solver (atomically); :func:`read_solution` restores it exactly."""
    with _atomic_h5(path, SOLUTION_FORMAT) as f:
        write_solution_group(f, solution)


def write_solution_group(f: Any, solution: Solution | ChannelSolution) -> None:
    """Write a solution's layout (module docstring) into an open HDF5 file or group ``f``."""
    f.attrs.update({"method": solution.method, "calibrators": list(solution.calibrators)})
    f.attrs["metadata"] = _json(solution.metadata)
    if isinstance(solution, ChannelSolution):
        f.attrs["solution_kind"] = PER_CHANNEL_KIND
        g = f.create_group("channels")
        g.attrs["parameters"] = list(PARAMETERS)
        _dataset(g, "frequencies", solution.freq_hz, "Hz")
        _dataset(g, "mean", solution.mean, "K")
        _dataset(g, "covariance", solution.covariance, "K^2")
        if solution.log_evidence is not None:
            _dataset(g, "log_evidence", solution.log_evidence, "nats")
        return
    f.attrs["solution_kind"] = POLYNOMIAL_KIND
    post, basis = solution.posterior, solution.basis
    f.attrs["measurement_model"] = solution.measurement_model
    b = f.create_group("basis")
    b.attrs.update({"kind": basis.kind, "f_lo_hz": basis.f_lo_hz, "f_hi_hz": basis.f_hi_hz})
    if isinstance(basis, DelayBasis):  # polynomials then delay terms (solve.delay_terms)
        b.attrs["polynomial_terms"] = basis.polynomial_terms
        b.attrs["delays_s"] = np.asarray(basis.delays_s, dtype=float)
    g = f.create_group("posterior")
    _write_posterior(g, post, solution.measurement_model)
    if isinstance(post, MixturePosterior):
        mix = g.create_group("components")
        _dataset(mix, "weights", post.weights, "1")
        for i, component in enumerate(post.components):
            _write_posterior(mix.create_group(str(i)), component, solution.measurement_model)
    table = solution.evidence_table
    ev = f.create_group("evidence")
    rows = np.array(list(table), dtype=np.int64).reshape(len(table), N_PARAMETERS)
    _dataset(ev, "orders", rows, "terms")
    _dataset(ev, "log_evidence", np.array(list(table.values()), dtype=float), "nats")


def _write_posterior(g: Any, post: LinearPosterior, measurement_model: str) -> None:
    g.attrs.update({k: float(getattr(post, k)) for k in _POSTERIOR_FLOATS})
    g.attrs.update({"n_rows": int(post.n_rows), "parameters": list(PARAMETERS)})
    g.attrs["noise_variance_units"] = (
        "K^2" if measurement_model == "homoscedastic" else "1 (scale of var Q)"
    )
    _dataset(g, "orders", np.asarray(post.orders, dtype=np.int64), "terms")
    _dataset(g, "mean", post.mean, "K")
    _dataset(g, "scale", post.scale, "K^2")


def _read_posterior(g: Any, path: PathLike) -> LinearPosterior:
    orders = _orders(_array(g, "orders", path), path)
    mean = _array(g, "mean", path).astype(float)
    scale = _array(g, "scale", path).astype(float)
    n = sum(orders)
    if mean.shape != (n,) or scale.shape != (n, n):
        raise FileFormatError(f"{path}: posterior mean/scale do not match orders {orders}")
    dof, logz, noise, chi2 = (_number(g, k, path) for k in _POSTERIOR_FLOATS)
    n_rows = _number(g, "n_rows", path)
    if n_rows != int(n_rows):
        raise FileFormatError(f"{path}: attribute 'n_rows' on '{g.name}' is not an integer")
    posterior = LinearPosterior(orders, mean, scale, dof, logz, noise, chi2, int(n_rows))
    problems = posterior_problems(posterior)
    if problems:
        raise FileFormatError(f"{path}: posterior '{g.name}': {'; '.join(problems)}")
    if "components" not in g:
        return posterior
    mix = _group(g, "components", path)
    weights = _array(mix, "weights", path).astype(float)
    good = weights.ndim == 1 and weights.size >= 1 and np.all(np.isfinite(weights))
    if not (good and np.all(weights >= 0) and abs(weights.sum() - 1.0) < 1e-6):
        raise FileFormatError(f"{path}: '{mix.name}/weights' are not >= 0 summing to 1")
    components = tuple(
        _read_posterior(_group(mix, str(i), path), path) for i in range(weights.size)
    )
    if any(any(a > b for a, b in zip(c.orders, orders, strict=True)) for c in components):
        raise FileFormatError(f"{path}: a mixture component exceeds the envelope {orders}")
    return MixturePosterior(**vars(posterior), components=components, weights=weights)


def _delays(group: Any, basis: PolynomialBasis, path: PathLike) -> PolynomialBasis:
    """``basis`` with the delay terms the group records (:class:`DelayBasis`), if any."""
    if "delays_s" not in group.attrs:
        return basis
    try:
        return DelayBasis(
            basis.kind, basis.f_lo_hz, basis.f_hi_hz, int(group.attrs["polynomial_terms"]),
            tuple(float(d) for d in np.atleast_1d(group.attrs["delays_s"])),
        )
    except (KeyError, TypeError, ValueError) as err:
        raise FileFormatError(f"{path}: bad delay terms on '{group.name}': {err}") from err


def read_solution(path: PathLike) -> Solution | ChannelSolution:
    """Read a solution written by :func:`write_solution`: whichever kind it holds."""
    with _open(path, SOLUTION_FORMAT) as f:
        return read_solution_group(f, path)


def read_solution_group(f: Any, path: PathLike) -> Solution | ChannelSolution:
    """Read a solution from the open HDF5 file or group ``f``; errors name ``path``."""
    kind = attr_text(f.attrs.get("solution_kind", POLYNOMIAL_KIND))
    if kind == PER_CHANNEL_KIND:
        return _read_channel_solution(f, path)
    if kind != POLYNOMIAL_KIND:
        known = f"{POLYNOMIAL_KIND!r} or {PER_CHANNEL_KIND!r}"
        raise FileFormatError(f"{path}: unknown solution_kind {kind!r} (expected {known})")
    basis = _delays(_group(f, "basis", path), _basis(_group(f, "basis", path), path), path)
    posterior = _read_posterior(_group(f, "posterior", path), path)
    ev = _group(f, "evidence", path)
    ev_orders = _array(ev, "orders", path)
    ev_logz = _array(ev, "log_evidence", path).astype(float)
    if ev_orders.shape != (ev_logz.size, N_PARAMETERS):
        raise FileFormatError(f"{path}: evidence orders {ev_orders.shape} vs log_evidence")
    if np.any(np.isnan(ev_logz) | (ev_logz == np.inf)):  # -inf: a model the data left free
        raise FileFormatError(f"{path}: evidence log_evidence holds NaN or +inf")
    table = {_orders(o, path): float(z) for o, z in zip(ev_orders, ev_logz, strict=True)}
    model = attr_text(_attr(f, "measurement_model", path))
    if model not in ("radiometer", "homoscedastic"):
        raise FileFormatError(f"{path}: unknown measurement_model {model!r}")
    method, calibrators = attr_text(_attr(f, "method", path)), _names(f, "calibrators")
    return Solution(
        method,
        basis,
        posterior,
        "radiometer" if model == "radiometer" else "homoscedastic",
        table,
        tuple(calibrators or ()),
        _solution_metadata(f, path),
    )


def _read_channel_solution(f: Any, path: PathLike) -> ChannelSolution:
    g = _group(f, "channels", path)
    freq = _array(g, "frequencies", path, "f")
    mean = _array(g, "mean", path, "f")
    cov = _array(g, "covariance", path, "f")
    log_z = _array(g, "log_evidence", path, "f") if "log_evidence" in g else None
    if log_z is not None and log_z.shape != freq.shape:
        raise FileFormatError(f"{path}: channels/log_evidence {log_z.shape} vs {freq.shape}")
    method = attr_text(_attr(f, "method", path))
    if method not in ("least_squares", "bayesian"):
        raise FileFormatError(f"{path}: unknown per-channel method {method!r}")
    try:
        solution = ChannelSolution(
            freq,
            mean,
            cov,
            log_z,
            method,
            tuple(_names(f, "calibrators") or ()),
            _solution_metadata(f, path),
        )
    except ValueError as err:
        raise FileFormatError(f"{path}: bad per-channel solution: {err}") from err
    variances = np.diagonal(solution.covariance, axis1=1, axis2=2)
    bad = not np.all(np.isfinite(solution.mean)) or np.any(np.isnan(solution.covariance))
    if bad or np.any(variances < 0) or not np.all(np.isfinite(solution.freq_hz)):
        raise FileFormatError(
            f"{path}: per-channel solution with NaN or infinite means or frequencies, or "
            "negative variances"
        )
    return solution


def _solution_metadata(f: Any, path: PathLike) -> dict[str, Any]:
    """A solution's metadata, with the entries the commands read checked."""
    metadata = _metadata(f, path)
    problems = metadata_problems(metadata)
    if problems:
        raise FileFormatError(f"{path}: metadata: {'; '.join(problems)}")
    return metadata


def write_calibrated(
    path: PathLike, spectrum: CalibratedSpectrum, source: str, attrs: dict[str, Any] | None = None
) -> None:
    """Write a calibrated spectrum: ``frequencies`` (Hz), ``mean``, the stds and intervals (K).

    ``lower_68``/``upper_68`` and ``lower_95``/``upper_95`` are the central credible
    intervals of the full predictive (:meth:`CalibratedSpectrum.interval`): for a
    model-averaged solution the mixture's quantiles, which the stds alone do not give.
    With the VNA's systematic error attached, ``std_systematic`` and its Monte-Carlo
    draws (``systematic_draws``, deviations from ``mean``) go beside them.
    ``std_model_choice`` is the part of ``std_calibration`` that is the choice of model
    (zero for one model), ``model_choice_share`` its share of the calibration variance.
    """
    with _atomic_h5(path, CALIBRATED_FORMAT) as f:
        f.attrs.update(
            {
                **dict(attrs or {}),
                "source": source,
                "dof": float(spectrum.dof),
                "model_choice_share": spectrum.model_choice_share,
            }
        )
        _dataset(f, "frequencies", spectrum.freq_hz, "Hz")
        for name in ("mean", "std", "std_calibration", "std_measurement", "std_model_choice"):
            _dataset(f, name, getattr(spectrum, name), "K")
        for name, values in spectrum.intervals().items():
            _dataset(f, name, values, "K").attrs["description"] = INTERVAL_DESCRIPTION
        if spectrum.systematic is not None:
            _dataset(f, "std_systematic", spectrum.std_systematic, "K")
            _dataset(f, "systematic_draws", spectrum.systematic, "K")
