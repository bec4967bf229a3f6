"""The run's checks: the VNA against its test load, a new solution against a benchmark.

Pure functions of arrays, so each is tested on its own and the runner only records
their verdicts.

* **Test load** (thesis 2.1.1): the MS2-6 50 ohm test load measured after the SOL
  calibration is compared, frequency by frequency, with a reference measurement (a PNA-X
  file): ``d(f) = |S11(f) - S11_ref(f)| / |S11_ref(f)|``. The verdict uses a statistic of
  ``d`` over the band: ``max`` is the thesis's literal reading; ``p95`` (the default) is
  robust to the noise of a -40 dB load, whose relative scatter is a few percent at
  REACH's sweep settings, so that the maximum over 1401 points exceeds 5 % by chance.
* **Benchmark** (thesis 2.1.3: "previous calibration coefficients to within 5 %"): the
  polynomial coefficients depend on the basis and order, so the comparison is made on
  the parameters themselves, band-averaged: ``|<T_new> - <T_ref>| / |<T_ref>|`` for each
  of T_unc, T_cos, T_sin, T_NS, T_L.

RFI flags of calibrated spectra are the engine's (:func:`calibration.checks.rfi.flag_sky`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from calibration.model.noise_waves import PARAMETERS
from calibration.solve.solvers import NoiseWaveSolution

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


@dataclass(frozen=True)
class LoadCheckVerdict:
    """The outcome of one test-load comparison."""

    passed: bool
    statistic: str
    value: float
    tolerance: float
    worst_hz: float


def compare_test_load(
    measured: ComplexArray,
    reference: ComplexArray,
    freq_hz: FloatArray,
    tolerance: float,
    statistic: str = "p95",
    smoothing: int = 21,
) -> LoadCheckVerdict:
    """Compare a measured test load with its reference at the same frequencies."""
    kernel = np.ones(max(1, smoothing)) / max(1, smoothing)
    smoothed = np.convolve(measured, kernel, mode="same")
    edge = max(1, smoothing) // 2
    inner = slice(edge, len(measured) - edge) if len(measured) > 2 * edge else slice(None)
    deviation = np.abs(smoothed[inner] - reference[inner]) / np.abs(reference[inner])
    freq_hz = np.asarray(freq_hz)[inner]
    value = {
        "max": float(np.max(deviation)),
        "p95": float(np.percentile(deviation, 95)),
        "rms": float(np.sqrt(np.mean(deviation**2))),
    }[statistic]
    worst = float(freq_hz[int(np.argmax(deviation))])
    return LoadCheckVerdict(value <= tolerance, statistic, value, tolerance, worst)


@dataclass(frozen=True)
class BenchmarkVerdict:
    """A new solution against a benchmark: relative difference of each band-averaged parameter."""

    passed: bool
    differences: dict[str, float]
    tolerance: float


def compare_with_benchmark(
    solution: NoiseWaveSolution, benchmark: NoiseWaveSolution, freq_hz: FloatArray, tolerance: float
) -> BenchmarkVerdict:
    """Band-averaged parameters of ``solution`` within ``tolerance`` of ``benchmark``'s."""
    new = solution.evaluate(freq_hz).mean(axis=1)
    old = benchmark.evaluate(freq_hz).mean(axis=1)
    differences = {
        name: float(abs(a - b) / abs(b)) for name, a, b in zip(PARAMETERS, new, old, strict=True)
    }
    return BenchmarkVerdict(max(differences.values()) <= tolerance, differences, tolerance)
