"""A season as ``GSData``, the 21-cm global-signal container (``pygsdata``), written as GSH5.

One load (``ant``), one polarisation (``XX``: REACH's single dipole), a time per LST bin
that holds data. As EDGES' own LST binning does, each bin's time is the Julian date at
the bin's centre LST on the day of the season's mean time
(``pygsdata.coordinates.lsts_to_times``), its ``lsts`` the bin centre and ``lst_ranges``
its edges; ``data`` is the weighted average (K, ``data_unit = "temperature"``), NaN where
flagged; ``nsamples`` the weight, ``1 / std_radiometer^2`` (K^-2), 0 where flagged, so
that ``pygsdata``'s and ``edges-analysis``'s weighted averages of bins are inverse-variance
averages; flags ``reach_season`` (no unflagged spectrum). The errors go in
``auxiliary_measurements`` (per bin, ``(n_bins, n_channels)``, K): ``calibration_error_k``
(shared within a solution: it does not average down over bins or channels calibrated by
one solution), ``radiometer_error_k`` and ``n_spectra``. The integration times are not
carried (``pygsdata``'s default 1 s): ``nsamples`` is the weight, not a count.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ..core.atomic_file import write_atomically
from .binning import Season

__all__ = ["to_gsdata", "write_gsdata"]

FLAG_NAME = "reach_season"


def to_gsdata(season: Season, telescope_name: str = "REACH") -> Any:
    """The season's bins with data as a ``pygsdata.GSData`` (module doc)."""
    import astropy.units as un
    from astropy.coordinates import EarthLocation, Longitude
    from astropy.time import Time
    from pygsdata import GSData, GSFlag, Telescope  # type: ignore[import-untyped]
    from pygsdata.coordinates import lsts_to_times  # type: ignore[import-untyped]

    keep = np.flatnonzero(~np.all(season.flags, axis=1))
    location = EarthLocation.from_geodetic(
        lon=season.site.longitude_deg * un.deg, lat=season.site.latitude_deg * un.deg,
        height=0.0 * un.m,
    )
    mean_t, _, _ = season.bin_times()
    reference = Time(float(np.nanmean(mean_t[keep])), format="unix", scale="utc")
    edges = season.edges_h
    lst_ranges = Longitude(np.stack([edges[keep], edges[keep + 1]], axis=-1)[:, None, :]
                           * un.hourangle)
    lsts = Longitude(season.lst_h[keep][:, None] * un.hourangle)
    # Bin edges past the first bin's start are unwrapped, so each range ends after it starts.
    first = edges[keep[0]] if keep.size else 0.0
    unwrapped = np.where(lst_ranges.hour < first, lst_ranges.hour + 24.0, lst_ranges.hour)
    unwrapped[..., 1] = np.where(unwrapped[..., 1] <= unwrapped[..., 0],
                                 unwrapped[..., 1] + 24.0, unwrapped[..., 1])
    centres = np.where(lsts.hour < first, lsts.hour + 24.0, lsts.hour)
    times = lsts_to_times(centres * un.hourangle, ref_time=reference, location=location)
    time_ranges = lsts_to_times(unwrapped * un.hourangle, ref_time=reference, location=location)
    flags = season.flags[keep][None, None]
    telescope = Telescope(name=telescope_name, location=location, pols=("XX",))
    return GSData(
        data=season.mean[keep][None, None],
        freqs=season.freq_hz / 1e6 * un.MHz,
        times=Time(times.jd, format="jd", location=location),
        time_ranges=Time(time_ranges.jd, format="jd", location=location),
        lsts=lsts,
        lst_ranges=lst_ranges,
        telescope=telescope,
        loads=("ant",),
        nsamples=np.where(flags, 0.0, season.weight[keep][None, None]),
        flags={FLAG_NAME: GSFlag(flags=flags, axes=("load", "pol", "time", "freq"))},
        data_unit="temperature",
        auxiliary_measurements={
            "calibration_error_k": season.std_calibration[keep],
            "radiometer_error_k": season.std_radiometer[keep],
            "n_spectra": season.count[keep],
        },
        name=f"REACH season, {season.site.name}, {len(season.runs)} runs",
    )


def write_gsdata(season: Season, path: str | os.PathLike[str]) -> None:
    """Write the season as GSH5 atomically (``GSData.write_gsh5`` into a temporary file)."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    data = to_gsdata(season)
    with tempfile.TemporaryDirectory(dir=target.parent, prefix=f".{target.name}.") as tmp:
        scratch = Path(tmp) / target.name
        data.write_gsh5(scratch)
        write_atomically(target, scratch.read_bytes())
