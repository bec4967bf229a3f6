"""Signal paths: turn "connect this source to the LNA (or the VNA)" into switch states.

The front-end model knows the contents of every switch position (:mod:`.layout`, table
A.2) and the safety rules (table A.3, fig. 2.42); it talks to the board through the small
:class:`~reach_receiver.devices.protocols.SwitchMatrix` protocol, which the Teensy driver
implements. Rules are checked here before any command is sent, and again by the firmware:

* a switch moves only while its drive rail is on, so :meth:`FrontEnd.connect` powers the
  rails a path needs before it moves anything;
* the noise source is powered exactly while it is connected to the LNA (a Dicke cycle's
  third position) and off otherwise;
* the 3.3 V and 5 V rails are never touched.

Path to the LNA: MTS ``lna``, MS1 at the source (and MS3 or MS4 for the cable-terminated
ones). Path to the VNA: MTS ``vna``, MS2 at 1 (sources) or 2 (the LNA itself), or MS2 at a
standard (short, open, load, test load).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

from reach_receiver.devices.board import FrontEndState
from reach_receiver.devices.protocols import SwitchMatrix
from reach_receiver.errors import ConfigError, InterlockError

from .layout import (
    MS2_TO_LNA,
    MS2_TO_SOURCES,
    NOISE_SOURCE,
    REACH_SOURCES,
    SWITCH_RAIL,
    VNA_STANDARDS,
    SourcePosition,
)

log = logging.getLogger(__name__)

Destination = Literal["lna", "vna"]


@dataclass(frozen=True)
class SignalPath:
    """An ordered list of switch settings and the rails that must be on (or off) first."""

    description: str
    rails_on: tuple[str, ...]
    rails_off: tuple[str, ...]
    switches: tuple[tuple[str, int | str], ...]


class FrontEnd:
    """The front-end's signal paths over a :class:`SwitchMatrix`.

    Parameters
    ----------
    matrix
        The microcontroller (the Teensy driver, or anything with the same four methods).
    sources
        Source name -> switch position; table A.2 by default, a site file may override it.
    """

    def __init__(
        self, matrix: SwitchMatrix, sources: Mapping[str, SourcePosition] = REACH_SOURCES
    ) -> None:
        self.matrix = matrix
        self.sources = dict(sources)

    # ----------------------------------------------------------------- pure planning
    def path(self, source: str, to: Destination = "lna") -> SignalPath:
        """The switch settings that connect ``source`` to the LNA or the VNA.

        ``source`` is a source name, or for the VNA also ``lna`` or one of the standards
        ``short``, ``open``, ``load``, ``test_load``.
        """
        if to == "vna" and source in VNA_STANDARDS:
            standard = (("ms2", VNA_STANDARDS[source]),)
            return SignalPath(f"VNA standard {source}", ("24v",), (NOISE_SOURCE,), standard)
        if to == "vna" and source == "lna":
            return SignalPath(
                "LNA to the VNA", ("24v",), (NOISE_SOURCE,), (("mts", "vna"), ("ms2", MS2_TO_LNA))
            )
        if source not in self.sources:
            known = ", ".join(sorted(self.sources))
            raise ConfigError(f"unknown source {source!r}; known sources: {known}")
        if to not in ("lna", "vna"):
            raise ConfigError(f"a source connects to 'lna' or 'vna', not {to!r}")
        positions = self.sources[source].switch_states()
        singles: tuple[tuple[str, int | str], ...] = tuple(
            (switch, positions[switch]) for switch in ("ms3", "ms4", "ms1")
        )
        if to == "lna":
            powered = source == NOISE_SOURCE
            rails_on = ("12v", "24v", "6v") + ((NOISE_SOURCE,) if powered else ())
            rails_off = () if powered else (NOISE_SOURCE,)
            return SignalPath(
                f"{source} to the LNA", rails_on, rails_off, (("mts", "lna"), *singles)
            )
        return SignalPath(
            f"{source} to the VNA",
            ("12v", "24v"),
            (NOISE_SOURCE,),
            (*singles, ("mts", "vna"), ("ms2", MS2_TO_SOURCES)),
        )

    # ----------------------------------------------------------------- actions
    def connect(self, source: str, to: Destination = "lna") -> FrontEndState:
        """Connect ``source`` to the LNA or the VNA and return the state read back.

        The board's state is read back at the end and compared with the plan, so a
        switch that did not move is an error here rather than a wrong measurement later.
        """
        path = self.path(source, to)
        log.info("front-end: %s", path.description)
        for rail in path.rails_off:
            self.matrix.set_rail(rail, False)
        for rail in path.rails_on:
            if rail == NOISE_SOURCE:
                continue
            self.matrix.set_rail(rail, True)
        for switch, position in path.switches:
            self.matrix.select(switch, position)
        if NOISE_SOURCE in path.rails_on:
            self.matrix.set_rail(NOISE_SOURCE, True)
        state = self.matrix.read_state()
        self._verify(path, state)
        return state

    def safe(self) -> FrontEndState:
        """Put the front-end in its safe state."""
        log.info("front-end: going to the safe state")
        return self.matrix.safe()

    @staticmethod
    def _verify(path: SignalPath, state: FrontEndState) -> None:
        for switch, position in path.switches:
            if state.switches.get(switch) != position:
                raise InterlockError(
                    f"{path.description}: {switch} reads {state.switches.get(switch)!r}, "
                    f"expected {position!r}"
                )
        for rail in path.rails_on:
            if not state.rails.get(rail, False):
                raise InterlockError(f"{path.description}: rail {rail} reads off")
        for rail in path.rails_off:
            if state.rails.get(rail, False):
                raise InterlockError(f"{path.description}: rail {rail} reads on")

    @staticmethod
    def rail_for(switch: str) -> str:
        """The rail that drives ``switch``."""
        return SWITCH_RAIL[switch]
