"""Step lists as written in YAML -> the frozen steps of :mod:`.steps`, every mistake kept.

Each step is one single-key mapping, ``- kind: {arguments}``; a kind without arguments
may be written bare (``- safe``) or with a null value (``- safe:``). ``- use: <block>``
inlines a named block (blocks may use blocks; a cycle is a problem). Each parser checks
its arguments' names, types and ranges against the front-end's facts (:mod:`..frontend.
layout`: source names, VNA standards, rails) and the VNA's sweep limits
(:class:`~reach_receiver.devices.vna_settings.SweepSettings`), and always returns a step
(with harmless fallbacks where an argument was wrong) so that the later whole-schedule
checks still run; nothing is returned to the caller when any problem was found.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from datetime import date, datetime, timezone
from pathlib import Path
from typing import Any, Literal, cast

from reach_receiver.devices.vna_settings import SweepSettings
from reach_receiver.errors import ConfigError
from reach_receiver.frontend.layout import (
    FIXED_RAILS,
    REACH_SOURCES,
    SWITCHABLE_RAILS,
    VNA_STANDARDS,
)

from . import steps as s
from .fields import REQUIRED, Fields, closest, type_name
from .variables import UNRESOLVED, Variables
from .yaml_lines import LineDict, LineList, Problem

SOURCES: tuple[str, ...] = tuple(REACH_SOURCES)
SWEEP_KEYS: tuple[str, ...] = tuple(f.name for f in fields(s.Sweep))
WAIT_STABLE_KEYS: tuple[str, ...] = tuple(f.name for f in fields(s.WaitStable))
TEC_RANGE_C = (5.0, 45.0)


@dataclass(frozen=True)
class Block:
    """A named list of steps as written, and the file it was written in."""

    steps: Any
    file: str
    line: int


@dataclass
class Context:
    """What every parser shares: variables, blocks, the problem list, the blocks in use."""

    variables: Variables
    problems: list[Problem]
    blocks: dict[str, Block] = field(default_factory=dict)
    using: list[str] = field(default_factory=list)
    sources: tuple[str, ...] = SOURCES

    @property
    def vna_targets(self) -> tuple[str, ...]:
        """What a connection to the VNA may name: sources, the LNA, the standards."""
        return (*self.sources, "lna", *VNA_STANDARDS)

    @property
    def s11_targets(self) -> tuple[str, ...]:
        """What an ``s11`` step may measure."""
        return (*self.sources, "lna")

    def path(self, file: str, text: str) -> Path:
        """A path written in ``file``, relative to that file's directory."""
        written = Path(text)
        if written.is_absolute() or file.startswith("<"):
            return written
        return Path(file).parent / written


Parser = Callable[[Fields, s.Where, Context], s.Step]


@dataclass(frozen=True)
class Unparsed(s.Step):
    """Stands for a step that could not be read at all, so later checks assume nothing.

    Never part of a returned schedule: it exists only alongside a reported problem.
    """


