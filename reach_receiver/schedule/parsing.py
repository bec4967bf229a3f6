"""Step lists as written in YAML -> compiled steps, every mistake kept.

Each step is one single-key mapping, ``- kind: {arguments}``; a kind without arguments
may be written bare (``- safe``) or with a null value (``- safe:``). ``- use: <block>``
inlines a named block (blocks may use blocks; a cycle is a problem). The kind's own
:meth:`~.kinds.StepKind.parse` reads its arguments through a
:class:`~reach_receiver.config.fields.Fields` and always returns a step (with harmless
fallbacks where an argument was wrong), so that the later whole-schedule checks still
run; nothing is returned to the caller when any problem was found.

Every value a kind reads goes through :meth:`ParseContext.checked`, which refuses
numbers no kind could take (not finite, or past the bounds of their key's unit:
:func:`~.limits.number_problem`) before the kind compares or converts them. Step lists
nest at most :data:`~.limits.MAX_NESTING` deep (a ``repeat``'s body, a block's use),
and every step compiled counts against :data:`~.limits.MAX_STEPS`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from reach_receiver.config.fields import UNRESOLVED, Fields, closest, type_name
from reach_receiver.config.site import SiteConfig
from reach_receiver.config.yaml_lines import LineDict, LineList, Problem
from reach_receiver.frontend.layout import REACH_SOURCES, VNA_STANDARDS

from .kinds import KindRegistry
from .limits import MAX_NESTING, Budget, LimitExceeded, number_problem
from .steps import Step, Unparsed, Where
from .variables import Variables


@dataclass(frozen=True)
class Block:
    """A named list of steps as written, and the file it was written in."""

    steps: Any
    file: str
    line: int


@dataclass
class ParseContext:
    """What every parser shares: kinds, variables, problems, blocks, the site's facts."""

    kinds: KindRegistry
    variables: Variables
    problems: list[Problem]
    site: SiteConfig | None = None
    blocks: dict[str, Block] = field(default_factory=dict)
    using: list[str] = field(default_factory=list)
    budget: Budget = field(default_factory=Budget)
    depth: int = 0

    @property
    def sources(self) -> tuple[str, ...]:
        """The sources of the site's front-end (table A.2 without a site)."""
        return tuple(self.site.sources if self.site is not None else REACH_SOURCES)

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

    def integration(self, f: Fields, name: str) -> float:
        """An integration time (s): positive and, with a site, at least one spectrum."""
        before = len(self.problems)
        seconds = f.seconds(name)
        if self.site is not None and len(self.problems) == before:
            period = self.site.devices.spectrometer.period_s
            if seconds < period:
                f.report(
                    name,
                    f"{seconds:g} s is shorter than one spectrum "
                    f"(devices.spectrometer.period_s {period:g} s in {self.site.source})",
                )
        return seconds

    def fields(self, args: LineDict, file: str, key: str, allowed: tuple[str, ...]) -> Fields:
        """A reader of one mapping with this schedule's variables."""
        return Fields(
            args,
            file=file,
            key=key,
            allowed=allowed,
            problems=self.problems,
            resolve=self.checked,
        )

    def checked(self, value: Any, file: str, line: int, key: str) -> Any:
        """``value`` with its variables substituted, refused when no kind could take it."""
        resolved = self.variables.resolve(value, file, line, key)
        problem = number_problem(key, resolved)
        if problem is None:
            return resolved
        self.problems.append(Problem(file, line, key, problem))
        return UNRESOLVED


def compile_steps(items: Any, file: str, line: int, key: str, ctx: ParseContext) -> list[Step]:
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
    if ctx.depth >= MAX_NESTING:
        message = f"steps nested more than {MAX_NESTING} deep (repeats, blocks using blocks)"
        raise LimitExceeded(Problem(file, line, key, message))
    out: list[Step] = []
    ctx.depth += 1
    try:
        for index, item in enumerate(items):
            out += compile_step(item, file, items.line_of(index), ctx)
    finally:
        ctx.depth -= 1
    return out


def compile_step(item: Any, file: str, line: int, ctx: ParseContext) -> list[Step]:
    """Compile one step (a ``use`` gives the block's steps) written at ``file:line``."""
    if isinstance(item, str):
        item = LineDict({item: None}, line=line, lines={item: line})
    written = str(next(iter(item))) if isinstance(item, dict) and item else "<step>"
    ctx.budget.step(file, line, written)
    if not isinstance(item, LineDict) or len(item) != 1:
        message = f"a step is one 'kind: arguments' mapping, not {type_name(item)}"
        if isinstance(item, dict) and item:
            message = f"a step has one kind, not {len(item)} ({', '.join(map(str, item))})"
        ctx.problems.append(Problem(file, line, "<step>", message))
        return [Unparsed(Where(file, line))]
    ((name, args),) = item.items()
    if name == "use":
        return _use(args, file, line, ctx) or [Unparsed(Where(file, line))]
    if name not in ctx.kinds:
        message = f"unknown step kind {name!r}{closest(name, (*ctx.kinds.names, 'use'))}"
        ctx.problems.append(Problem(file, line, str(name), message))
        return [Unparsed(Where(file, line))]
    kind = ctx.kinds.named(name)
    if isinstance(args, str):  # a whole-mapping variable: "${dicke_args}"
        args = ctx.variables.resolve(args, file, line, name)
        if args is UNRESOLVED:
            return [Unparsed(Where(file, line))]
    if args is None:
        args = LineDict(line=line)
    if not isinstance(args, LineDict):
        message = f"takes a mapping of {', '.join(kind.keys) or 'nothing'}, not {type_name(args)}"
        ctx.problems.append(Problem(file, line, name, message))
        return [Unparsed(Where(file, line))]
    reader = ctx.fields(args, file, name, kind.keys)
    return [kind.parse(reader, Where(file, line), ctx)]


def _use(name: Any, file: str, line: int, ctx: ParseContext) -> list[Step]:
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
