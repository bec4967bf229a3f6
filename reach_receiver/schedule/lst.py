r"""Sidereal time: when a given local sidereal time next comes round at the site.

Observation schedules start at a local sidereal time (LST), so that the same sky is
overhead night after night. Greenwich mean sidereal time (GMST) follows the IAU 1982
expression in the form of Meeus, *Astronomical Algorithms* (2nd ed., 1998), eq. 12.4:

.. math::

    \theta_0 = 280.46061837^\circ + 360.98564736629^\circ\,(JD - 2451545.0)
               + 0.000387933^\circ\,T^2 - T^3 / 38\,710\,000^\circ,

with :math:`T = (JD - 2451545.0) / 36525` Julian centuries of UT from J2000.0, and the
local sidereal time is :math:`\theta_0` plus the east longitude.

Accuracy: the expression itself reproduces the IAU 1982 GMST to far better than a
millisecond over this century (Meeus' examples 12.a and 12.b are met to 0.1 ms in the
tests). UTC is used in place of UT1, which differs by less than 0.9 s, and the mean
rather than apparent sidereal time is returned (the equation of the equinoxes, at most
about 1.2 s), so the LST is good to about 2 s of time: ample for starting observations.

Records carry astropy's apparent sidereal time instead (:func:`apparent_lst_h`); a test
holds the two within that 2 s.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from datetime import datetime, timedelta, timezone
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: J2000.0 (2000-01-01 12:00 TT, taken as UTC here) as a POSIX time stamp.
_J2000_POSIX_S = 946_728_000.0
_SECONDS_PER_DAY = 86_400.0
#: Sidereal hours per solar hour: the derivative of eq. 12.4's linear term / 360 deg.
SIDEREAL_RATE = 360.98564736629 / 360.0


def _as_utc(time: datetime) -> datetime:
    """A time-zone aware UTC datetime; naive datetimes are taken to be UTC already."""
    if time.tzinfo is None:
        return time.replace(tzinfo=timezone.utc)
    return time.astimezone(timezone.utc)


def greenwich_sidereal_time_h(utc: datetime) -> float:
    """Greenwich mean sidereal time (IAU 1982, Meeus eq. 12.4) in hours, in [0, 24).

    Parameters
    ----------
    utc
        The time (UTC, standing in for UT1; naive datetimes are taken as UTC).

    Returns
    -------
    float
        GMST in hours.
    """
    days = (_as_utc(utc).timestamp() - _J2000_POSIX_S) / _SECONDS_PER_DAY
    centuries = days / 36_525.0
    # 360.98564736629 * days split as 360 * days + 0.98564736629 * days, with the whole
    # days (whole turns) dropped from the first term, keeps the sum's rounding small.
    degrees = (
        280.46061837
        + 360.0 * (days % 1.0)
        + 0.98564736629 * days
        + 0.000387933 * centuries**2
        - centuries**3 / 38_710_000.0
    )
    return (degrees % 360.0) / 15.0


def local_sidereal_time_h(utc: datetime, longitude_deg: float) -> float:
    """Local mean sidereal time in hours, in [0, 24), at east longitude ``longitude_deg``."""
    return (greenwich_sidereal_time_h(utc) + longitude_deg / 15.0) % 24.0


def next_utc_at_lst(after: datetime, lst_h: float, longitude_deg: float) -> datetime:
    """The first UTC time at or after ``after`` when the local sidereal time is ``lst_h``.

    Parameters
    ----------
    after
        Where to start looking (naive datetimes are UTC).
    lst_h
        The wanted local sidereal time in hours (taken modulo 24).
    longitude_deg
        The site's east longitude in degrees.

    Returns
    -------
    datetime
        An aware UTC datetime less than one sidereal day after ``after``.

    Raises
    ------
    ValueError
        When ``lst_h`` or ``longitude_deg`` is not finite.
    """
    if not (math.isfinite(lst_h) and math.isfinite(longitude_deg)):
        raise ValueError(f"LST {lst_h} h and longitude {longitude_deg} deg must be finite")
    start = _as_utc(after)
    ahead_h = (lst_h - local_sidereal_time_h(start, longitude_deg)) % 24.0
    if ahead_h > 24.0 - 1e-9:  # "now", seen a rounding error behind
        ahead_h = 0.0
    result = start + timedelta(hours=ahead_h / SIDEREAL_RATE)
    # one correction step for the (tiny) quadratic and cubic terms
    error_h = (lst_h - local_sidereal_time_h(result, longitude_deg) + 12.0) % 24.0 - 12.0
    result += timedelta(hours=error_h / SIDEREAL_RATE)
    return max(result, start)


def apparent_lst_h(
    timestamps: Sequence[float] | NDArray[Any], longitude_deg: float
) -> NDArray[np.float64]:
    """Apparent local sidereal time (hours) of Unix time stamps, through astropy, offline.

    For the time stamps of records, where the closed form above (good to about 2 s) is
    replaced by astropy's IAU 2006/2000A apparent sidereal time with UT1 from the IERS-B
    table that astropy ships. Nothing is downloaded: a site 90 km from town has no use
    for a call home that fails. Beyond the bundled table UT1 is taken as UTC and polar
    motion as its last value (astropy's "degraded accuracy", under a second of time);
    those warnings, and ERFA's "dubious year" for times past its leap-second table, are
    expected and silenced here.
    """
    from astropy import units
    from astropy.time import Time
    from astropy.utils import iers

    stamps = np.atleast_1d(np.asarray(timestamps, dtype=float))
    if stamps.size == 0:
        return np.zeros(0)
    with iers.conf.set_temp("auto_download", False), iers.conf.set_temp(
        "auto_max_age", None
    ), iers.conf.set_temp("iers_degraded_accuracy", "ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ERFA "dubious year", IERS polar-motion fallback
        times = Time(stamps, format="unix", scale="utc")
        lst = times.sidereal_time("apparent", longitude=longitude_deg * units.deg)
    return np.asarray(lst.hour, dtype=float)
