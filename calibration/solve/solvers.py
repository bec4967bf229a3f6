"""The noise-wave solvers by name: one entry point wherever a calibration is made.

``reach-cal solve / validate --method``, the run's ``calibrate`` step (``solver:``) and
the site file's ``calibration.solver`` all name one of :data:`METHODS`:

``radiometric`` (the default)
    Polynomial parameters (eqs. 3.39-3.40) fitted to the measured ``Q`` with the
    radiometer-noise likelihood (:mod:`calibration.solve.radiometric_solver`): per-parameter
    orders chosen by evidence (3.34-3.36), the posterior averaged over the models that
    carry the weight. Works from two calibrators up (identifiability permitting); its
    errors are correlated across channels and reach the radiometer noise floor.
``thesis``
    EXCALIBRATE as published (thesis 3.2-3.3, :mod:`calibration.solve.thesis_solver`):
    polynomials, homoscedastic noise on the calibrator temperatures, ``Q`` in the design
    matrix. The baseline against which the others are judged.
``least-squares``
    Every channel on its own, five parameters from the ``M`` calibrator equations by
    ordinary least squares (the MATLAB pipeline of thesis 4.7,
    :func:`calibration.solve.per_frequency.solve_least_squares_per_channel`). Unweighted;
    with exactly five calibrators the fit is exact and its errors undefined (``inf``).
``bayesian``
    Every channel on its own with the Gaussian likelihood of the radiometer equation and
    a uniform prior (thesis 4.8, eqs. 4.12-4.24,
    :func:`calibration.solve.per_frequency.solve_bayesian_per_channel`): a posterior and an
    evidence per channel.

When to pick which: the polynomial methods are the default, because a smooth receiver
is described by a few dozen coefficients learnt from every channel at once. The
per-channel methods assume nothing about smoothness (structure on the scale of a
channel, a check of the polynomial model), but need at least 5 calibrators, and each
channel's five parameters are learnt from that channel alone: their errors are
uncorrelated between channels and much larger (a simulated REACH run with 12
calibrators at 195 kHz channels: 0.4 K per channel against the polynomial floor's 3 mK;
:func:`calibration.solve.noise_floor.channel_noise_floor` is their own floor). They are cheap
(tens of ms against a second). Orders, order limits and the basis apply to the
polynomial methods only.

Both kinds of solution answer :class:`NoiseWaveSolution`, what every consumer of a
solution (calibrating a source, the figures, the summaries, the run's steps) uses.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol, TypeAlias

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..choice.model_fit import OrderChoice
from ..core.constants import METHODS, PER_CHANNEL_METHODS, POLYNOMIAL_METHODS
from ..core.errors import InvalidDataError
from ..model.basis import BasisKind
from ..model.data import CalibrationData, SourceData
from .noise_floor import NoiseFloor, channel_noise_floor, noise_floor
from .per_frequency import (
    ChannelSolution,
    solve_bayesian_per_channel,
    solve_least_squares_per_channel,
)
from .radiometric_solver import solve_radiometric
from .solution import CalibratedSpectrum, Solution
from .thesis_solver import solve_thesis

__all__ = [
    "METHODS",
    "PER_CHANNEL_METHODS",
    "POLYNOMIAL_METHODS",
    "AnySolution",
    "NoiseWaveSolution",
    "band_hz",
    "method_name",
    "solution_noise_floor",
    "solve",
    "solver",
]

FloatArray = NDArray[np.float64]

#: The solvers by name, the default first.

#: A solution of any solver.
AnySolution: TypeAlias = Solution | ChannelSolution


class NoiseWaveSolution(Protocol):
    """What every solution offers: parameters with errors, draws, calibration, a summary."""

    @property
    def method(self) -> str:
        """The solver that made it (a per-channel one stores ``least_squares``)."""

    @property
    def calibrators(self) -> tuple[str, ...]:
        """The calibrators it was solved from."""

    @property
    def metadata(self) -> Mapping[str, Any]:
        """What it was made from and how."""

    def evaluate(self, freq_hz: FloatArray) -> FloatArray:
        """Parameters ``(5, n)`` in K."""

    def parameter_std(self, freq_hz: FloatArray) -> FloatArray:
        """Standard deviation of each parameter, ``(5, n)``."""

    def sample_parameters(
        self, freq_hz: FloatArray, n: int, rng: np.random.Generator
    ) -> FloatArray:
        """``n`` draws of the parameters, ``(n, 5, n_freq)``."""

    def calibrate(
        self,
        freq_hz: FloatArray,
        gamma_rec: NDArray[np.complex128],
        source: SourceData,
        channel_width_hz: float | None = None,
        gamma_rec_std: FloatArray | None = None,
    ) -> CalibratedSpectrum:
        """A source's calibrated temperature with its errors (eq. 3.27)."""

    def summary(self) -> dict[str, Any]:
        """Plain-data summary."""


