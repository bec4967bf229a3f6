"""The front-end board as its firmware sees it: switch and rail names, and its state reply.

These are facts of the Teensy's protocol (``firmware/PROTOCOL.md``; thesis table A.3,
fig. 2.42): which switches exist and how many positions each has, which rails the board
may switch and which it never touches, and the ``state`` reply that reads every output
back. The driver checks requests against them before anything is sent; the front-end
model (:mod:`reach_receiver.frontend`), one layer up, builds its signal paths on them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from reach_receiver.errors import ProtocolError

#: Number of positions of each single-pole switch (table A.2); 0 means released.
SWITCH_POSITIONS: Mapping[str, int] = MappingProxyType({"ms1": 8, "ms2": 6, "ms3": 4, "ms4": 4})

#: The transfer switch's two states: sources to the LNA, or sources and LNA to the VNA.
MTS_STATES: tuple[str, str] = ("lna", "vna")

#: Rails the microcontroller may switch (table A.3, fig. 2.42); ``6v`` feeds the LNA.
SWITCHABLE_RAILS: tuple[str, ...] = ("6v", "12v", "24v", "ns", "fan", "tec")

#: Rails that are never switched: switching 5 V off loses the instrument (table A.3).
FIXED_RAILS: tuple[str, ...] = ("3v3", "5v")

DEVICE = "teensy"


@dataclass(frozen=True)
class FrontEndState:
    """The board's outputs as ``state`` reports them.

    ``switches`` maps ``ms1``-``ms4`` to positions (0 = released) and ``mts`` to
    ``"lna"`` or ``"vna"``; ``rails`` maps each switchable rail to on/off. ``boot`` is
    ``por`` or ``wdog``, ``uptime_ms`` the time since that start, ``changes`` the outputs
    changed since it (by anything: a command, ``safe``, the dead-man switch) and
    ``deadman_ms`` the armed dead-man timeout (0 when off).
    """

    switches: Mapping[str, int | str]
    rails: Mapping[str, bool]
    boot: str
    uptime_ms: int
    changes: int
    deadman_ms: int

    @classmethod
    def parse(cls, payload: str) -> FrontEndState:
        """Read a ``state`` payload, ``ms1=4 ... boot=por uptime_ms=1234 changes=7 deadman=0``."""
        fields = dict(item.split("=", 1) for item in payload.split() if "=" in item)
        try:
            switches: dict[str, int | str] = {s: int(fields[s]) for s in SWITCH_POSITIONS}
            switches["mts"] = fields["mts"]
            rails = {r: fields[r] == "1" for r in SWITCHABLE_RAILS}
            state = cls(
                MappingProxyType(switches),
                MappingProxyType(rails),
                fields["boot"],
                int(fields["uptime_ms"]),
                int(fields["changes"]),
                int(fields["deadman"]),
            )
        except (KeyError, ValueError) as err:
            raise ProtocolError(DEVICE, f"malformed state reply {payload!r}", "state") from err
        if switches["mts"] not in MTS_STATES:
            raise ProtocolError(DEVICE, f"unknown MTS state in {payload!r}", "state")
        return state

    def as_pins(self) -> dict[str, str]:
        """The state in the firmware's own ``name=value`` strings."""
        out = {name: str(value) for name, value in self.switches.items()}
        out.update({rail: "1" if on else "0" for rail, on in self.rails.items()})
        return out

    @property
    def is_safe(self) -> bool:
        """Whether this is the safe state: every switch released, ``ns``, ``6v``, ``12v`` off.

        PROTOCOL.md, "safe state"; ``24v``, the fan and the TEC keep their state.
        """
        released = all(self.switches[s] == 0 for s in SWITCH_POSITIONS)
        return released and self.switches["mts"] == "lna" and not any(
            self.rails[r] for r in ("ns", "6v", "12v")
        )

    def same_outputs_as(self, other: FrontEndState) -> bool:
        """Whether every switch and rail reads the same in both states."""
        return self.switches == other.switches and self.rails == other.rails

    def change_since(self, earlier: FrontEndState) -> str | None:
        """What moved on the board between ``earlier`` and this state; ``None`` if nothing.

        Nothing moved when the board did not restart (same ``boot``, ``uptime_ms`` not
        smaller) and no output changed (same ``changes``). A restart releases every
        switch, so it always counts, even if the outputs read the same afterwards.
        ``uptime_ms`` wraps after 49.7 days: a wrap reads as a restart (a false alarm,
        never a missed one).
        """
        if self.boot != earlier.boot or self.uptime_ms < earlier.uptime_ms:
            return (
                f"board restarted (boot={self.boot}, uptime {earlier.uptime_ms} -> "
                f"{self.uptime_ms} ms, outputs now {self.describe()})"
            )
        if self.changes != earlier.changes:
            moved = self.changes - earlier.changes
            return f"{moved} output change(s) (now {self.describe()})"
        return None

    def unchanged_since(self, earlier: FrontEndState) -> bool:
        """Whether nothing moved on the board since ``earlier`` (:meth:`change_since`)."""
        return self.change_since(earlier) is None

    def describe(self) -> str:
        """The outputs in the firmware's words, ``ms1=4 ... mts=lna 6v=1 ...``."""
        return " ".join(f"{name}={value}" for name, value in self.as_pins().items())
