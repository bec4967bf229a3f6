"""Noise temperatures of sources with a temperature gradient: cables, heated load, antenna.

A source that is a termination at ``T_R`` behind a passive cable at ``T_cab`` delivers, at
the cable's far end, the noise temperature (thesis eqs. 3.15 and 4.9)::

    T_src = G T_R + (1 - G) T_cab                                              (3.15, 4.9)

where ``G`` is the cable's available power gain with the termination as its source
(Pozar, *Microwave Engineering*, 4th ed., eq. 12.13; thesis eqs. 3.16 and 4.8)::

    G = |S21|^2 (1 - |G_R|^2) / (|1 - S11 G_R|^2 (1 - |G_src|^2))              (3.16, 4.8)

with port 1 of the cable at the termination and port 2 at the receiver (the convention
of :mod:`calibration.rf.two_port`), ``G_R`` the termination's reflection and ``G_src`` the
reflection of the whole source at port 2. ``G_src`` is
``S22 + S12 S21 G_R / (1 - S11 G_R)`` (eq. 4.7) when not given; a measured ``G_src``
may be passed instead, as the thesis does. (3.15) holds because a passive cable in
thermal equilibrium at ``T_cab`` emits noise waves of correlation ``k T_cab (I - S S^H)``
(Bosma's theorem): ``tests/test_source_temperatures.py`` checks it against that
brute-force wave sum. The thesis calls ``G`` the "realised gain" in 4.6.2; its formula
(4.8) is the available gain, as here.

Where only the temperature at the receiver end is known the relation is inverted for the
termination, the antenna's terminating load (eq. 4.10)::

    T_ATL = (T_ant + (G - 1) T_cab) / G                                           (4.10)

with a cable partly inside the temperature-controlled enclosure (eq. 4.11)::

    T_cab = (T_int L_int + T_ext L_ext) / L_tot                                  (4.11)

Antenna loss, thesis eq. (5.1): an antenna (ground, resistive, feed-line and balun loss
``l`` dB, transmission ``eta = 10^(-l/10)``) at ambient temperature ``T_amb`` in front of a
sky at ``T_sky`` delivers ``T_raw = eta T_sky + (1 - eta) T_amb``, so::

    T_sky = (T_raw - T_amb (1 - eta)) / eta                                        (5.1)

The thesis prints ``(10^(-l/10) - 1)`` where ``(1 - 10^(-l/10))`` belongs: with that sign
an antenna at ambient temperature looking at an ambient sky would not calibrate to
``T_amb`` (``tests/test_source_temperatures.py``: the lossy antenna at equilibrium).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import InvalidDataError
from ..rf.two_port import embed_reflection

__all__ = [
    "antenna_loss_correction",
    "available_gain",
    "cable_source_temperature",
    "split_cable_temperature",
    "terminating_load_temperature",
]

FloatArray = NDArray[np.float64]


def available_gain(
    s: ArrayLike, gamma_term: ArrayLike, gamma_src: ArrayLike | None = None
) -> FloatArray:
    """Available power gain ``G`` of a cable with its termination, eq. (3.16) / (4.8).

    Parameters
    ----------
    s
        The cable's S-parameters, shape ``(..., 2, 2)``, port 1 at the termination.
    gamma_term
        The termination's reflection ``G_R`` (per frequency).
    gamma_src
        The whole source's reflection at port 2; by default computed from ``s`` and
        ``gamma_term`` (eq. 4.7), which keeps ``0 <= G <= 1`` for a passive cable.
    """
    m = np.asarray(s, dtype=complex)
    g_r = np.asarray(gamma_term, dtype=complex)
    g_src = embed_reflection(g_r, m) if gamma_src is None else np.asarray(gamma_src, complex)
    if np.any(np.abs(g_src) >= 1):
        raise InvalidDataError("source reflection |Gamma_src| >= 1: no available power")
    num = np.abs(m[..., 1, 0]) ** 2 * (1 - np.abs(g_r) ** 2)
    den = np.abs(1 - m[..., 0, 0] * g_r) ** 2 * (1 - np.abs(g_src) ** 2)
    return np.asarray(num / den, dtype=float)


def cable_source_temperature(
    gain: ArrayLike, t_term_k: ArrayLike, t_cab_k: ArrayLike
) -> FloatArray:
    """Noise temperature at the receiver end, ``G T_R + (1 - G) T_cab``, eq. (3.15) / (4.9).

    The heated load (``T_R`` its resistor's thermocouple, ``T_cab`` its cable's or the
    ambient), and each cable-mounted calibrator (``T_R`` its termination's, ``T_cab`` its
    cable's thermocouple, thesis table 2.2).
    """
    g = np.asarray(gain, dtype=float)
    return np.asarray(g * np.asarray(t_term_k) + (1 - g) * np.asarray(t_cab_k), dtype=float)


def terminating_load_temperature(
    t_measured_k: ArrayLike, gain: ArrayLike, t_cab_k: ArrayLike
) -> FloatArray:
    """Temperature of a termination seen through a cable, eq. (4.10): (3.15) solved for ``T_R``.

    For the antenna, ``t_measured_k`` is its calibrated temperature at the receiver input
    and the result the temperature at its terminating load (the sky, for an antenna of
    radiation efficiency 1). Refuses ``G <= 0`` (nothing of the termination arrives).
    """
    g = np.asarray(gain, dtype=float)
    if np.any(g <= 0):
        raise InvalidDataError("cable gain G <= 0: the termination's temperature is not seen")
    t_cab = np.asarray(t_cab_k, dtype=float)
    return np.asarray((np.asarray(t_measured_k) + (g - 1) * t_cab) / g, dtype=float)


def split_cable_temperature(
    t_int_k: ArrayLike, length_int_m: float, t_ext_k: ArrayLike, length_ext_m: float
) -> FloatArray:
    """Length-weighted temperature of a cable partly inside the enclosure, eq. (4.11).

    The thesis's lab mock antenna: 28 cm inside, 100 cm outside. A length weighting is
    exact to first order in the cable's loss (each metre of a low-loss cable adds the same
    share of noise).
    """
    total = length_int_m + length_ext_m
    if length_int_m < 0 or length_ext_m < 0 or total <= 0:
        raise InvalidDataError("cable lengths must be >= 0 with a positive total")
    t = (np.asarray(t_int_k) * length_int_m + np.asarray(t_ext_k) * length_ext_m) / total
    return np.asarray(t, dtype=float)


def antenna_loss_correction(
    t_raw_k: ArrayLike, t_ambient_k: ArrayLike, loss_db: ArrayLike
) -> FloatArray:
    """Sky temperature from a lossy antenna's temperature, eq. (5.1) with its sign corrected.

    ``loss_db`` (>= 0, per channel or one value) is the total antenna loss: ground,
    resistive, transmission-line and balun loss; ``t_ambient_k`` the lossy parts'
    physical temperature.
    """
    loss = np.asarray(loss_db, dtype=float)
    if np.any(loss < 0) or not np.all(np.isfinite(loss)):
        raise InvalidDataError("antenna loss must be a finite number of dB >= 0")
    eta = 10 ** (-loss / 10)
    t_amb = np.asarray(t_ambient_k, dtype=float)
    return np.asarray((np.asarray(t_raw_k) - t_amb * (1 - eta)) / eta, dtype=float)
