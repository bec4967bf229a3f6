"""Static interlock checks: follow the front-end's rails and switches through a step list.

Before anything moves, the compiled steps are walked with a model of the board's state
(rails on/off/unknown, switch positions) to find requests the firmware would refuse
(``firmware/PROTOCOL.md``, "Interlocks"; thesis table A.3, fig. 2.42) or that make no
sense:

* any command to the hardware (power, connect, a measurement, the TEC, thermocouple
  logging) before ``initialise`` has connected the devices;
* ``3v3`` and ``5v`` are never switched (checked where the rails are read);
* ``24v`` off while the fan, which it feeds, is on; the fan on while ``24v`` is off;
* ``12v`` or ``24v`` off while a switch it drives (layout ``SWITCH_RAIL``) is engaged,
  i.e. after a connect or a measurement that moved it and before ``safe``;
* a ``tec`` step while rail ``tec`` is off.

What each connection switches is planned by :meth:`FrontEnd.path`, the same planner the
runner uses. ``initialise`` goes to the safe state (noise source, every switch, ``6v``
and ``12v`` off; ``24v``, fan and TEC keep a state that is unknown here) and then
switches its ``rails`` on. Only definite violations are reported: after a step that
could not be read, the state is unknown until the next ``initialise``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

from reach_receiver.devices.board import FrontEndState
from reach_receiver.errors import ConfigError, InterlockError
from reach_receiver.frontend.layout import (
    NOISE_SOURCE,
    REFERENCE_LOAD,
    SWITCH_POSITIONS,
    SWITCH_RAIL,
    SWITCHABLE_RAILS,
    SourcePosition,
)
from reach_receiver.frontend.paths import FrontEnd, SignalPath

from . import steps as s
from .step_parsers import Unparsed
from .yaml_lines import Problem

#: Steps that command the hardware and so need ``initialise`` first.
NEEDS_DEVICES = (
    s.Power,
    s.Connect,
    s.VnaCalibrate,
    s.TestLoadCheck,
    s.MeasureS11,
    s.MeasureSpectrum,
    s.Dicke,
    s.Temperatures,
    s.Tec,
    s.Observe,
)
_SWITCHES = (*SWITCH_POSITIONS, "mts")
_SAFE_OFF = (NOISE_SOURCE, "6v", "12v")  # PROTOCOL.md, "safe state"
_SOL = ("short", "open", "load")


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


PLANNER = FrontEnd(_NoBoard())


def connections(step: s.Step) -> list[tuple[str, str]]:
    """The (source, destination) connections a step makes, in order."""
    if isinstance(step, s.Connect):
        return [(step.source, step.to)]
    if isinstance(step, s.VnaCalibrate):
        return [(standard, "vna") for standard in _SOL]
    if isinstance(step, s.TestLoadCheck):  # a failed check recalibrates
        return [("test_load", "vna"), *((standard, "vna") for standard in _SOL)]
    if isinstance(step, s.MeasureS11):
        return [(target, "vna") for target in step.targets]
    if isinstance(step, s.MeasureSpectrum):
        return [(step.source, "lna")]
    if isinstance(step, s.Dicke | s.Observe):
        sources = step.sources if isinstance(step, s.Dicke) else (step.source,)
        dicke = [(x, "lna") for src in sources for x in (src, REFERENCE_LOAD, NOISE_SOURCE)]
        return dicke + ([("test_load", "vna")] if isinstance(step, s.Observe) else [])
    return []


@dataclass
class _Board:
    """What is known of the board: ``None`` means unknown."""

    initialised: bool | None = False
    rails: dict[str, bool | None] = field(default_factory=lambda: dict.fromkeys(SWITCHABLE_RAILS))
    switches: dict[str, int | str | None] = field(default_factory=lambda: dict.fromkeys(_SWITCHES))

    def forget(self) -> None:
        self.initialised = None
        self.rails = dict.fromkeys(SWITCHABLE_RAILS)
        self.switches = dict.fromkeys(_SWITCHES)

    def release(self) -> None:
        self.switches = {name: ("lna" if name == "mts" else 0) for name in _SWITCHES}
        for rail in _SAFE_OFF:
            self.rails[rail] = False

    def apply(self, path: SignalPath) -> None:
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


class _Checker:
    def __init__(self, planner: FrontEnd) -> None:
        self.planner = planner
        self.board = _Board()
        self.problems: list[Problem] = []

    def report(self, step: s.Step, key: str, message: str) -> None:
        problem = Problem(step.where.file, step.where.line, key, message)
        if problem not in self.problems:
            self.problems.append(problem)

    def walk(self, steps: Iterable[s.Step]) -> None:
        for step in steps:
            self.check(step)

    def check(self, step: s.Step) -> None:
        board = self.board
        if isinstance(step, NEEDS_DEVICES) and board.initialised is False:
            self.report(step, _kind(step), "comes before 'initialise' has connected the devices")
        if isinstance(step, s.Initialise):
            board.initialised = True
            board.release()
            for rail in step.rails:
                board.rails[rail] = True
        elif isinstance(step, s.Safe):
            board.release()
        elif isinstance(step, s.Power):
            for rail, on in step.states:
                self._power(step, rail, on)
        elif isinstance(step, s.Tec):
            if board.rails.get("tec") is False:
                self.report(step, "tec", "rail tec is off: power it first ({tec: on})")
        elif isinstance(step, s.Repeat):
            self.walk(step.steps)
            if step.count > 1:  # the second pass starts from the state the first left
                self.walk(step.steps)
        elif isinstance(step, Unparsed):
            board.forget()
        for source, to in connections(step):
            try:
                board.apply(self.planner.path(source, "vna" if to == "vna" else "lna"))
            except ConfigError:  # an unknown source, already reported
                board.switches = dict.fromkeys(_SWITCHES)

    def _power(self, step: s.Power, rail: str, on: bool) -> None:
        board = self.board
        key = f"power.{rail}"
        if on and rail == "fan" and board.rails.get("24v") is False:
            self.report(step, key, "the fan runs from 24v, which is off: switch 24v on first")
        if not on and rail == "24v" and board.rails.get("fan") is True:
            self.report(step, key, "24v feeds the fan, which is on: switch the fan off first")
        if not on and rail in ("12v", "24v"):
            engaged = board.engaged_by(rail)
            if engaged:
                self.report(
                    step,
                    key,
                    f"{rail} drives {', '.join(engaged)}, engaged since a connection: "
                    "put the front-end in its safe state ('safe') first",
                )
        board.rails[rail] = on


def _kind(step: s.Step) -> str:
    names = {
        s.MeasureS11: "s11",
        s.MeasureSpectrum: "spectrum",
        s.VnaCalibrate: "vna_calibrate",
        s.TestLoadCheck: "test_load_check",
    }
    return names.get(type(step), type(step).__name__.lower())


def interlock_problems(
    steps: Sequence[s.Step], sources: Mapping[str, SourcePosition] | None = None
) -> list[Problem]:
    """Every interlock violation found by walking ``steps`` from an unknown board state.

    ``sources`` is the site's source table (table A.2 by default).
    """
    checker = _Checker(FrontEnd(_NoBoard(), sources) if sources is not None else PLANNER)
    checker.walk(steps)
    return checker.problems
