"""The simulated VNA's SCPI: header forms, argument rules and reply formats, and its state.

What the TRVNA software accepts and answers, apart from what it measures: long and short
header forms with the channel suffix made explicit (:func:`normalise_header`),
``ON``/``OFF``/``1``/``0`` flags, settings clipped to the instrument's ranges and IF
bandwidths rounded to its steps, numbers answered as ASCII, complex traces re/im
interleaved; and the channel state that ``MMEM:STOR`` saves (:class:`ChannelState`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from calibration.rf.one_port import OnePortTerms
from reach_receiver.sim.vna_model import ComplexArray

_LONG_FORMS = {
    "SENSE": "SENS", "FREQUENCY": "FREQ", "START": "STAR", "SWEEP": "SWE", "POINTS": "POIN",
    "BWIDTH": "BWID", "SOURCE": "SOUR", "POWER": "POW", "AVERAGE": "AVER", "COUNT": "COUN",
    "CALCULATE": "CALC", "TRACE": "TRAC", "TRIGGER": "TRIG", "SEQUENCE": "SEQ",
    "SINGLE": "SING", "SYSTEM": "SYST", "ERROR": "ERR", "CORRECTION": "CORR", "STATE": "STAT",
    "COLLECT": "COLL", "METHOD": "METH", "SHORT": "SHOR", "MMEMORY": "MMEM", "STORE": "STOR",
    "STYPE": "STYP", "PARAMETER": "PAR", "DEFINE": "DEF",
}  # fmt: skip
_CHANNELLED = {"SENS", "SOUR", "CALC"}
IFBW_STEPS_HZ = (10.0, 30.0, 100.0, 300.0, 1e3, 3e3, 1e4, 3e4)


@dataclass
class ChannelState:
    """What ``MMEM:STOR`` saves: the channel settings and, for CST, the calibration."""

    start_hz: float = 40e6
    stop_hz: float = 180e6
    points: int = 201
    ifbw_hz: float = 1e3
    power_dbm: float = -5.0
    averaging: bool = False
    average_count: int = 1
    trigger_source: str = "INT"
    trigger_averaging: bool = False
    correction: bool = False
    cal_freq_hz: NDArray[np.float64] | None = None
    cal_terms: OnePortTerms | None = None
    collected: dict[str, ComplexArray] = field(default_factory=dict)

    def freq_hz(self) -> NDArray[np.float64]:
        """The sweep's frequencies (Hz): ``points`` evenly from start to stop."""
        return np.linspace(self.start_hz, self.stop_hz, self.points)


def normalise_header(header: str) -> str:
    """Short-form upper-case header, root channel suffix made explicit: ``SENS1:FREQ:STAR``."""
    nodes: list[str] = []
    for node in header.strip().lstrip(":").upper().split(":"):
        match = re.fullmatch(r"(\*?[A-Z]+)(\d*)(\??)", node)
        if match is None:
            return header.strip().upper()
        name, suffix, query = match.groups()
        name = _LONG_FORMS.get(name, name)
        if not nodes and name in _CHANNELLED and not suffix:
            suffix = "1"
        nodes.append(f"{name}{suffix}{query}")
    return ":".join(nodes)


def flag(arg: str) -> bool:
    """A boolean argument: ``1``/``ON`` or ``0``/``OFF`` (else ``ValueError``)."""
    value = arg.strip().upper()
    if value in ("1", "ON"):
        return True
    if value in ("0", "OFF"):
        return False
    raise ValueError(arg)


def clip(value: float, low: float, high: float) -> float:
    """``value`` held within the instrument's range ``[low, high]``."""
    return min(max(value, low), high)


def nearest(value: float, steps: tuple[float, ...]) -> float:
    """The step nearest ``value`` in ratio (IF bandwidths come in steps)."""
    return min(steps, key=lambda step: abs(np.log(step / value)))


def power_level(value: float) -> float:
    """A source power (dBm) within -55 to +3 dBm, in the instrument's 0.05 dB steps."""
    return round(clip(value, -55.0, 3.0) / 0.05) * 0.05


def interleave(data: ComplexArray) -> NDArray[np.float64]:
    """A complex trace as SCPI sends it: re, im, re, im, ..."""
    return np.column_stack([data.real, data.imag]).ravel()


def ascii_values(values: NDArray[np.float64]) -> str:
    """Numbers as an ASCII reply: comma-separated, 11 significant digits."""
    return ",".join(f"{v:.10e}" for v in values)


__all__ = [
    "IFBW_STEPS_HZ",
    "ChannelState",
    "ascii_values",
    "clip",
    "flag",
    "interleave",
    "nearest",
    "normalise_header",
    "power_level",
]
