"""The VNA's data-sheet accuracy (thesis table 2.3) carried into a calibration's error bars.

:mod:`calibration.model.reflection_noise` carries the VNA's *random* error (each sweep's trace
noise, independent per channel, read off the sweep itself). This module carries its
*systematic* error: what the data sheet allows a calibrated reading to be off by, an
error the sweep cannot show because it is smooth in frequency and the same in every
sweep of the same device.

Model. Every reflection the calibration uses (each calibrator's ``Gamma_i``, the LNA's
``Gamma_rec`` and the calibrated source's own) is off from the truth by ``dGamma(f)``, a
circular complex Gaussian process: per component the standard deviation of
:meth:`~calibration.model.measurement_uncertainty.VnaAccuracy.sigma_magnitude` (table 2.3, eq.
2.2, the bound read as ``coverage`` standard deviations), correlated over frequency as
``exp(-d^2 / 2 c^2)`` at a distance ``d`` (``c = correlation_hz``). The data sheet gives no
correlation length; a VNA's calibrated error follows its standards' models and the
residual directivity and source match, which vary over several MHz, so the default is
5 MHz (a choice, stated in every result; :func:`reflection_systematics` takes another).
The errors of different devices are independent: each is its own connection measured
against the same calibration, whose residual terms it meets with its own reflection.

Propagation (Monte Carlo, as EDGES does for its S11s, Monsalve et al. 2017, ApJ 835 49):
for draws ``k = 1..K`` every reflection is replaced by ``Gamma + dGamma_k``, the run is
solved again with the solution's model held fixed (same orders, so the spread is the
reflections' alone, not the model choice's), and the source is calibrated with its own
and the LNA's perturbed reflections (eq. 3.27). The spread over draws of the calibrated
temperature, ``T_k(f) - T_0(f)`` with ``T_0`` the unperturbed solve, is the systematic
error: correlated across channels, so :class:`ReflectionSystematics` keeps the draws
themselves and :meth:`CalibratedSpectrum.with_systematics` uses them for samples.

A calibrator temperature that is itself computed from a reflection (a cable's available
gain) keeps its nominal value in every draw: that dependence is second order.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..core.constants import DEFAULT_CORRELATION_HZ
from ..core.errors import InvalidDataError
from ..model.data import CalibrationData, SourceData
from ..model.measurement_uncertainty import VnaAccuracy, sample_reflections
from ..solve.solution import CalibratedSpectrum

__all__ = [
    "DEFAULT_CORRELATION_HZ",
    "ReflectionSystematics",
    "reflection_systematics",
]

FloatArray = NDArray[np.float64]



class Calibrates(Protocol):
    """What a solution must do here: calibrate a source (eq. 3.27)."""

    def calibrate(
        self, freq_hz: FloatArray, gamma_rec: NDArray[np.complex128], source: SourceData
    ) -> CalibratedSpectrum: ...


Resolve = Callable[[CalibrationData], Calibrates]


@dataclass(frozen=True)
class ReflectionSystematics:
    """The VNA systematic error of calibrated sources, from ``deviations``.

    ``deviations[name]`` is ``(K, n_channels)``: each draw's calibrated temperature less
    the unperturbed one (K). ``std_k`` is their root mean square about zero per channel
    (the error of the unperturbed calibration), ``bias_k`` their mean: the Monte-Carlo's
    own noise, about ``std_k / sqrt(K)``, plus the calibration's second-order response to
    the reflections (``1 - |Gamma|^2`` grows by ``2 sigma^2`` on average under an error of
    ``sigma`` per component), small beside ``std_k`` for the data sheet's errors.
    """

    freq_hz: FloatArray
    deviations: Mapping[str, FloatArray]
    accuracy: VnaAccuracy
    correlation_hz: float

    @property
    def draws(self) -> int:
        """Number of Monte-Carlo draws."""
        return int(next(iter(self.deviations.values())).shape[0])

    def std_k(self, name: str) -> FloatArray:
        """Systematic error of ``name``'s calibrated temperature (RMS, K), per channel."""
        return np.asarray(np.sqrt(np.mean(self.deviations[name] ** 2, axis=0)))

    def bias_k(self, name: str) -> FloatArray:
        """Mean deviation over the draws, per channel."""
        return np.asarray(np.mean(self.deviations[name], axis=0))

    def describe(self) -> str:
        """One line: the model's settings."""
        return (
            f"VNA accuracy (table 2.3, bound = {self.accuracy.coverage:g} sigma), "
            f"correlated over {self.correlation_hz / 1e6:g} MHz, {self.draws} draws"
        )


def _correlation_channels(freq_hz: FloatArray, correlation_hz: float) -> float:
    step = float(np.median(np.diff(freq_hz)))
    return correlation_hz / step


def _perturbed(
    data: CalibrationData, draw: Callable[[NDArray[np.complex128]], NDArray[np.complex128]]
) -> CalibrationData:
    sources = {
        name: dataclasses.replace(src, gamma=draw(src.gamma)) for name, src in data.sources.items()
    }
    return dataclasses.replace(data, sources=sources, gamma_rec=draw(data.gamma_rec))


def reflection_systematics(
    data: CalibrationData,
    targets: Mapping[str, SourceData],
    resolve: Resolve,
    rng: np.random.Generator | int | None = 0,
    n_draws: int = 64,
    accuracy: VnaAccuracy | None = None,
    correlation_hz: float = DEFAULT_CORRELATION_HZ,
) -> ReflectionSystematics:
    """Monte-Carlo the VNA's data-sheet error through ``resolve`` onto ``targets``.

    ``resolve`` solves a run with the model held fixed (for a polynomial solution, its
    orders: :func:`calibration.solve.solvers.refit`); ``targets`` are the sources to
    calibrate, on ``data``'s channels. Each draw costs one solve (about 60 ms for 12
    calibrators x 6554 channels with the radiometric solver), so 64 draws take seconds.
    """
    if n_draws < 2:
        raise InvalidDataError("the VNA systematics need at least 2 draws")
    if not correlation_hz >= 0:
        raise InvalidDataError("the VNA error's correlation length must be >= 0 Hz")
    accuracy = accuracy or VnaAccuracy()
    rng = np.random.default_rng(rng)
    freq = data.freq_hz
    corr = _correlation_channels(freq, correlation_hz)

    def draw(gamma: NDArray[np.complex128]) -> NDArray[np.complex128]:
        return sample_reflections(gamma, rng, 1, accuracy, corr)[0]

    def calibrated(
        run: CalibrationData, sources: Mapping[str, SourceData]
    ) -> dict[str, FloatArray]:
        solution = resolve(run)
        return {
            name: solution.calibrate(freq, run.gamma_rec, src).mean for name, src in sources.items()
        }

    nominal = calibrated(data, targets)
    deviations: dict[str, list[FloatArray]] = {name: [] for name in targets}
    for _ in range(n_draws):
        run = _perturbed(data, draw)
        moved = {
            name: dataclasses.replace(src, gamma=draw(src.gamma)) for name, src in targets.items()
        }
        for name, temps in calibrated(run, moved).items():
            deviations[name].append(temps - nominal[name])
    return ReflectionSystematics(
        freq, {name: np.asarray(d) for name, d in deviations.items()}, accuracy, correlation_hz
    )
