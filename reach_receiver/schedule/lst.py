"""Sidereal time for schedules: the UTC at which a local sidereal time comes next.

The sidereal time itself is the engine's (:mod:`calibration.core.sidereal`, astropy's
apparent LST with its IERS tables read once, offline), so that a wait's LST, a timer's,
a spectrum's stamp and a season's LST bins are one clock.
"""

from __future__ import annotations

import math
from datetime import datetime, timedelta, timezone

from calibration.core.sidereal import apparent_lst_h

#: Sidereal hours per solar hour (Meeus eq. 12.4's rate, 360.98564736629 / 360): only
#: the step of :func:`next_utc_at_lst`'s search and the length of a sidereal day.
SIDEREAL_RATE = 360.98564736629 / 360.0


def _as_utc(time: datetime) -> datetime:
    """A time-zone aware UTC datetime; naive datetimes are taken to be UTC already."""
    if time.tzinfo is None:
        return time.replace(tzinfo=timezone.utc)
    return time.astimezone(timezone.utc)


def local_sidereal_time_h(utc: datetime, longitude_deg: float) -> float:
    """:func:`apparent_lst_h` of one datetime (naive datetimes are taken as UTC)."""
    return float(apparent_lst_h([_as_utc(utc).timestamp()], longitude_deg)[0])


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
    # One correction: the mean rate misses the day's nutation and UT1 - UTC drift by
    # milliseconds, and a step of milliseconds misses by far less than a microsecond.
    error_h = (lst_h - local_sidereal_time_h(result, longitude_deg) + 12.0) % 24.0 - 12.0
    result += timedelta(hours=error_h / SIDEREAL_RATE)
    return max(result, start)
