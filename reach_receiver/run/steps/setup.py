"""Set-up kinds: bring the receiver up, switch rails and paths, hold the enclosure, wait.

==================  =====================================================================
``initialise``      connect every device, safe state, switch on ``rails``, start the
                    temperature log (every 10 s)
``power``           switch rails on or off: ``{12v: on, fan: off}``
``connect``         ``{source: hot, to: lna}`` (``to``: ``lna`` or ``vna``)
``safe``            the front-end's safe state
``temperatures``    ``{period_s: 10}``: (re)start the background thermocouple log
``tec``             ``{setpoint_c: 25, wait: {tolerance_c: 0.1, hold_s: 300, timeout_s: 7200}}``
``wait``            ``{seconds: 60}``, ``{until_utc: "2026-11-22T18:00Z"}``, ``{until_lst_h: 4.5}``
==================  =====================================================================
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import date, datetime, timezone
from typing import Literal, cast

from reach_receiver.config.fields import REQUIRED, UNRESOLVED, Fields, closest, type_name
from reach_receiver.devices.tec_frames import TecStatus
from reach_receiver.frontend.layout import FIXED_RAILS, SWITCHABLE_RAILS
from reach_receiver.schedule.interlocks import BoardCheck
from reach_receiver.schedule.lst import next_utc_at_lst
from reach_receiver.schedule.parsing import ParseContext
from reach_receiver.schedule.steps import Step, Where
from reach_receiver.schedule.timing import TimingWalk, as_utc, hms

from ..context import RunContext
from ..kind import RunnableKind

log = logging.getLogger(__name__)

#: The setpoints the enclosure's TEC may be asked for (C).
TEC_RANGE_C = (5.0, 45.0)
#: Rails in a safe switch-on order: the switch supplies before what depends on them.
POWER_ORDER = ("12v", "24v", "6v", "fan", "tec", "ns")
#: How often ``initialise`` starts the temperature log (s).
DEFAULT_TEMPERATURE_PERIOD_S = 10.0


def power_order(rails: tuple[str, ...]) -> list[str]:
    """Rails in :data:`POWER_ORDER`."""
    last = len(POWER_ORDER)
    return sorted(rails, key=lambda r: POWER_ORDER.index(r) if r in POWER_ORDER else last)


# --------------------------------------------------------------------------- initialise
@dataclass(frozen=True)
class Initialise(Step):
    """Connect the devices, put the front-end in its safe state, then power ``rails``."""

    rails: tuple[str, ...] = ("12v", "24v", "6v", "fan", "tec")


class InitialiseKind(RunnableKind[Initialise]):
    """``initialise``."""

    name = "initialise"
    step_type = Initialise
    keys = ("rails",)
    needs_devices = False
    on_resume = "replay"

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> Initialise:
        """``rails``: the switchable rails to power, in any order."""
        if not f.has("rails"):
            return Initialise(where)
        rails = f.names("rails", (*SWITCHABLE_RAILS, *FIXED_RAILS), "rail", empty=True)
        for rail in rails:
            if rail in FIXED_RAILS:
                f.report("rails", f"rail {rail} is never switched (thesis table A.3)")
        return Initialise(where, tuple(r for r in rails if r in SWITCHABLE_RAILS))

    def describe(self, step: Initialise) -> str:
        """Which rails come on."""
        return f"initialise, rails {', '.join(step.rails) or 'none'} on"

    def duration(self, step: Initialise, walk: TimingWalk) -> float:
        """5 s."""
        return 5.0

    def check_interlocks(self, step: Initialise, board: BoardCheck) -> None:
        """Safe state, then the rails on."""
        board.initialised = True
        board.release()
        for rail in step.rails:
            board.rails[rail] = True

    def execute(self, step: Initialise, run: RunContext) -> None:
        """Connect everything, go safe, power the rails, start the temperature log."""
        devices = run.instruments
        devices.connect()
        devices.frontend.safe()
        for rail in power_order(step.rails):
            devices.teensy.set_rail(rail, True)
        if "tec" in step.rails:
            devices.connect_tec()
        run.log_temperatures(DEFAULT_TEMPERATURE_PERIOD_S)


# --------------------------------------------------------------------------- power
@dataclass(frozen=True)
class Power(Step):
    """Switch rails: ``states`` maps rail name to on (True) or off."""

    states: tuple[tuple[str, bool], ...]


class PowerKind(RunnableKind[Power]):
    """``power``: its keys are rail names."""

    name = "power"
    step_type = Power
    keys = (*SWITCHABLE_RAILS, *FIXED_RAILS)
    on_resume = "replay"

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> Power:
        """``{rail: on|off, ...}``; ``3v3`` and ``5v`` are refused."""
        states: list[tuple[str, bool]] = []
        for rail in f.args:
            if rail in FIXED_RAILS:
                f.report(rail, f"rail {rail} is never switched (thesis table A.3)")
                continue
            if rail not in SWITCHABLE_RAILS:
                continue  # reported as an unknown key
            value = f.raw(str(rail))
            if value is UNRESOLVED:
                continue
            if not isinstance(value, bool):
                f.report(rail, f"must be on or off, not {type_name(value)}")
                continue
            states.append((str(rail), value))
        if not f.args:
            f.report("<rails>", "name at least one rail: {12v: on, fan: off}", f.args.line)
        return Power(where, tuple(states))

    def describe(self, step: Power) -> str:
        """Each rail and its new state."""
        return "power " + ", ".join(f"{r} {'on' if on else 'off'}" for r, on in step.states)

    def duration(self, step: Power, walk: TimingWalk) -> float:
        """1 s."""
        return 1.0

    def check_interlocks(self, step: Power, board: BoardCheck) -> None:
        """The fan lives on ``24v``; ``12v``/``24v`` must not drop under an engaged switch."""
        for rail, on in step.states:
            key = f"power.{rail}"
            if on and rail == "fan" and board.rails.get("24v") is False:
                board.report(key, "the fan runs from 24v, which is off: switch 24v on first")
            if not on and rail == "24v" and board.rails.get("fan") is True:
                board.report(key, "24v feeds the fan, which is on: switch the fan off first")
            if not on and rail in ("12v", "24v"):
                engaged = board.engaged_by(rail)
                if engaged:
                    board.report(
                        key,
                        f"{rail} drives {', '.join(engaged)}, engaged since a connection: "
                        "put the front-end in its safe state ('safe') first",
                    )
            board.rails[rail] = on

    def execute(self, step: Power, run: RunContext) -> None:
        """Switch the rails in the order written."""
        for rail, on in step.states:
            run.instruments.teensy.set_rail(rail, on)


# --------------------------------------------------------------------------- connect
@dataclass(frozen=True)
class Connect(Step):
    """Connect a source (or ``lna``, or a VNA standard) to the LNA or the VNA."""

    source: str
    to: Literal["lna", "vna"] = "lna"


class ConnectKind(RunnableKind[Connect]):
    """``connect``."""

    name = "connect"
    step_type = Connect
    keys = ("source", "to")
    on_resume = "replay"

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> Connect:
        """``source`` (a source; for the VNA also ``lna`` or a standard) and ``to``."""
        to = f.choice("to", ("lna", "vna"), "lna") or "lna"
        source = f.text("source")
        known = ctx.vna_targets if to == "vna" else ctx.sources
        if source is not None and source not in known:
            f.report(
                "source",
                f"unknown source {source!r} for the {to.upper()}{closest(source, known)} "
                f"(known: {', '.join(known)})",
            )
        return Connect(where, source or "", cast(Literal["lna", "vna"], to))

    def describe(self, step: Connect) -> str:
        """What goes where."""
        return f"connect {step.source} to the {step.to.upper()}"

    def duration(self, step: Connect, walk: TimingWalk) -> float:
        """1 s."""
        return 1.0

    def connections(self, step: Connect) -> list[tuple[str, str]]:
        """The one connection."""
        return [(step.source, step.to)]

    def execute(self, step: Connect, run: RunContext) -> None:
        """Make the connection (the state read back is checked)."""
        run.instruments.frontend.connect(step.source, step.to)


# --------------------------------------------------------------------------- safe
@dataclass(frozen=True)
class Safe(Step):
    """Put the front-end in its safe state."""


class SafeKind(RunnableKind[Safe]):
    """``safe``."""

    name = "safe"
    step_type = Safe
    needs_devices = False

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> Safe:
        """No arguments."""
        return Safe(where)

    def describe(self, step: Safe) -> str:
        """The safe state."""
        return "safe state"

    def duration(self, step: Safe, walk: TimingWalk) -> float:
        """1 s."""
        return 1.0

    def check_interlocks(self, step: Safe, board: BoardCheck) -> None:
        """Every switch released, noise source, ``6v`` and ``12v`` off."""
        board.release()

    def execute(self, step: Safe, run: RunContext) -> None:
        """The front-end's safe state, through the run's link or one opened for it.

        ``safe`` needs nothing before it: a schedule of just ``steps: [safe]`` is the
        way to make the front-end safe from a script or a timer.
        """
        run.instruments.make_safe()


# --------------------------------------------------------------------------- temperatures
@dataclass(frozen=True)
class Temperatures(Step):
    """(Re)start background thermocouple logging every ``period_s``."""

    period_s: float = DEFAULT_TEMPERATURE_PERIOD_S


class TemperaturesKind(RunnableKind[Temperatures]):
    """``temperatures``."""

    name = "temperatures"
    step_type = Temperatures
    keys = ("period_s",)
    on_resume = "replay"

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> Temperatures:
        """``period_s``: seconds between readings."""
        return Temperatures(where, f.seconds("period_s", DEFAULT_TEMPERATURE_PERIOD_S))

    def describe(self, step: Temperatures) -> str:
        """The logging period."""
        return f"temperatures every {step.period_s:g} s"

    def execute(self, step: Temperatures, run: RunContext) -> None:
        """(Re)start the log."""
        run.log_temperatures(step.period_s)


# --------------------------------------------------------------------------- tec
@dataclass(frozen=True)
class WaitStable:
    """How the TEC step waits for the enclosure to settle."""

    tolerance_c: float = 0.1
    hold_s: float = 300.0
    timeout_s: float = 7200.0


@dataclass(frozen=True)
class Tec(Step):
    """Set the enclosure's temperature; optionally wait until it is stable."""

    setpoint_c: float
    wait: WaitStable | None = None


