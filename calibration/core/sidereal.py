"""Sidereal time, one implementation for the engine and the receiver: astropy's, offline.

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
took 1 us. A schedule's next LST (:mod:`reach_receiver.schedule.lst`) asks twice (4.4 ms).
A daemon turn with an LST timer
took 5.5 ms instead of 0.55 ms until the timers remembered their occurrences
(:mod:`reach_receiver.daemon.timers`; 0.41 ms a turn since); ``reach-run check --sim
--dry-run`` of ``observe.yaml`` took 4.75 s against 4.71 s, and of a schedule of 100 LST
waits 6.2 s against 4.6 s. Nowhere did the closed form's speed matter: no fast path.
"""

from __future__ import annotations

import functools
import threading
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

# ``warnings.catch_warnings`` swaps a process-wide filter list: two threads inside it at
# once (a run stamping spectra, the daemon's timers) could leave each other's filters.
_WARNINGS = threading.Lock()



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
