"""Sweep settings and result records of the Copper Mountain TR1300/1 VNA driver.

Holds the instrument's sweep limits, :class:`SweepSettings` (one S11 sweep's settings,
validated against those limits), :class:`S11Measurement` (one validated sweep) and
:class:`ScpiErrorEntry` (one entry of the SCPI error queue). They are plain values with
no I/O; :mod:`reach_receiver.devices.vna` talks to the instrument and re-exports them.

Notes
-----
The limits are those of lessju/reach_control's driver ("tested on TR1300/1") for the
frequency range, source power and IF bandwidths; the points and average ranges follow
Copper Mountain's other analysers and are not confirmed for the TR.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from reach_receiver.errors import ConfigError

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

# TR1300/1 limits: 0.3 MHz-1.3 GHz and -55..+3 dBm in 0.05 dB steps (lessju/reach_control's
# driver, "tested on TR1300/1"); IF bandwidths of that driver's list; points and average
# ranges as Copper Mountain's other analysers (QCoDeS driver): not confirmed for the TR.
F_MIN_HZ, F_MAX_HZ = 3e5, 1.3e9
POWER_RANGE_DBM = (-55.0, 3.0)
POWER_STEP_DB = 0.05
IFBW_STEPS_HZ = (10.0, 30.0, 100.0, 300.0, 1e3, 3e3, 1e4, 3e4)
POINTS_RANGE = (2, 16001)
AVERAGES_RANGE = (1, 999)


@dataclass(frozen=True)
class SweepSettings:
    """One S11 sweep's settings, validated against the TR1300/1's ranges.

    Defaults are REACH's first control code (``lessju/reach_control``,
    ``config/instrument.yaml``): 40-180 MHz, 1 kHz IFBW, 20 averages, -5 dBm. ``points``
    is not in that file: 1401 puts the points on a 100 kHz grid, which samples the
    ripple of the longest calibration cable's reflections (tens of MHz period for
    metres of cable) many times over while a sweep stays under 30 s.

    Raises
    ------
    ConfigError
        When a value is outside the instrument's range.
    """

    f_start_hz: float = 40e6
    f_stop_hz: float = 180e6
    points: int = 1401
    ifbw_hz: float = 1e3
    power_dbm: float = -5.0
    averages: int = 20

    def __post_init__(self) -> None:
        problems = []
        if not F_MIN_HZ <= self.f_start_hz < self.f_stop_hz <= F_MAX_HZ:
            problems.append(
                f"frequencies must satisfy {F_MIN_HZ:g} <= start < stop <= {F_MAX_HZ:g} Hz, "
                f"got {self.f_start_hz:g}-{self.f_stop_hz:g}"
            )
        if not POINTS_RANGE[0] <= self.points <= POINTS_RANGE[1]:
            problems.append(f"points must be in {POINTS_RANGE}, got {self.points}")
        if self.ifbw_hz not in IFBW_STEPS_HZ:
            problems.append(f"IF bandwidth must be one of {IFBW_STEPS_HZ} Hz, got {self.ifbw_hz}")
        low, high = POWER_RANGE_DBM
        steps = self.power_dbm / POWER_STEP_DB
        if not (low <= self.power_dbm <= high and abs(steps - round(steps)) < 1e-6):
            problems.append(
                f"power must be in {low}..{high} dBm in {POWER_STEP_DB} dB steps, "
                f"got {self.power_dbm}"
            )
        if not AVERAGES_RANGE[0] <= self.averages <= AVERAGES_RANGE[1]:
            problems.append(f"averages must be in {AVERAGES_RANGE}, got {self.averages}")
        if problems:
            raise ConfigError("VNA sweep settings: " + "; ".join(problems))

    def frequencies(self) -> FloatArray:
        """The linear frequency grid the sweep measures."""
        return np.linspace(self.f_start_hz, self.f_stop_hz, self.points)

    def nominal_duration_s(self) -> float:
        """Points times averages over IF bandwidth: the sweep time without overheads."""
        return self.points * self.averages / self.ifbw_hz


@dataclass(frozen=True, eq=False)
class S11Measurement:
    """One validated S11 sweep.

    Attributes
    ----------
    freq_hz
        Frequencies reported by the instrument.
    s11
        Complex reflection, corrected when ``calibrated``.
    settings
        The sweep settings in force.
    timestamp
        Clock time at which the sweep was triggered (s since the epoch).
    idn
        The instrument's ``*IDN?`` reply.
    calibrated
        Whether the instrument's error correction was on.
    """

    freq_hz: FloatArray
    s11: ComplexArray
    settings: SweepSettings
    timestamp: float
    idn: str
    calibrated: bool


@dataclass(frozen=True)
class ScpiErrorEntry:
    """One entry of the SCPI error queue: ``<code>,"<message>"``."""

    code: int
    message: str

    def __str__(self) -> str:
        return f'{self.code},"{self.message}"'