def solver(
    method: str = "radiometric",
    choice: OrderChoice | None = None,
    basis_kind: BasisKind | None = None,
) -> Callable[[CalibrationData], AnySolution]:
    """The solve that ``method`` names (:data:`METHODS`), checked before any data is read.

    ``choice`` (fixed orders or the order search's limits) and ``basis_kind`` (default
    Legendre) apply to the polynomial methods; given with a per-channel method they are an
    :class:`~calibration.core.errors.InvalidDataError`, never silently ignored.
    """
    if method not in METHODS:
        raise InvalidDataError(f"unknown solver {method!r}; choose one of {', '.join(METHODS)}")
    if method in PER_CHANNEL_METHODS:
        asked = [what for what, v in (("orders", choice), ("a basis", basis_kind)) if v is not None]
        if asked:
            raise InvalidDataError(
                f"the {method} solver solves each channel on its own: {' and '.join(asked)} "
                f"apply only to the polynomial solvers ({', '.join(POLYNOMIAL_METHODS)})"
            )
        if method == "least-squares":
            return solve_least_squares_per_channel
        return solve_bayesian_per_channel
    kind: BasisKind = basis_kind or "legendre"
    polynomial = solve_radiometric if method == "radiometric" else solve_thesis

    def solve_polynomial(data: CalibrationData) -> AnySolution:
        return polynomial(data, choice, basis_kind=kind)

    return solve_polynomial


def solve(
    data: CalibrationData,
    method: str = "radiometric",
    choice: OrderChoice | None = None,
    basis_kind: BasisKind | None = None,
) -> AnySolution:
    """Solve ``data`` with the solver ``method`` names (module doc; :func:`solver`)."""
    return solver(method, choice, basis_kind)(data)


def refit(solution: AnySolution) -> Callable[[CalibrationData], AnySolution]:
    """A solve that fits ``solution``'s own model to other data (its method, orders, basis).

    Radiometric: the evidence-best orders as one model (no average; terms the data leave to
    the prior allowed, as in the solution itself); thesis: its orders; per channel: the same
    per-channel solver. The refits of :mod:`calibration.checks.vna_systematics` use it.
    """
    name = method_name(solution)
    if isinstance(solution, ChannelSolution):
        return solver(name)
    choice = OrderChoice.fixed(solution.best_orders)
    kind = solution.basis.kind
    if name == "radiometric":
        return lambda data: solve_radiometric(
            data, choice, basis_kind=kind, average=False, allow_prior_dominated=True
        )
    return solver(name, choice, kind)


def method_name(solution: AnySolution) -> str:
    """The solver's name in :data:`METHODS` (a per-channel solution stores ``least_squares``)."""
    return solution.method.replace("_", "-")


def band_hz(solution: AnySolution) -> tuple[float, float]:
    """The band a solution may calibrate: its basis's, or its first and last channel."""
    if isinstance(solution, ChannelSolution):
        return solution.band_hz
    return solution.basis.f_lo_hz, solution.basis.f_hi_hz


def solution_noise_floor(
    solution: AnySolution,
    data: CalibrationData,
    source: SourceData,
    theta: ArrayLike | None = None,
    own_reflection: bool = True,
) -> NoiseFloor:
    """The radiometer floor of ``source`` for ``solution``'s own kind of model.

    Polynomial: :func:`~calibration.solve.noise_floor.noise_floor` at the orders of the
    model the solution uses (:attr:`~calibration.solve.solution.Solution.orders_used`, the
    heaviest of an average), not at the envelope of the models averaged: every term of
    that envelope (up to the box's edge) would count in the Fisher information, and a
    floor for a model of 40 coefficients where 15 are used reads the distance to it low;
    per channel: :func:`~calibration.solve.noise_floor.channel_noise_floor`. Either is
    evaluated at ``solution``'s mean unless ``theta`` (``(5, N)`` on ``data``'s channels,
    per channel only) is given.
    """
    if isinstance(solution, ChannelSolution):
        at = solution.evaluate(data.freq_hz) if theta is None else np.asarray(theta, float)
        return channel_noise_floor(data, source, at, own_reflection=own_reflection)
    parameters = solution.parameters
    used = solution.orders_used
    if used != parameters.orders and all(
        n <= m for n, m in zip(used, parameters.orders, strict=True)
    ):
        parameters = parameters.truncated(used)
    return noise_floor(data, source, parameters, own_reflection=own_reflection)
