"""The REACH front-end's contents as data: thesis tables A.1-A.3 and fig. 2.42.

Which source sits behind which switch position, which rail drives which switch, which
rails may be switched at all. Declared once here; the front-end model turns it into
switch states, the simulated receiver reads it backwards to know what is connected, and
a site file may override the source table when a deployment rewires the front-end.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

# The board's own names (the firmware protocol), re-exported with the front-end's facts.
from reach_receiver.devices.board import (
    FIXED_RAILS,
    MTS_STATES,
    SWITCH_POSITIONS,
    SWITCHABLE_RAILS,
)

__all__ = [
    "FIXED_RAILS",
    "MS2_TO_LNA",
    "MS2_TO_SOURCES",
    "MTS_STATES",
    "NOISE_SOURCE",
    "REACH_SOURCES",
    "REFERENCE_LOAD",
    "SOURCE_THERMOCOUPLE",
    "SWITCHABLE_RAILS",
    "SWITCH_POSITIONS",
    "SWITCH_RAIL",
    "TC08_PORTS",
    "VNA_STANDARDS",
    "SourcePosition",
    "source_at",
]

#: The rail that drives each switch (table A.1: MS1 12 V, MS2 and MTS 24 V; MS3 and MS4
#: are taken as 12 V parts, their model records being lost).
SWITCH_RAIL: Mapping[str, str] = MappingProxyType(
    {"ms1": "12v", "ms2": "24v", "ms3": "12v", "ms4": "12v", "mts": "24v"}
)

#: MS2 positions (table A.2): the two VNA paths and the VNA's standards.
MS2_TO_SOURCES = 1
MS2_TO_LNA = 2
VNA_STANDARDS: Mapping[str, int] = MappingProxyType(
    {"short": 3, "open": 4, "load": 5, "test_load": 6}
)


@dataclass(frozen=True)
class SourcePosition:
    """Where a source sits: an MS1 position, and for cable-terminated ones MS3 or MS4 too."""

    ms1: int
    termination: tuple[str, int] | None = None

    def switch_states(self) -> dict[str, int]:
        """The single-pole switch positions that select this source (MS3/MS4 released otherwise)."""
        states = {"ms1": self.ms1, "ms3": 0, "ms4": 0}
        if self.termination is not None:
            switch, position = self.termination
            states[switch] = position
        return states


#: Table A.2 under REACH's source names (the names of REACH's HDF5 files).
REACH_SOURCES: Mapping[str, SourcePosition] = MappingProxyType(
    {
        "ant": SourcePosition(1),
        "hot": SourcePosition(2),
        "ns": SourcePosition(3),
        "cold": SourcePosition(4),
        "r25": SourcePosition(5),
        "r100": SourcePosition(6),
        "c2r36": SourcePosition(7, ("ms3", 1)),
        "c2r27": SourcePosition(7, ("ms3", 2)),
        "c2r69": SourcePosition(7, ("ms3", 3)),
        "c2r91": SourcePosition(7, ("ms3", 4)),
        "c10open": SourcePosition(8, ("ms4", 1)),
        "c10short": SourcePosition(8, ("ms4", 2)),
        "c10r10": SourcePosition(8, ("ms4", 3)),
        "c10r250": SourcePosition(8, ("ms4", 4)),
    }
)

#: The Dicke cycle's references: the ambient 50 ohm load (thesis 2.1.1: the deployment
#: used the ambient calibrator itself) and the NC346A noise diode.
REFERENCE_LOAD = "cold"
NOISE_SOURCE = "ns"
#: The noise diode's model, written into every run file (``noise_source_model``): the
#: engine holds a fitted T_NS to this diode's ENR table only where a run names it.
NOISE_SOURCE_MODEL = "NC346A"  # calibration.io.hdf5_io.NC346A, without importing h5py

#: TC-08 ports (thesis table 2.2); port 0 is the logger's cold junction.
TC08_PORTS: Mapping[int, str] = MappingProxyType(
    {
        0: "cold_junction",
        1: "ms1",
        2: "hot",
        3: "ms3",
        4: "ms4",
        5: "cable_2m",
        6: "cable_10m",
        7: "lna",
        8: "antenna",
    }
)

#: The TC-08 port whose reading is each source's physical temperature.
SOURCE_THERMOCOUPLE: Mapping[str, int] = MappingProxyType(
    {
        "hot": 2,
        "cold": 1,
        "r25": 1,
        "r100": 1,
        "ns": 1,
        "c2r27": 3,
        "c2r36": 3,
        "c2r69": 3,
        "c2r91": 3,
        "c10open": 4,
        "c10short": 4,
        "c10r10": 4,
        "c10r250": 4,
        "ant": 8,
    }
)


def source_at(
    ms1: int, ms3: int, ms4: int, sources: Mapping[str, SourcePosition] = REACH_SOURCES
) -> str | None:
    """The source that MS1/MS3/MS4 select, or ``None`` when nothing is connected."""
    for name, place in sources.items():
        if place.ms1 != ms1:
            continue
        if place.termination is None:
            return name
        switch, position = place.termination
        if (ms3 if switch == "ms3" else ms4) == position:
            return name
    return None
