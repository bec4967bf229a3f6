"""A run file's calibrated spectra read in chunks of rows, each binned on its own.

A large run (a night of 1 s spectra is tens of thousands of rows of 16k channels, GBs)
does not fit one worker's memory as one :class:`~calibration.io.calibrated_spectra.RunSpectra`.
:func:`read_rows` reads rows ``[start, stop)`` of the run's calibrated spectra, exactly
the rows :func:`~calibration.io.calibrated_spectra.read_calibrated_spectra` would give
(the same solutions, times, LSTs, and the night's flags ORed into the rows they name: a
night check names each spectrum's latest row of its name before the check, over the
whole run); :func:`bin_rows` bins them (:func:`calibration.season.binning.bin_run`), and the
chunks' sums add (:func:`calibration.season.binning.add`) to the run's.

:func:`rows_per_chunk` sizes a chunk to a memory budget: a row costs about
:data:`ROW_ARRAYS` float64 arrays of its channels at once (the five read, their stacked
copies, the binning's weights and products).
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Iterator, Mapping
from typing import Any, cast

import h5py
import numpy as np

from ..core.errors import InvalidDataError
from ..core.sidereal import apparent_lst_h
from ..io.calibrated_spectra import (
    RunSpectra,
    SolutionRecord,
    open_run_file,
    read_site,
    solution_digest,
    spectrum_row,
)
from ..io.hdf5_io import attr_text
from .binning import BinnedRun, FloatArray, bin_run

__all__ = ["ROW_ARRAYS", "bin_rows", "count_rows", "read_rows", "rows_per_chunk"]

#: float64 arrays of a row's channels held at once while a chunk is read and binned
#: (measured: ``python -m benchmarks.archive`` prints the peak per worker against it).
ROW_ARRAYS = 24


def rows_per_chunk(n_channels: int, budget_bytes: float) -> int:
    """Rows of ``n_channels`` whose reading and binning fit ``budget_bytes`` (at least 1)."""
    return max(1, int(budget_bytes // (ROW_ARRAYS * 8 * max(n_channels, 1))))


def _no_rows(path: str) -> InvalidDataError:
    return InvalidDataError(
        f"{path}: no calibrated spectra (observe calibrates its cycles once the run has "
        "a solution); leave this run out of the season"
    )


def count_rows(path: str) -> tuple[int, int]:
    """The run's number of calibrated spectra and their channels (names and one shape)."""
    with open_run_file(path) as f:
        by_number = _Measurements(f["measurements"])
        numbers = [n for n in by_number if by_number.kind_and_name(n)[0] == "calibrated"]
        if not numbers:
            raise _no_rows(path)
        return len(numbers), int(by_number[numbers[0]]["frequencies"].shape[0])


class _Measurements(Mapping[int, h5py.Group]):
    """A run's measurements by number, each group opened only when asked for.

    The names are ``NNNNNN_<kind>_<name>`` (``reach_receiver/store/merge.py``): the scan of
    a chunk reads names, not the attributes of every group of the run.
    """

    def __init__(self, measurements: h5py.Group):
        self.group = measurements
        self.keys_by_number = {int(k.split("_", 1)[0]): k for k in measurements}

    def __getitem__(self, number: int) -> h5py.Group:
        return self.group[self.keys_by_number[number]]

    def __iter__(self) -> Iterator[int]:
        return iter(sorted(self.keys_by_number))

    def __len__(self) -> int:
        return len(self.keys_by_number)

    def kind_and_name(self, number: int) -> tuple[str, str]:
        _, kind, name = self.keys_by_number[number].split("_", 2)
        return kind, name


def read_rows(path: str, start: int, stop: int) -> RunSpectra:
    """Rows ``[start, stop)`` of the run's calibrated spectra (module doc)."""
    with open_run_file(path) as f:
        by_number = _Measurements(f["measurements"])
        solutions: list[SolutionRecord] = []
        rows: dict[int, dict[str, Any]] = {}
        latest: dict[str, int] = {}  # a name's latest row so far, over the whole run
        index = 0
        for number in by_number:
            kind, name = by_number.kind_and_name(number)
            if kind == "solution" and "solution" in (g := by_number[number]):
                solutions.append(SolutionRecord(
                    solution_digest(g["solution"]), path, g.name.rsplit("/", 1)[-1],
                    float(g.attrs["timestamp"]), attr_text(g["solution"].attrs.get("method", "")),
                ))
            elif kind == "calibrated":
                latest[name] = index
                if start <= index < stop:
                    lookup = cast(dict[int, Any], by_number)  # spectrum_row only looks up
                    rows[index] = spectrum_row(by_number[number], lookup, path, len(solutions) - 1)
                index += 1
            elif kind == "check" and name.startswith("rfi_night_"):
                _night_flags(by_number[number], rows, latest)
        if not index:
            raise _no_rows(path)
        if not rows:
            raise InvalidDataError(f"{path}: rows {start}-{stop} of {index} asked for")
        site = read_site(f, path)
        run_name = attr_text(f.attrs.get("name", os.path.basename(os.path.dirname(path))))
    ordered = [rows[i] for i in sorted(rows)]
    freq = ordered[0]["freq"]
    for row in ordered[1:]:
        if row["freq"].shape != freq.shape or not np.allclose(row["freq"], freq, rtol=1e-9):
            raise InvalidDataError(f"{path}: calibrated spectra on different frequency grids")
    times = np.array([r["time"] for r in ordered])

    def stack(key: str) -> FloatArray:
        return np.asarray(np.stack([r[key] for r in ordered]), dtype=float)

    return RunSpectra(
        path=path, run_name=run_name, site=site, freq_hz=freq,
        names=tuple(r["name"] for r in ordered), mean=stack("mean"),
        std_radiometer=stack("std_radiometer"), std_calibration=stack("std_calibration"),
        std_reflection=stack("std_reflection"), flags=np.stack([r["flags"] for r in ordered]),
        time_s=times, integration_s=np.array([r["integration"] for r in ordered]),
        lst_h=apparent_lst_h(times, site.longitude_deg),
        solution=np.array([r["solution"] for r in ordered], dtype=np.int64),
        solutions=tuple(solutions), sweeps=tuple(r["sweeps"] for r in ordered),
    )


def _night_flags(g: h5py.Group, rows: dict[int, dict[str, Any]], latest: dict[str, int]) -> None:
    """OR a night's flags into the rows of this chunk it names (each name's latest row)."""
    names = json.loads(attr_text(g.attrs.get("details", "{}"))).get("spectra", [])
    if "flags" not in g or not names:
        return
    flags = np.asarray(g["flags"][()], dtype=bool)
    for name, row_flags in zip(names, flags, strict=False):
        row = rows.get(latest.get(name, -1))
        if row is not None and row["flags"].shape == row_flags.shape:
            row["flags"] = row["flags"] | row_flags


def bin_rows(path: str, start: int, stop: int, edges_h: FloatArray) -> BinnedRun:
    """Rows ``[start, stop)`` of a run binned; the run is named by its first chunk only."""
    binned = bin_run(read_rows(path, start, stop), edges_h)
    return binned if start == 0 else dataclasses.replace(binned, runs=())
