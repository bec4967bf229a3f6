"""Physical reflection-coefficient models of the REACH calibration sources.

Loads are lumped impedances; cable-mounted sources sit at the end of a matched
transmission line (``Z_0 = 50 ohm``) with skin-effect loss::

    Gamma_load = (Z - Z_0) / (Z + Z_0)
    Gamma_in   = Gamma_load * exp(-2 gamma l),   gamma = alpha(f) + j 2 pi f / (v_f c)
    alpha(f)   = (L_dB / 8.686) * sqrt(f / 100 MHz)     [Np/m, L_dB = loss per metre at 100 MHz]

The REACH front-end contents are thesis table A.2; cable lengths follow the December 2022
deployment (2 m and 10 m calibration cables).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

Z0_OHM = 50.0
SPEED_OF_LIGHT_M_S = 299_792_458.0
NEPER_PER_DB = 1.0 / 8.685889638


@dataclass(frozen=True)
class Cable:
    """A matched coaxial cable: length, velocity factor, loss per metre at 100 MHz."""

    length_m: float
    velocity_factor: float = 0.83
    loss_db_per_m_100mhz: float = 0.12

    def round_trip(self, freq_hz: FloatArray) -> ComplexArray:
        """``exp(-2 gamma l)``: the factor a reflection acquires through the cable."""
        f = np.asarray(freq_hz, dtype=float)
        alpha = self.loss_db_per_m_100mhz * NEPER_PER_DB * np.sqrt(f / 100e6)
        beta = 2 * np.pi * f / (self.velocity_factor * SPEED_OF_LIGHT_M_S)
        return np.exp(-2 * (alpha + 1j * beta) * self.length_m)


def impedance_reflection(z_ohm: complex | ComplexArray) -> ComplexArray:
    """``Gamma = (Z - Z_0) / (Z + Z_0)``."""
    z = np.asarray(z_ohm, dtype=complex)
    return np.asarray((z - Z0_OHM) / (z + Z0_OHM), dtype=complex)


def terminated_cable(
    freq_hz: FloatArray, termination: complex | ComplexArray, cable: Cable
) -> ComplexArray:
    """Reflection at the input of ``cable`` ended in ``termination`` (a Gamma, not ohms)."""
    return np.asarray(termination, dtype=complex) * cable.round_trip(freq_hz)


def resistor(freq_hz: FloatArray, r_ohm: float, lead_inductance_h: float = 0.4e-9) -> ComplexArray:
    """A resistor with a little series lead inductance (open: ``inf``, short: ``0``)."""
    f = np.asarray(freq_hz, dtype=float)
    if np.isinf(r_ohm):
        return np.ones(f.shape, dtype=complex)
    return impedance_reflection(r_ohm + 2j * np.pi * f * lead_inductance_h)


#: Cables of the REACH front-end (thesis 2.1.1; the 10 m one is deliberately lossy).
CABLE_2M = Cable(length_m=2.0, loss_db_per_m_100mhz=0.12)
CABLE_10M = Cable(length_m=10.0, loss_db_per_m_100mhz=0.25)
HEATED_LOAD_CABLE = Cable(length_m=0.3, loss_db_per_m_100mhz=0.1)


def reach_source_reflection(name: str, freq_hz: FloatArray) -> ComplexArray:
    """Reflection coefficient of a REACH source by its REACH name (table A.2).

    ``cold`` (ambient 50 ohm), ``hot`` (heated 50 ohm), ``r25``, ``r100``, ``c2r27``,
    ``c2r36``, ``c2r69``, ``c2r91`` (2 m cable), ``c10open``, ``c10short``, ``c10r10``,
    ``c10r250`` (10 m cable), ``ant`` (a mock antenna, about -12 dB across the band).
    """
    f = np.asarray(freq_hz, dtype=float)
    lumped = {"cold": 50.4, "r25": 25.0, "r100": 100.0}
    on_2m = {"c2r27": 27.0, "c2r36": 36.0, "c2r69": 69.0, "c2r91": 91.0}
    on_10m = {"c10open": np.inf, "c10short": 0.0, "c10r10": 10.0, "c10r250": 250.0}
    if name in lumped:
        return resistor(f, lumped[name])
    if name == "hot":
        return terminated_cable(f, resistor(f, 51.0), HEATED_LOAD_CABLE)
    if name in on_2m:
        return terminated_cable(f, resistor(f, on_2m[name]), CABLE_2M)
    if name in on_10m:
        return terminated_cable(f, resistor(f, on_10m[name]), CABLE_10M)
    if name == "ant":
        return mock_antenna(f)
    raise KeyError(f"unknown REACH source {name!r}")


def mock_antenna(freq_hz: FloatArray, f0_hz: float = 90e6) -> ComplexArray:
    """A resonant mock antenna (series RLC, R = 60 ohm) behind 0.5 m of cable.

    About -21 dB at resonance, -10 dB at the band edges: like the thesis's lab mock antenna.
    """
    f = np.asarray(freq_hz, dtype=float)
    z = np.asarray(60.0 + 30j * (f / f0_hz - f0_hz / f), dtype=complex)
    return terminated_cable(f, impedance_reflection(z), Cable(length_m=0.5))


def lna_reflection(
    freq_hz: FloatArray, f_lo_hz: float = 50e6, f_hi_hz: float = 130e6
) -> ComplexArray:
    """A realistic LNA input reflection, about -30 dB with a slow phase wrap."""
    f = np.asarray(freq_hz, dtype=float)
    x = (2 * f - f_lo_hz - f_hi_hz) / (f_hi_hz - f_lo_hz)
    return 0.032 * (1 + 0.2 * x) * np.exp(1j * (1.0 - 2 * np.pi * f * 3e-9))
