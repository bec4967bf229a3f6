"""Host-side one-port calibration: raw sweeps of the standards, corrected by the engine.

The instrument's own SOL (:meth:`Vna.calibrate_sol`) assumes whichever kit it was told
(``SENS1:CORR:COLL:CKIT``) and keeps its error terms inside the instrument, where no run
file can see them. Done on the host, the raw (uncorrected) sweeps of the three standards
are kept, the error terms come from :func:`calibration.rf.one_port.solve_one_port` with any
kit description (:class:`calibration.rf.cal_kit.CalKit`: offset delay, loss and impedance,
open capacitance and short inductance polynomials, load resistance), and every later raw
sweep ``m`` is corrected with the one-port error model (directivity ``e00``, source match
``e11``, tracking ``e10e01``; Hiebel, *Fundamentals of Vector Network Analysis*, ch. 7)::

    Gamma = (m - e00) / (e10e01 + e11 (m - e00))

Kept raw, a calibration can be redone offline with a better kit model, which an
instrument-side calibration cannot.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from calibration.rf.cal_kit import IDEAL_KIT, STANDARD_NAMES, CalKit
from calibration.rf.one_port import OnePortTerms, solve_one_port
from reach_receiver.devices.vna import Vna
from reach_receiver.devices.vna_settings import S11Measurement
from reach_receiver.errors import DeviceError

ComplexArray = NDArray[np.complex128]

#: Raw readings of two different standards closer than this (linear reflection units) mean
#: the same thing was measured twice (a stuck MS2 switch): ideal standards differ by 1 to
#: 2 in reflection, which the path's tracking (|e10e01| well above 0.1 on REACH's short
#: cables) keeps far above it, and sweep noise (~1e-3) far below it.
MIN_RAW_SEPARATION = 0.02


@dataclass(frozen=True)
class HostCalibration:
    """Error terms solved on the host, with the raw standards and kit they came from."""

    freq_hz: NDArray[np.float64]
    raw: Mapping[str, ComplexArray]
    kit: CalKit
    terms: OnePortTerms
    timestamp: float

    def correct(self, raw: S11Measurement) -> S11Measurement:
        """``raw`` (a sweep with correction off) corrected with these terms.

        Raises
        ------
        DeviceError
            If the sweep was already corrected by the instrument, or is on another grid.
        """
        if raw.calibrated:
            raise DeviceError("vna", "the sweep is already corrected by the instrument")
        if raw.freq_hz.shape != self.freq_hz.shape or not np.allclose(
            raw.freq_hz, self.freq_hz, rtol=0.0, atol=1.0
        ):
            raise DeviceError("vna", "the sweep's frequencies are not the calibration's")
        return dataclasses.replace(raw, s11=self.terms.correct(raw.s11), calibrated=True)


def measure_raw(vna: Vna) -> S11Measurement:
    """One sweep with the instrument's correction off, then restored as it was."""
    was_on = vna.calibration_active()
    if was_on:
        vna.set_correction(False)
    try:
        return vna.measure_s11()
    finally:
        if was_on:
            vna.set_correction(True)


def calibrate_on_host(
    vna: Vna, connect_standard: Callable[[str], None], kit: CalKit = IDEAL_KIT
) -> HostCalibration:
    """Raw sweeps of short, open and load (``connect_standard`` switches MS2), solved here.

    Raises
    ------
    DeviceError
        Where two standards read alike (:data:`MIN_RAW_SEPARATION`: a stuck switch).
    calibration.core.errors.DegenerateStandardsError
        Where the kit's standards coincide or the readings leave the system singular.
    """
    raw: dict[str, S11Measurement] = {}
    for standard in STANDARD_NAMES:
        connect_standard(standard)
        raw[standard] = measure_raw(vna)
    freq = raw[STANDARD_NAMES[0]].freq_hz
    measured = np.stack([raw[s].s11 for s in STANDARD_NAMES])
    _check_separated(measured, freq)
    terms = solve_one_port(measured, kit.reflections(freq), freq)
    return HostCalibration(
        freq, {s: m.s11 for s, m in raw.items()}, kit, terms, raw[STANDARD_NAMES[0]].timestamp
    )


def _check_separated(measured: ComplexArray, freq_hz: NDArray[np.float64]) -> None:
    """Raise if two standards' raw readings coincide anywhere (:data:`MIN_RAW_SEPARATION`)."""
    for i in range(len(STANDARD_NAMES)):
        for j in range(i):
            gap = np.abs(measured[i] - measured[j])
            if np.min(gap) < MIN_RAW_SEPARATION:
                k = int(np.argmin(gap))
                raise DeviceError(
                    "vna",
                    f"the {STANDARD_NAMES[j]} and {STANDARD_NAMES[i]} read alike "
                    f"({gap[k]:.2g} apart at {freq_hz[k] / 1e6:.3f} MHz, "
                    f"{int(np.sum(gap < MIN_RAW_SEPARATION))} channels): is MS2 switching?",
                )
