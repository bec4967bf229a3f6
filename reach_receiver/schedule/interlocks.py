"""Static interlock checks: follow the front-end's rails and switches through a step list.

Before anything moves, the compiled steps are walked with a model of the board's state
(rails on/off/unknown, switch positions) to find requests the firmware would refuse
(``firmware/PROTOCOL.md``, "Interlocks"; thesis table A.3, fig. 2.42) or that make no
sense. The walk here is generic: each kind says what it does to the board
(:meth:`~.kinds.StepKind.check_interlocks`, by default: make its connections), and this
module supplies the board model and the rules every kind shares:

* any command to the hardware (a kind with ``needs_devices``) before ``initialise`` has
  connected the devices;
* ``12v`` or ``24v`` off while a switch it drives (layout ``SWITCH_RAIL``) is engaged,
  i.e. after a connection moved it and before ``safe`` (:meth:`BoardCheck.engaged_by`).

What each connection switches is planned by :meth:`FrontEnd.path`, the same planner the
runner uses. Only definite violations are reported: after a step that could not be
read, the state is unknown until the next ``initialise``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

from reach_receiver.config.yaml_lines import Problem
from reach_receiver.devices.board import FrontEndState
from reach_receiver.errors import ConfigError, InterlockError
from reach_receiver.frontend.layout import (
    NOISE_SOURCE,
    SWITCH_POSITIONS,
    SWITCH_RAIL,
    SWITCHABLE_RAILS,
    SourcePosition,
)
from reach_receiver.frontend.paths import FrontEnd, SignalPath

from . import steps as s
from .kinds import KindRegistry
from .limits import Budget

SWITCHES = (*SWITCH_POSITIONS, "mts")
_SAFE_OFF = (NOISE_SOURCE, "6v", "12v")  # PROTOCOL.md, "safe state"


class _NoBoard:
    """A switch matrix for planning only: :meth:`FrontEnd.path` never touches it."""

    def select(self, switch: str, position: int | str) -> None:
        """Refuse: planning only."""
        raise InterlockError("planning only")

    def set_rail(self, rail: str, on: bool) -> None:
        """Refuse: planning only."""
        raise InterlockError("planning only")

    def read_state(self) -> FrontEndState:
        """Refuse: planning only."""
        raise InterlockError("planning only")

    def safe(self) -> FrontEndState:
        """Refuse: planning only."""
        raise InterlockError("planning only")


@dataclass
class BoardCheck:
    """What is known of the board while a step list is walked: ``None`` means unknown.

    Kinds act on it from :meth:`~.kinds.StepKind.check_interlocks`.
    """

    kinds: KindRegistry
    planner: FrontEnd
    initialised: bool | None = False
    rails: dict[str, bool | None] = field(default_factory=lambda: dict.fromkeys(SWITCHABLE_RAILS))
    switches: dict[str, int | str | None] = field(default_factory=lambda: dict.fromkeys(SWITCHES))
    problems: list[Problem] = field(default_factory=list)
    current: s.Step | None = None
    budget: Budget = field(default_factory=Budget)

    def report(self, key: str, message: str) -> None:
        """Record a violation at the line of the step being checked."""
        if self.current is None:
            raise RuntimeError("report outside a step")
        where = self.current.where
        problem = Problem(where.file, where.line, key, message)
        if problem not in self.problems:
            self.problems.append(problem)

    def walk(self, steps: Iterable[s.Step]) -> None:
        """Check steps in order (a kind with nested steps walks them from here)."""
        for step in steps:
            self.check(step)

    def check(self, step: s.Step) -> None:
        """Check one step against what is known, then apply its effect."""
        outer, self.current = self.current, step
        try:
            self.budget.visit(step.where.file, step.where.line, self._key(step))
            if not self.kinds.knows(step):  # could not be read: assume nothing after it
                self.forget()
                return
            kind = self.kinds.of(step)
            if kind.needs_devices and self.initialised is False:
                self.report(kind.name, "comes before 'initialise' has connected the devices")
            kind.check_interlocks(step, self)
        finally:
            self.current = outer

    def _key(self, step: s.Step) -> str:
        return self.kinds.of(step).name if self.kinds.knows(step) else "<step>"

    def forget(self) -> None:
        """Nothing is known any more (after a step that could not be read)."""
        self.initialised = None
        self.rails = dict.fromkeys(SWITCHABLE_RAILS)
        self.switches = dict.fromkeys(SWITCHES)

    def release(self) -> None:
        """The safe state: every switch released, noise source, ``6v`` and ``12v`` off."""
        self.switches = {name: ("lna" if name == "mts" else 0) for name in SWITCHES}
        for rail in _SAFE_OFF:
            self.rails[rail] = False

    def connect(self, source: str, to: str) -> None:
        """Apply the switch settings and rails of one planned connection."""
        try:
            path = self.planner.path(source, "vna" if to == "vna" else "lna")
        except ConfigError:  # an unknown source, already reported
            self.switches = dict.fromkeys(SWITCHES)
            return
        self._apply(path)

    def _apply(self, path: SignalPath) -> None:
        for rail in path.rails_off:
            self.rails[rail] = False
        for rail in path.rails_on:
            self.rails[rail] = True
        for switch, position in path.switches:
            self.switches[switch] = position

    def engaged_by(self, rail: str) -> list[str]:
        """Switches driven by ``rail`` that are known to be away from rest."""
        return [
            name
            for name, position in self.switches.items()
            if SWITCH_RAIL[name] == rail and position is not None and position not in (0, "lna")
        ]


def interlock_problems(
    steps: Sequence[s.Step],
    kinds: KindRegistry,
    sources: Mapping[str, SourcePosition] | None = None,
    budget: Budget | None = None,
) -> list[Problem]:
    """Every interlock violation found by walking ``steps`` from an unknown board state.

    ``sources`` is the site's source table (table A.2 by default); ``budget`` counts
    the steps visited (a repeat's body is walked twice) against their bound.
    """
    planner = FrontEnd(_NoBoard(), sources) if sources is not None else FrontEnd(_NoBoard())
    board = BoardCheck(kinds, planner, budget=budget if budget is not None else Budget())
    board.walk(steps)
    return board.problems