class TecKind(RunnableKind[Tec]):
    """``tec``."""

    name = "tec"
    step_type = Tec
    keys = ("setpoint_c", "wait")
    on_resume = "replay"

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> Tec:
        """``setpoint_c`` in :data:`TEC_RANGE_C`; ``wait``: true or its settings."""
        low, high = TEC_RANGE_C
        setpoint = f.number("setpoint_c", REQUIRED, low=low, high=high, fallback=25.0)
        wait: WaitStable | None = None
        written = f.raw("wait", None)
        if isinstance(written, bool):
            wait = WaitStable() if written else None
        elif written is not None and written is not UNRESOLVED:
            sub = f.mapping("wait", ("tolerance_c", "hold_s", "timeout_s"))
            if sub is not None:
                defaults = WaitStable()
                hold = sub.seconds("hold_s", defaults.hold_s)
                timeout = sub.seconds("timeout_s", defaults.timeout_s)
                if not sub.failed and timeout < hold:
                    message = f"must be at least hold_s ({hold:g} s), not {timeout:g}"
                    sub.report("timeout_s", message)
                tolerance = sub.seconds("tolerance_c", defaults.tolerance_c)
                wait = WaitStable(tolerance, hold, timeout)
        return Tec(where, setpoint, wait)

    def describe(self, step: Tec) -> str:
        """The setpoint and the hold."""
        text = f"TEC setpoint {step.setpoint_c:g} C"
        if step.wait is not None:
            text += f", wait {hms(step.wait.hold_s)} within {step.wait.tolerance_c:g} C"
        return text

    def duration(self, step: Tec, walk: TimingWalk) -> float:
        """The hold when waiting (at least that), else 1 s."""
        return step.wait.hold_s if step.wait else 1.0

    def check_interlocks(self, step: Tec, board: BoardCheck) -> None:
        """The TEC needs its rail."""
        if board.rails.get("tec") is False:
            board.report("tec", "rail tec is off: power it first ({tec: on})")

    def execute(self, step: Tec, run: RunContext) -> None:
        """Set the setpoint (read back) and, if asked, wait until the enclosure holds it."""
        run.instruments.connect_tec()
        tec = run.instruments.tec
        tec.set_setpoint(step.setpoint_c)
        if step.wait is None:
            return
        wait, start = step.wait, run.clock.now()

        def on_poll(status: TecStatus) -> None:
            run.stop.check()
            elapsed = run.clock.now() - start
            text = f"enclosure {status.temperature:.3f} C, setpoint {status.setpoint:g} C"
            run.progress.update(text, round(elapsed), round(wait.timeout_s), None)

        status = tec.wait_until_stable(
            wait.tolerance_c, wait.hold_s, wait.timeout_s, on_poll=on_poll
        )
        log.info("enclosure stable at %.3f C", status.temperature)


