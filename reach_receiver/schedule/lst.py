"""Sidereal time, one implementation: astropy's, with its tables loaded once, offline.

Observation schedules start at a local sidereal time (LST), so that the same sky is
overhead night after night, and every spectrum is stamped with the LST of its mid-point.
Both use :func:`apparent_lst_h`: astropy's IAU 2006/2000A Greenwich apparent sidereal
time (``Time.sidereal_time("apparent")``, ERFA's ``gst06a``) from UT1, plus the site's
east longitude, so a ``wait: {until_lst_h: 22}`` ends where the records say 22 h.

UT1 - UTC and polar motion come from the IERS tables astropy bundles (the
``astropy-iers-data`` package, read by ``IERS_Auto`` with ``auto_download`` off, set once
for the process by :func:`load_tables`). The field machine has no network: nothing is
ever downloaded. Outside the bundled table (before 1973, after its predictions end) UT1
is taken as UTC and polar motion as a mean (astropy's "degraded accuracy", under a second
of time); those warnings and ERFA's "dubious year" for times past its leap-second table
are expected and silenced, and nothing else is.

Cost, timed on the 2-core development machine when this became the one implementation
(means over repeated calls): importing ``astropy.time`` 0.46 s, the first sidereal
time 1.17 s (it parses the IERS-A and IERS-B tables, once a process); after that 1.95 ms
for one time stamp, 40 ms for a batch of 1000, where the Meeus closed form this replaced
took 1 us. :func:`next_utc_at_lst` asks twice (4.4 ms). A daemon turn with an LST timer
took 5.5 ms instead of 0.55 ms until the timers remembered their occurrences
(:mod:`reach_receiver.daemon.timers`; 0.41 ms a turn since); ``reach-run check --sim
--dry-run`` of ``observe.yaml`` took 4.75 s against 4.71 s, and of a schedule of 100 LST
waits 6.2 s against 4.6 s. Nowhere did the closed form's speed matter: no fast path.
"""

from __future__ import annotations

import functools
import math
import threading
import warnings
from collections.abc import Sequence
from datetime import datetime, timedelta, timezone
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: Sidereal hours per solar hour (Meeus eq. 12.4's rate, 360.98564736629 / 360): only
#: the step of :func:`next_utc_at_lst`'s search and the length of a sidereal day.
SIDEREAL_RATE = 360.98564736629 / 360.0

# ``warnings.catch_warnings`` swaps a process-wide filter list: two threads inside it at
# once (a run stamping spectra, the daemon's timers) could leave each other's filters.
_WARNINGS = threading.Lock()


def _as_utc(time: datetime) -> datetime:
    """A time-zone aware UTC datetime; naive datetimes are taken to be UTC already."""
    if time.tzinfo is None:
        return time.replace(tzinfo=timezone.utc)
    return time.astimezone(timezone.utc)


@functools.cache
def load_tables() -> None:
    """Set astropy's IERS offline and read its tables: once per process (about a second).

    Called by the first sidereal time; a daemon or run calls it at start so that the
    second is not paid by the first spectrum or timer.
    """
    from astropy.utils import iers

    iers.conf.auto_download = False  # no network in the field, and no call home
    iers.conf.auto_max_age = None
    iers.conf.iers_degraded_accuracy = "ignore"
    _sidereal_h(np.array([946_728_000.0]), 0.0)  # reads the IERS and leap-second tables


def _sidereal_h(stamps: NDArray[np.float64], longitude_deg: float) -> NDArray[np.float64]:
    from astropy import units
    from astropy.time import Time

    with _WARNINGS, warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r".*dubious year")
        warnings.filterwarnings("ignore", message=r"Tried to get polar motions for times")
        times = Time(stamps, format="unix", scale="utc")
        lst = times.sidereal_time("apparent", longitude=longitude_deg * units.deg)
    return np.asarray(lst.hour, dtype=float)


def apparent_lst_h(
    timestamps: Sequence[float] | NDArray[Any], longitude_deg: float
) -> NDArray[np.float64]:
    """Local apparent sidereal time in hours, in [0, 24), of Unix time stamps.

    Parameters
    ----------
    timestamps
        Unix seconds (UTC); one call for many is far cheaper than many calls.
    longitude_deg
        The site's east longitude in degrees.
    """
    stamps = np.atleast_1d(np.asarray(timestamps, dtype=float))
    if stamps.size == 0:
        return np.zeros(0)
    load_tables()
    return _sidereal_h(stamps, longitude_deg)


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
