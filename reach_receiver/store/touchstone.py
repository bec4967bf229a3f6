"""Touchstone files (``.s1p``, ``.s2p``): the engine's reader and writer, re-exported.

The reader and writer live in :mod:`calibration.rf.touchstone` (the engine needs two-port files
for S-parameter corrections, and must not import this package); this module keeps the
receiver side's imports (``reach_receiver.store.touchstone``) working.
"""

from calibration.rf.touchstone import (
    TouchstoneData,
    TouchstoneError,
    read_touchstone,
    read_touchstone_network,
    write_touchstone,
    write_touchstone_network,
)

__all__ = [
    "TouchstoneData",
    "TouchstoneError",
    "read_touchstone",
    "read_touchstone_network",
    "write_touchstone",
    "write_touchstone_network",
]