def _initialise(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    if not f.has("rails"):
        return s.Initialise(where)
    rails = f.names("rails", (*SWITCHABLE_RAILS, *FIXED_RAILS), "rail", empty=True)
    for rail in rails:
        if rail in FIXED_RAILS:
            f.report("rails", f"rail {rail} is never switched (thesis table A.3)")
    return s.Initialise(where, tuple(r for r in rails if r in SWITCHABLE_RAILS))


def _power(f: Fields, where: s.Where, ctx: Context) -> s.Step:
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
    return s.Power(where, tuple(states))


def _connect(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    to = f.choice("to", ("lna", "vna"), "lna") or "lna"
    source = f.text("source")
    known = ctx.vna_targets if to == "vna" else ctx.sources
    if source is not None and source not in known:
        f.report(
            "source",
            f"unknown source {source!r} for the {to.upper()}{closest(source, known)} "
            f"(known: {', '.join(known)})",
        )
    return s.Connect(where, source or "", cast(Literal["lna", "vna"], to))


def _sweep(f: Fields, where: s.Where, ctx: Context) -> s.Sweep:
    sweep = f.mapping("sweep", SWEEP_KEYS)
    if sweep is None:
        return s.Sweep()
    given: dict[str, float | int] = {}
    for name in SWEEP_KEYS:
        if not sweep.has(name):
            continue
        if name in ("points", "averages"):
            given[name] = sweep.count(name)
        else:
            given[name] = sweep.number(name, REQUIRED)
    if sweep.failed:
        return s.Sweep()
    try:
        SweepSettings(**given)  # type: ignore[arg-type]  # validated by its own checks
    except ConfigError as err:
        f.report("sweep", str(err), where.line)
        return s.Sweep()
    return s.Sweep(**given)  # type: ignore[arg-type]


def _vna_calibrate(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    return s.VnaCalibrate(where, _sweep(f, where, ctx))


def _test_load_check(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    reference = f.text("reference", None)
    statistic = f.choice("statistic", ("max", "p95", "rms"), "p95") or "p95"
    return s.TestLoadCheck(
        where,
        reference=ctx.path(f.file, reference) if reference else None,
        tolerance=f.fraction("tolerance", 0.05),
        statistic=cast(Literal["max", "p95", "rms"], statistic),
        retries=f.count("retries", 2, minimum=0),
    )


def _s11(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    return s.MeasureS11(where, tuple(f.names("targets", ctx.s11_targets, "S11 target")))


def _spectrum(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    source = f.choice("source", ctx.sources) or ""
    return s.MeasureSpectrum(where, source, f.seconds("seconds"))


def _dicke(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    sources = f.names("sources", ctx.sources, "source")
    return s.Dicke(where, tuple(sources), f.seconds("seconds"))


def _temperatures(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    return s.Temperatures(where, f.seconds("period_s", 10.0))


def _tec(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    low, high = TEC_RANGE_C
    setpoint = f.number("setpoint_c", REQUIRED, low=low, high=high, fallback=25.0)
    wait: s.WaitStable | None = None
    written = f.raw("wait", None)
    if isinstance(written, bool):
        wait = s.WaitStable() if written else None
    elif written is not None and written is not UNRESOLVED:
        sub = f.mapping("wait", WAIT_STABLE_KEYS)
        if sub is not None:
            defaults = s.WaitStable()
            hold = sub.seconds("hold_s", defaults.hold_s)
            timeout = sub.seconds("timeout_s", defaults.timeout_s)
            if not sub.failed and timeout < hold:
                sub.report("timeout_s", f"must be at least hold_s ({hold:g} s), not {timeout:g}")
            wait = s.WaitStable(sub.seconds("tolerance_c", defaults.tolerance_c), hold, timeout)
    return s.Tec(where, setpoint, wait)


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


def _wait(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    written = [name for name in ("seconds", "until_utc", "until_lst_h") if f.has(name)]
    if len(written) != 1:
        f.report(
            "<how>",
            "give exactly one of seconds, until_utc, until_lst_h"
            + (f", not {' and '.join(written)}" if written else ""),
            f.args.line,
        )
    return s.Wait(
        where,
        seconds=f.seconds("seconds") if f.has("seconds") else None,
        until_utc=_utc(f, "until_utc") if f.has("until_utc") else None,
        until_lst_h=(
            f.number("until_lst_h", REQUIRED, low=0.0, high=24.0, open_high=True)
            if f.has("until_lst_h")
            else None
        ),
    )


def _repeat(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    count = f.count("count")
    period = f.optional_seconds("period_s")
    body = f.raw("steps", REQUIRED)
    inner: list[s.Step] = []
    if body is not UNRESOLVED:
        inner = compile_steps(body, f.file, f.line("steps"), f"{f.key}.steps", ctx)
    return s.Repeat(where, count, tuple(inner), period)


def _calibrate(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    benchmark = f.text("benchmark", None)
    low = f.number("f_lo_hz", 50e6, low=0.0, open_low=True, fallback=50e6)
    high = f.number("f_hi_hz", 130e6, low=0.0, open_low=True, fallback=130e6)
    if not f.failed and low >= high:
        f.report("f_hi_hz", f"must be above f_lo_hz ({low:g} Hz), not {high:g}")
    return s.Calibrate(
        where,
        benchmark=ctx.path(f.file, benchmark) if benchmark else None,
        tolerance=f.fraction("tolerance", 0.05),
        f_lo_hz=low,
        f_hi_hz=high,
    )


def _observe(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    return s.Observe(
        where,
        cycles=f.count("cycles"),
        seconds=f.seconds("seconds"),
        source=f.choice("source", ctx.sources, "ant") or "ant",
        test_load_every=f.count("test_load_every", 6),
        rfi_threshold_sigma=f.number("rfi_threshold_sigma", 5.0, low=0.0, open_low=True),
    )


def _safe(f: Fields, where: s.Where, ctx: Context) -> s.Step:
    return s.Safe(where)


#: Step kind -> (argument names, parser). ``power`` takes rail names as its keys.
PARSERS: dict[str, tuple[Sequence[str], Parser]] = {
    "initialise": (("rails",), _initialise),
    "power": ((*SWITCHABLE_RAILS, *FIXED_RAILS), _power),
    "connect": (("source", "to"), _connect),
    "vna_calibrate": (("sweep",), _vna_calibrate),
    "test_load_check": (("reference", "tolerance", "statistic", "retries"), _test_load_check),
    "s11": (("targets",), _s11),
    "spectrum": (("source", "seconds"), _spectrum),
    "dicke": (("sources", "seconds"), _dicke),
    "temperatures": (("period_s",), _temperatures),
    "tec": (("setpoint_c", "wait"), _tec),
    "wait": (("seconds", "until_utc", "until_lst_h"), _wait),
    "repeat": (("count", "period_s", "steps"), _repeat),
    "calibrate": (("benchmark", "tolerance", "f_lo_hz", "f_hi_hz"), _calibrate),
    "observe": (
        ("cycles", "seconds", "source", "test_load_every", "rfi_threshold_sigma"),
        _observe,
    ),
    "safe": ((), _safe),
}
STEP_KINDS: tuple[str, ...] = (*PARSERS, "use")


def compile_steps(items: Any, file: str, line: int, key: str, ctx: Context) -> list[s.Step]:
    """Compile a list of steps written at ``file:line`` under ``key``."""
    if isinstance(items, str):  # a whole list from a variable: "${night}"
        items = ctx.variables.resolve(items, file, line, key)
        if items is UNRESOLVED:
            return []
    if not isinstance(items, LineList) or not items:
        ctx.problems.append(
            Problem(file, line, key, f"must be a non-empty list of steps, not {type_name(items)}")
        )
        return []
    out: list[s.Step] = []
    for index, item in enumerate(items):
        out += compile_step(item, file, items.line_of(index), ctx)
    return out


def compile_step(item: Any, file: str, line: int, ctx: Context) -> list[s.Step]:
    """Compile one step (a ``use`` gives the block's steps) written at ``file:line``."""
    if isinstance(item, str):
        item = LineDict({item: None}, line=line, lines={item: line})
    if not isinstance(item, LineDict) or len(item) != 1:
        message = f"a step is one 'kind: arguments' mapping, not {type_name(item)}"
        if isinstance(item, dict) and item:
            message = f"a step has one kind, not {len(item)} ({', '.join(map(str, item))})"
        ctx.problems.append(Problem(file, line, "<step>", message))
        return [Unparsed(s.Where(file, line))]
    ((kind, args),) = item.items()
    if kind == "use":
        return _use(args, file, line, ctx) or [Unparsed(s.Where(file, line))]
    if kind not in PARSERS:
        message = f"unknown step kind {kind!r}{closest(kind, STEP_KINDS)}"
        ctx.problems.append(Problem(file, line, str(kind), message))
        return [Unparsed(s.Where(file, line))]
    allowed, parser = PARSERS[kind]
    if isinstance(args, str):  # a whole-mapping variable: "${dicke_args}"
        args = ctx.variables.resolve(args, file, line, kind)
        if args is UNRESOLVED:
            return [Unparsed(s.Where(file, line))]
    if args is None:
        args = LineDict(line=line)
    if not isinstance(args, LineDict):
        message = f"takes a mapping of {', '.join(allowed) or 'nothing'}, not {type_name(args)}"
        ctx.problems.append(Problem(file, line, kind, message))
        return [Unparsed(s.Where(file, line))]
    reader = Fields(
        args, file=file, key=kind, allowed=allowed, variables=ctx.variables, problems=ctx.problems
    )
    return [parser(reader, s.Where(file, line), ctx)]


def _use(name: Any, file: str, line: int, ctx: Context) -> list[s.Step]:
    name = ctx.variables.resolve(name, file, line, "use")
    if name is UNRESOLVED:
        return []
    if not isinstance(name, str) or name not in ctx.blocks:
        known = sorted(ctx.blocks)
        message = f"unknown block {name!r}{closest(name, known)}"
        message += f" (known: {', '.join(known)})" if known else " (no blocks are defined)"
        ctx.problems.append(Problem(file, line, "use", message))
        return []
    if name in ctx.using:
        chain = " -> ".join([*ctx.using[ctx.using.index(name) :], name])
        ctx.problems.append(Problem(file, line, "use", f"block cycle: {chain}"))
        return []
    block = ctx.blocks[name]
    ctx.using.append(name)
    try:
        return compile_steps(block.steps, block.file, block.line, f"blocks.{name}", ctx)
    finally:
        ctx.using.pop()