# --------------------------------------------------------------------------- wait
@dataclass(frozen=True)
class Wait(Step):
    """Wait a duration, until a UTC time, or until a local sidereal time (hours)."""

    seconds: float | None = None
    until_utc: datetime | None = None
    until_lst_h: float | None = None


def _utc(f: Fields, name: str) -> datetime | None:
    value = f.raw(name)
    if value is UNRESOLVED:
        return None
    if isinstance(value, str):
        try:
            value = datetime.fromisoformat(value.strip().replace("Z", "+00:00"))
        except ValueError:
            f.report(name, f"must be an ISO 8601 time such as 2026-11-22T18:00Z, not {value!r}")
            return None
    if not isinstance(value, datetime):
        kind = "a date without a time" if isinstance(value, date) else type_name(value)
        f.report(name, f"must be a UTC time such as 2026-11-22T18:00Z, not {kind}")
        return None
    if value.tzinfo is None:
        return value.replace(tzinfo=timezone.utc)  # the key says UTC
    return value.astimezone(timezone.utc)


class WaitKind(RunnableKind[Wait]):
    """``wait``."""

    name = "wait"
    step_type = Wait
    keys = ("seconds", "until_utc", "until_lst_h")
    needs_devices = False

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> Wait:
        """Exactly one of ``seconds``, ``until_utc``, ``until_lst_h``."""
        written = [name for name in self.keys if f.has(name)]
        if len(written) != 1:
            f.report(
                "<how>",
                "give exactly one of seconds, until_utc, until_lst_h"
                + (f", not {' and '.join(written)}" if written else ""),
                f.args.line,
            )
        return Wait(
            where,
            seconds=f.seconds("seconds") if f.has("seconds") else None,
            until_utc=_utc(f, "until_utc") if f.has("until_utc") else None,
            until_lst_h=(
                f.number("until_lst_h", REQUIRED, low=0.0, high=24.0, open_high=True)
                if f.has("until_lst_h")
                else None
            ),
        )

    def describe(self, step: Wait) -> str:
        """How long, or until when."""
        if step.seconds is not None:
            return f"wait {hms(step.seconds)}"
        if step.until_utc is not None:
            return f"wait until {step.until_utc:%Y-%m-%d %H:%M:%S} UTC"
        if step.until_lst_h is not None:
            return f"wait until LST {step.until_lst_h:.4g} h"
        return "wait"

    def timing(self, step: Wait, walk: TimingWalk) -> tuple[float, str]:
        """Until the time or LST from the estimated arrival; a time already past is refused."""
        now = walk.now_utc
        if step.seconds is not None:
            return step.seconds, self.describe(step)
        if step.until_utc is not None:
            until = as_utc(step.until_utc)
            if until < now:
                walk.report(
                    step,
                    "wait.until_utc",
                    f"{until:%Y-%m-%dT%H:%M:%SZ} is before the schedule gets there "
                    f"(estimated {now:%Y-%m-%dT%H:%M:%SZ}, {hms(walk.t)} after the start)",
                )
                return 0.0, self.describe(step)
            return (until - now).total_seconds(), self.describe(step)
        if step.until_lst_h is not None:
            until = next_utc_at_lst(now, step.until_lst_h, walk.longitude_deg)
            text = f"{self.describe(step)} ({until:%Y-%m-%d %H:%M:%S} UTC)"
            return (until - now).total_seconds(), text
        return 0.0, self.describe(step)

    def execute(self, step: Wait, run: RunContext) -> None:
        """Wait in clock time (a stop request ends it)."""
        now = run.clock.now()
        if step.seconds is not None:
            target = now + step.seconds
        elif step.until_utc is not None:
            target = step.until_utc.timestamp()
        elif step.until_lst_h is not None:
            after = datetime.fromtimestamp(now, tz=timezone.utc)
            lst = next_utc_at_lst(after, step.until_lst_h, run.site.longitude_deg)
            target = lst.timestamp()
        else:
            return
        # In tenths, each reported: a wait of hours shows that it is moving.
        total, text = max(0.0, target - now), self.describe(step)
        while True:
            left = max(0.0, target - run.clock.now())
            run.progress.update(text, round(total - left), max(1, round(total)), left)
            if left <= 0:
                return
            run.wait(min(left, total / 10))
