"""Room on the data disk: free space, and how many hours of observation it holds."""

from __future__ import annotations

import shutil
from pathlib import Path

from reach_receiver.config.site import SiteConfig
from reach_receiver.store.measurements import DICKE_POSITIONS

from .outcome import Check
from .paths import existing

#: Free space below which the disk check fails (a warning below twice this).
DEFAULT_MIN_FREE_BYTES = 10 * 2**30

# The assumptions of the data rate estimate (:func:`run_bytes_per_hour`).
#: The iTPM's spectrum: 2 inputs x 16384 channels of float64 (devices.spectrometer).
SPECTRUM_INPUTS, SPECTRUM_CHANNELS, VALUE_BYTES = 2, 16384, 8
#: One Dicke cycle (source, load, noise source) every ten minutes, as ``observe.yaml``.
CYCLE_S = 600.0
#: Part files and the merged ``run.h5`` coexist until the merge at the end of a run.
MERGE_FACTOR = 2


def run_bytes_per_hour(site: SiteConfig) -> float:
    """Bytes an hour of observation adds to the data disk, roughly and on the high side.

    Assumes Dicke cycles back to back, one every :data:`CYCLE_S` (10 minutes, as
    ``schedules/observe.yaml``): each of the three positions stores one mean spectrum
    (2 inputs x 16384 channels, float64: 256 KiB) and the UTC and sidereal time
    (2 float64) of every spectrum it averaged (``period_s`` from the site: 600 per cycle
    at REACH's 1 s). Part files and the merged ``run.h5`` coexist until the merge, hence
    :data:`MERGE_FACTOR`. S11s, temperatures, solutions and HDF5's overhead are small
    beside this and left out. About 9.6 MB an hour at 1 s spectra.
    """
    spectra = len(DICKE_POSITIONS) * SPECTRUM_INPUTS * SPECTRUM_CHANNELS * VALUE_BYTES
    timestamps = CYCLE_S / site.devices.spectrometer.period_s * 2 * VALUE_BYTES
    return MERGE_FACTOR * (spectra + timestamps) * 3600.0 / CYCLE_S


def check_disk(data_dir: Path, min_free_bytes: int, bytes_per_hour: float) -> Check:
    """Free space where runs are written: ``fail`` below the minimum, ``warn`` below twice.

    The line says how many hours of observation the free space holds at
    ``bytes_per_hour`` (:func:`run_bytes_per_hour`), which is what an operator planning
    a campaign wants to know.
    """
    where = existing(data_dir)
    try:
        usage = shutil.disk_usage(where)
    except OSError as err:
        return Check("disk", "fail", f"{data_dir}: {err.strerror or err}")
    hours = usage.free / bytes_per_hour
    detail = (
        f"{data_dir}: {_gib(usage.free)} free of {_gib(usage.total)}, about {hours:,.0f} h "
        f"of observation at {bytes_per_hour / 1e6:.1f} MB/h"
    )
    minimum = _gib(min_free_bytes)
    if usage.free < min_free_bytes:
        return Check("disk", "fail", f"{detail}; below the minimum {minimum}")
    if usage.free < 2 * min_free_bytes:
        return Check("disk", "warn", f"{detail}; less than twice the minimum {minimum}")
    return Check("disk", "ok", detail)


def _gib(n_bytes: float) -> str:
    return f"{n_bytes / 2**30:.1f} GiB"


__all__ = ["DEFAULT_MIN_FREE_BYTES", "check_disk", "run_bytes_per_hour"]
