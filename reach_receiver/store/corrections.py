"""The site's calibration corrections, applied to the hand-over's data before the solve.

The ``calibrate`` step takes the engine's view of the run (:mod:`.handover`) and, as the
site file's ``calibration`` section describes them (:mod:`reach_receiver.config.
corrections`) and the step allows, corrects it in this order (issue 14, thesis 4.6-4.7):

1. **MTS** (``mts``): every source's S11 de-embedded through the switch path between the
   sources and the VNA (:func:`calibration.rf.two_port.deembed_reflection`, eq. 4.6), and the
   LNA's embedded through the path between the LNA and the sources
   (:func:`~calibration.rf.two_port.embed_reflection`, eq. 4.7): both at the sources' plane.
   Each path file is checked for reciprocity and passivity (``check_two_port``), the
   findings reported.
2. **Cables** (``cables``): each listed calibrator's temperature becomes
   ``G T_R + (1 - G) T_cab`` (eqs. 4.8-4.9, :mod:`calibration.model.source_temperatures`), ``T_R``
   its own thermocouple's (the hand-over's), ``T_cab`` its cable's port averaged over the
   same cycles (the hand-over's ``thermocouples_k``), ``G`` the cable's available gain with
   the termination ``deembed(G_src, S_cable)`` behind it, clipped to ``[0, 1]`` (a VNA's
   noise on an open or short termination can push it just outside).
3. **RFI** (``rfi``): :func:`calibration.checks.rfi.flag_spectrum` (5 sigma) on every source's
   three Dicke spectra (the calibrators' and the antenna's; the cable sources' ripple is
   followed by the flagger's trend, :func:`calibration.checks.rfi.calibrator_flags`); the
   channels flagged anywhere are dropped from every source, and their frequencies and
   counts kept in the report.

The report (what was done, in numbers) is stored with the solution in its hand-over.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from calibration.checks.rfi import flag_spectrum
from calibration.model.data import CalibrationData, SourceData
from calibration.model.source_temperatures import available_gain, cable_source_temperature
from calibration.rf.coax import DataSheetCoax
from calibration.rf.touchstone import read_touchstone_network
from calibration.rf.two_port import (
    check_two_port,
    deembed_reflection,
    embed_reflection,
    interpolate_s,
)
from reach_receiver.config.corrections import CableSettings, CorrectionSettings
from reach_receiver.errors import ConfigError

from .handover import HandOver

ComplexArray = NDArray[np.complex128]
Others = dict[str, SourceData]


@dataclass(frozen=True)
class Chosen:
    """Which corrections to apply (each only where the site describes it)."""

    mts: bool = True
    cables: bool = True
    rfi: bool = True


#: Every correction the site describes.
ALL_CORRECTIONS = Chosen()


def _two_port(path: str, freq_hz: NDArray[np.float64], report: dict[str, Any]) -> ComplexArray:
    net = read_touchstone_network(path)
    if net.s.shape[1:] != (2, 2):
        raise ConfigError(f"{path}: not a two-port ({net.s.shape[1]} ports)")
    if freq_hz[0] < net.freq_hz[0] or freq_hz[-1] > net.freq_hz[-1]:
        raise ConfigError(f"{path}: covers {net.freq_hz[0]:g}-{net.freq_hz[-1]:g} Hz, not the band")
    report.setdefault("two_port_checks", {})[path] = str(check_two_port(net.s, net.freq_hz, path))
    return interpolate_s(net.freq_hz, net.s, freq_hz)


def _cable_s(cable: CableSettings, path: str | None, freq_hz: NDArray[np.float64],
             report: dict[str, Any]) -> ComplexArray:
    if path is not None:
        return _two_port(path, freq_hz, report)
    coax = DataSheetCoax(
        float(cable.length_m or 0.0),
        float(cable.velocity_factor or 1.0),
        float(cable.loss_db_per_m or 0.0),
        cable.ref_freq_hz,
        cable.loss_exponent,
    )
    return coax.s_parameters(freq_hz)


def _mts(data: CalibrationData, others: Others, settings: CorrectionSettings, site_source: str,
         report: dict[str, Any]) -> tuple[CalibrationData, Others]:
    f = data.freq_hz
    if settings.mts_sources:
        s = _two_port(str(settings.path(settings.mts_sources, site_source)), f, report)
        data = replace(data, sources={
            n: replace(src, gamma=deembed_reflection(src.gamma, s))
            for n, src in data.sources.items()})
        others = {n: replace(src, gamma=deembed_reflection(src.gamma, s))
                  for n, src in others.items()}
        report["mts_sources"] = settings.mts_sources
    if settings.mts_lna:
        s = _two_port(str(settings.path(settings.mts_lna, site_source)), f, report)
        data = replace(data, gamma_rec=embed_reflection(data.gamma_rec, s))
        report["mts_lna"] = settings.mts_lna
    return data, others


def _cables(data: CalibrationData, handover: HandOver, settings: CorrectionSettings,
            site_source: str, report: dict[str, Any]) -> CalibrationData:
    sources = dict(data.sources)
    done: dict[str, float] = {}
    for name, cable in settings.cables.items():
        src = sources.get(name)
        t_cab = handover.thermocouples_k.get(name, {}).get(cable.thermocouple)
        if src is None or src.temperature_k is None:
            continue
        if t_cab is None:
            report.setdefault("warnings", []).append(
                f"{name}: no reading of its cable's port {cable.thermocouple}; not corrected")
            continue
        path = str(settings.path(cable.s2p, site_source)) if cable.s2p else None
        s = _cable_s(cable, path, data.freq_hz, report)
        gain = np.clip(available_gain(s, deembed_reflection(src.gamma, s), src.gamma), 0.0, 1.0)
        t_src = cable_source_temperature(gain, src.temperature_k, t_cab)
        sources[name] = replace(src, temperature_k=t_src)
        done[name] = float(np.mean(t_src - np.asarray(src.temperature_k)))
    report["cable_mean_change_k"] = done
    return replace(data, sources=sources)


def _flat(spectrum: NDArray[Any]) -> NDArray[np.float64]:
    p = np.asarray(spectrum, dtype=float)
    return p if p.ndim == 1 else np.asarray(p.mean(axis=0), dtype=float)


def _rfi(data: CalibrationData, others: Others,
         report: dict[str, Any]) -> tuple[CalibrationData, Others]:
    flagged = np.zeros(data.n_channels, dtype=bool)
    counts = {}
    everyone = {**data.sources, **others}
    for name, src in everyone.items():
        flags = np.zeros(data.n_channels, dtype=bool)
        for spectrum in (src.p_source, src.p_load, src.p_ns):
            flags |= flag_spectrum(_flat(spectrum))
        counts[name] = int(np.count_nonzero(flags))
        flagged |= flags
    keep = ~flagged
    report["rfi_flagged_channels"] = int(np.count_nonzero(flagged))
    report["rfi_flagged_by_source"] = counts
    report["rfi_flagged_hz"] = [float(f) for f in data.freq_hz[flagged]]
    if not flagged.any():
        return data, others
    data = data.select(keep, "the RFI flags")
    return data, {n: s.select(keep) for n, s in others.items()}


def correct(
    data: CalibrationData,
    others: Others,
    handover: HandOver,
    settings: CorrectionSettings,
    site_source: str,
    chosen: Chosen = ALL_CORRECTIONS,
) -> tuple[CalibrationData, Others, dict[str, Any]]:
    """The corrections of the module doc on the hand-over's data: data, others, report."""
    report: dict[str, Any] = {}
    if chosen.mts and (settings.mts_sources or settings.mts_lna):
        data, others = _mts(data, others, settings, site_source, report)
    if chosen.cables and settings.cables:
        data = _cables(data, handover, settings, site_source, report)
    if chosen.rfi and settings.rfi:
        data, others = _rfi(data, others, report)
    return data, others, report


def corrections_line(report: dict[str, Any] | Any) -> str:
    """One line of what :func:`correct` did (its ``report``), empty if it did nothing."""
    parts = []
    if report.get("mts_sources"):
        parts.append(f"sources de-embedded through {report['mts_sources']}")
    if report.get("mts_lna"):
        parts.append(f"LNA reflection embedded through {report['mts_lna']}")
    if report.get("cable_mean_change_k"):
        changes = ", ".join(f"{k} {v:+.3f} K" for k, v in report["cable_mean_change_k"].items())
        parts.append(f"cable temperatures ({changes})")
    if "rfi_flagged_channels" in report:
        parts.append(f"{report['rfi_flagged_channels']} RFI channels flagged")
    parts += [f"warning: {w}" for w in report.get("warnings", [])]
    return "; ".join(parts)
