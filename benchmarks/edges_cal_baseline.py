"""Adapter running EDGES' iterative calibration (``edges-cal``) on our simulated runs.

The baseline is :func:`edges_cal.noise_waves.get_calibration_quantities_iterative`, the
scheme of Monsalve et al. (2017, M17) that ``edges_cal.CalibrationObservation`` runs. It
uses four loads, which map onto the REACH calibrators as::

    ambient  <- cold       (ambient-temperature matched load)
    hot_load <- hot        (heated matched load)
    open     <- c10open    (open at the end of the 10 m cable)
    short    <- c10short   (short at the end of the 10 m cable)

Conventions (checked against the installed edges-cal 7.1.1 source):

* edges-cal works with the *uncalibrated temperature* ``T* = t_load_ns Q + t_load``
  (``LoadSpectrum.averaged_spectrum``; ``CalibrationObservation.calibrate(q=...)``) with
  the nominal ``t_load = 300 K`` and ``t_load_ns = 400 K`` (the defaults of
  ``edges_cal.simulate.simulate_q`` and of ``temp_amb_internal`` /
  ``calibrated_antenna_temperature(t_load=300)``). ``Q`` is the same Dicke ratio
  ``(P_src - P_L) / (P_NS - P_L)`` as ours.
* Its M17 eq. 7 reads ``T_cal = (T* - t_load) C1 + t_load - C2`` with
  ``T_cal = T_src K1 + T_unc K2 + T_cos K3 + T_sin K4`` (``edges_cal.noise_waves.get_K``).
  With our forward model (:mod:`calibration.model.noise_waves`) this holds exactly for
  ``C1 = T_NS / t_load_ns`` and ``C2 = t_load - T_L``; the noise-wave terms use the same
  ``F``, ``alpha = arg(Gamma F)`` and sign conventions, so no sign flips are needed.
* Reflection coefficients are passed as callables of frequency (MHz, as edges-cal uses).
* A source is calibrated afterwards with edges-cal's own
  :func:`edges_cal.noise_waves.calibrated_antenna_temperature` (M17 eq. 7 inverted).

Settings are those of ``CalibrationObservation``'s defaults: ``cterms=5`` (scale and
offset), ``wterms=7`` (noise waves), ``niter=4``, ``smooth_scale_offset_within_loop=False``,
no cable-delay sweep, no hot-load loss. The fit is an unweighted least squares, as in
edges-cal.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

try:
    from edges_cal import noise_waves as ecnw
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise ImportError(
        "the benchmarks compare against edges-cal: install it with pip install -e '.[bench]'"
    ) from exc

from calibration.model.data import CalibrationData, SourceData

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: edges-cal load name -> REACH calibrator name.
EDGES_LOADS: dict[str, str] = {
    "ambient": "cold",
    "hot_load": "hot",
    "open": "c10open",
    "short": "c10short",
}
#: Nominal internal-load temperature of edges-cal's ``T*`` (K).
T_LOAD_K = 300.0
#: Nominal load + noise-source temperature of edges-cal's ``T*`` (K).
T_LOAD_NS_K = 400.0
#: ``CalibrationObservation`` defaults.
CTERMS = 5
WTERMS = 7
NITER = 4


class TabulatedReflection:
    """A reflection coefficient tabulated on channels, callable at frequencies in MHz.

    edges-cal wants S11 *models* (callables); it only ever evaluates them on the data's
    channels, where linear interpolation returns the tabulated values exactly.
    """

    def __init__(self, freq_mhz: FloatArray, gamma: ComplexArray) -> None:
        self.freq_mhz = np.asarray(freq_mhz, dtype=float)
        self.gamma = np.asarray(gamma, dtype=complex)

    def __call__(self, freq_mhz: Any) -> ComplexArray:
        """Reflection at ``freq_mhz`` (exact on the tabulated channels)."""
        f = np.asarray(freq_mhz, dtype=float)
        if f.shape == self.freq_mhz.shape and np.array_equal(f, self.freq_mhz):
            return self.gamma
        return np.interp(f, self.freq_mhz, self.gamma.real) + 1j * np.interp(
            f, self.freq_mhz, self.gamma.imag
        )


def uncalibrated_temperature(q: FloatArray) -> FloatArray:
    """edges-cal's ``T* = t_load_ns Q + t_load`` (``LoadSpectrum.averaged_spectrum``)."""
    return np.asarray(T_LOAD_NS_K * np.asarray(q, dtype=float) + T_LOAD_K)


