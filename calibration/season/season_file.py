"""The season file: LST-binned calibrated spectra with their errors, self-describing HDF5.

Root attributes ``format = "reach-calibration-season"``, ``format_version``, ``site_name``,
``longitude_deg``, ``latitude_deg``, ``lst_bin_h``, ``weights``, ``calibration_error``,
``n_runs``, ``n_spectra``, ``n_solutions``; every dataset has ``units`` and a
``description``::

    frequencies (Hz)          channel centres
    lst_edges (h)             bin edges over [0, 24]; lst (h) their centres
    mean (K)                  (n_bins, n_channels) weighted average; NaN where flagged
    std_radiometer (K)        radiometer noise of the average: 1 / sqrt(weight)
    std_calibration (K)       the calibration's error of the average (solutions and S11s)
    std_reflection (K)        the S11s' trace-noise part of std_calibration
    std (K)                   both in quadrature
    weight (K^-2)             sum of 1 / std_radiometer^2 of the unflagged spectra
    n_spectra (1)             unflagged spectra per bin and channel
    flags (1)                 channels of bins without weight
    time_mean, time_first, time_last (s)   per bin, Unix time of its spectra (NaN: none)
    spectra/                  one row per input spectrum, by time: run, name, time (s),
                              lst (h), bin, solution (digest), flagged (channels)
    solutions/                one row per solution: digest, run, measurement, time (s),
                              method; spectra/solution says which calibrated which
    runs                      the run files read

The file is written whole in memory and replaces its target atomically
(:func:`calibration.core.atomic_file.write_atomically`).
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from ..core.atomic_file import write_atomically
from ..core.errors import FileFormatError
from ..io.calibrated_spectra import Site, SolutionRecord
from .binning import Season, SpectrumRow

SEASON_FORMAT = "reach-calibration-season"
FORMAT_VERSION = "1.0"

__all__ = ["SEASON_FORMAT", "read_season", "write_season"]

_TEXT = h5py.string_dtype()


def _put(g: Any, name: str, value: Any, units: str, description: str) -> None:
    ds = g.create_dataset(name, data=value)
    ds.attrs.update(units=units, description=description)


def _text(values: list[str]) -> np.ndarray:
    return np.array(values, dtype=_TEXT)


def season_bytes(season: Season, software: str = "") -> bytes:
    """The season file's bytes (module doc)."""
    buffer = io.BytesIO()
    mean_t, first_t, last_t = season.bin_times()
    with h5py.File(buffer, "w") as f:
        f.attrs.update(
            format=SEASON_FORMAT, format_version=FORMAT_VERSION, site_name=season.site.name,
            longitude_deg=season.site.longitude_deg, latitude_deg=season.site.latitude_deg,
            lst_bin_h=float(season.edges_h[1] - season.edges_h[0]),
            n_runs=len(season.runs), n_spectra=len(season.spectra),
            n_solutions=len(season.solutions), software=software,
            weights="1 / std_radiometer^2 of each unflagged spectrum (0 where flagged)",
            calibration_error=(
                "spectra of one solution (or one set of S11 sweeps) share their error: "
                "their stds add, independent solutions add in quadrature"
            ),
        )
        _put(f, "frequencies", season.freq_hz, "Hz", "channel centres")
        _put(f, "lst_edges", season.edges_h, "h", "LST bin edges (apparent sidereal time)")
        _put(f, "lst", season.lst_h, "h", "LST bin centres")
        _put(f, "mean", season.mean, "K", "weighted average of the bin's spectra")
        _put(f, "std_radiometer", season.std_radiometer, "K",
             "radiometer noise of the average (independent per spectrum)")
        _put(f, "std_calibration", season.std_calibration, "K",
             "the calibration's error of the average (correlated within a solution)")
        _put(f, "std_reflection", season.std_reflection, "K",
             "the S11s' trace-noise part of std_calibration")
        _put(f, "std", season.std, "K", "std_radiometer and std_calibration in quadrature")
        _put(f, "weight", season.weight, "K^-2", "sum of the spectra's weights")
        _put(f, "n_spectra", season.count, "1", "unflagged spectra in the bin, per channel")
        _put(f, "flags", season.flags, "1", "true: no unflagged spectrum")
        for name, values in (("time_mean", mean_t), ("time_first", first_t),
                             ("time_last", last_t)):
            _put(f, name, values, "s", f"Unix time ({name[5:]}) of the bin's spectra")
        rows = season.spectra
        g = f.create_group("spectra")
        _put(g, "run", _text([r.run for r in rows]), "text", "run file")
        _put(g, "name", _text([r.name for r in rows]), "text", "calibrated measurement")
        _put(g, "time", np.array([r.time_s for r in rows]), "s", "mid-time, Unix")
        _put(g, "lst", np.array([r.lst_h for r in rows]), "h", "apparent LST of time")
        _put(g, "bin", np.array([r.bin for r in rows], dtype=np.int64), "1", "LST bin")
        _put(g, "solution", _text([r.solution for r in rows]), "text", "solution digest")
        _put(g, "flagged", np.array([r.flagged for r in rows], dtype=np.int64), "1",
             "flagged channels")
        s = f.create_group("solutions")
        sols = season.solutions
        _put(s, "digest", _text([x.digest for x in sols]), "text", "SHA-1 of its datasets")
        _put(s, "run", _text([x.run for x in sols]), "text", "run file first holding it")
        _put(s, "measurement", _text([x.measurement for x in sols]), "text", "its group")
        _put(s, "time", np.array([x.timestamp for x in sols]), "s", "stored, Unix")
        _put(s, "method", _text([x.method for x in sols]), "text", "solver")
        _put(f, "runs", _text(list(season.runs)), "text", "run files read")
    return buffer.getvalue()


def write_season(path: str | os.PathLike[str], season: Season, software: str = "") -> None:
    """Write the season file atomically."""
    write_atomically(Path(path), season_bytes(season, software))


def _strings(ds: Any) -> list[str]:
    return [v.decode() if isinstance(v, bytes) else str(v) for v in ds[()]]


def read_season(path: str | os.PathLike[str]) -> Season:
    """Read a season file back."""
    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise FileFormatError(f"{path}: not a season file ({err})") from err
    with f:
        fmt = f.attrs.get("format", "")
        fmt = fmt.decode() if isinstance(fmt, bytes) else str(fmt)
        if fmt != SEASON_FORMAT:
            raise FileFormatError(
                f"{path}: not a season file (format {fmt!r}); make one with reach-cal season"
            )
        site = Site(str(f.attrs["site_name"]), float(f.attrs["longitude_deg"]),
                    float(f.attrs["latitude_deg"]))
        g, s = f["spectra"], f["solutions"]
        spectra = tuple(
            SpectrumRow(run, name, float(t), float(lst), int(b), sol, int(n))
            for run, name, t, lst, b, sol, n in zip(
                _strings(g["run"]), _strings(g["name"]), g["time"][()], g["lst"][()],
                g["bin"][()], _strings(g["solution"]), g["flagged"][()], strict=True,
            )
        )
        solutions = tuple(
            SolutionRecord(d, r, m, float(t), meth)
            for d, r, m, t, meth in zip(
                _strings(s["digest"]), _strings(s["run"]), _strings(s["measurement"]),
                s["time"][()], _strings(s["method"]), strict=True,
            )
        )
        return Season(
            f["frequencies"][()], f["lst_edges"][()], site, f["mean"][()],
            f["std_radiometer"][()], f["std_calibration"][()], f["std_reflection"][()],
            f["weight"][()], f["n_spectra"][()], spectra, solutions, tuple(_strings(f["runs"])),
        )
