"""The run store: one self-describing, crash-safe HDF5 file per run.

A run is written as one part file per measurement (:mod:`.parts`, atomic and durable
before ``add_*`` returns) by :class:`RunStore`, and merged into ``run.h5`` at the end
(:func:`merge_run`, also the recovery of a killed run). The merged file carries the
measurements as taken and the REACH layout that :func:`calibration.io.hdf5_io.read_run`
reads (:mod:`.merge`). :func:`read_run_file` reads a run back, merged or not;
:mod:`.touchstone` re-exports the engine's Touchstone S1P/S2P reader and writer.
:mod:`.handover` is the one place where a run's measurements become the calibration
engine's input. :mod:`reach_receiver.disk` refuses, by name, a write the disk has no room for.
"""

from reach_receiver.disk import DiskFull

from .handover import HandOver
from .measurements import DICKE_POSITIONS
from .merge import RUN_FILE, merge_run
from .parts import StoreError
from .reader import Measurement, RunContents, read_run_file
from .run_store import EngineView, RunStore, software_versions
from .touchstone import TouchstoneError, read_touchstone, write_touchstone

__all__ = [
    "DICKE_POSITIONS",
    "RUN_FILE",
    "DiskFull",
    "EngineView",
    "HandOver",
    "Measurement",
    "RunContents",
    "RunStore",
    "StoreError",
    "TouchstoneError",
    "merge_run",
    "read_run_file",
    "read_touchstone",
    "software_versions",
    "write_touchstone",
]