@dataclass(frozen=True)
class EdgesCalibration:
    """The result of edges-cal's iterative method: scale, offset and noise waves per channel.

    All curves are evaluated on the run's channels; ``gamma_rec`` is the receiver
    reflection the calibration was derived with.
    """

    freq_hz: FloatArray
    gamma_rec: ComplexArray
    scale: FloatArray
    offset: FloatArray
    t_unc: FloatArray
    t_cos: FloatArray
    t_sin: FloatArray

    def calibrate(self, source: SourceData) -> FloatArray:
        """Calibrated temperature of ``source`` by edges-cal's M17 eq. 7 (K)."""
        return np.asarray(
            ecnw.calibrated_antenna_temperature(
                uncalibrated_temperature(source.q),
                np.asarray(source.gamma, dtype=complex),
                self.gamma_rec,
                self.scale,
                self.offset,
                self.t_unc,
                self.t_cos,
                self.t_sin,
                t_load=T_LOAD_K,
            )
        )

    @property
    def t_ns(self) -> FloatArray:
        """Noise-source temperature implied by the scale, ``C1 t_load_ns`` (K)."""
        return self.scale * T_LOAD_NS_K

    @property
    def t_l(self) -> FloatArray:
        """Internal-load temperature implied by the offset, ``t_load - C2`` (K)."""
        return T_LOAD_K - self.offset


def solve_edges(
    data: CalibrationData,
    cterms: int = CTERMS,
    wterms: int = WTERMS,
    niter: int = NITER,
    loads: dict[str, str] | None = None,
) -> EdgesCalibration:
    """Run edges-cal's iterative method on the four EDGES loads of ``data``.

    ``loads`` maps edges-cal names (``ambient``, ``hot_load``, ``open``, ``short``) to
    calibrator names of ``data`` (default :data:`EDGES_LOADS`). The result of the last
    iteration is kept, as ``CalibrationObservation`` does.
    """
    loads = loads or EDGES_LOADS
    freq_mhz = data.freq_hz / 1e6
    src = {edges: data.sources[ours] for edges, ours in loads.items()}
    temp_raw = {k: uncalibrated_temperature(s.q) for k, s in src.items()}
    temp_ant = {k: np.asarray(s.temperature_k, dtype=float) for k, s in src.items()}
    gamma_rec = TabulatedReflection(freq_mhz, data.gamma_rec)
    gamma_ant = {k: TabulatedReflection(freq_mhz, s.gamma) for k, s in src.items()}
    iterations = ecnw.get_calibration_quantities_iterative(
        freq_mhz,
        temp_raw=temp_raw,
        gamma_rec=gamma_rec,
        gamma_ant=gamma_ant,
        temp_ant=temp_ant,
        cterms=cterms,
        wterms=wterms,
        temp_amb_internal=T_LOAD_K,
        niter=niter,
        hot_load_loss=None,
        smooth_scale_offset_within_loop=False,
        delays_to_fit=np.array([0.0]),
    )
    scale_model, offset_model, nw = deque(iterations, maxlen=1).pop()
    return EdgesCalibration(
        freq_hz=np.asarray(data.freq_hz, dtype=float),
        gamma_rec=np.asarray(data.gamma_rec, dtype=complex),
        scale=np.asarray(scale_model(freq_mhz)),
        offset=np.asarray(offset_model(freq_mhz)),
        t_unc=np.asarray(nw.get_tunc(freq_mhz)),
        t_cos=np.asarray(nw.get_tcos(freq_mhz)),
        t_sin=np.asarray(nw.get_tsin(freq_mhz)),
    )
