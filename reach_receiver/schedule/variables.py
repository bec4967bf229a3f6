"""Schedule variables: ``${name}`` and ``${site.<key>}`` substitution, with lines kept.

A scalar that is exactly ``"${name}"`` is replaced by the variable's value, whatever
its YAML type (a number, a list of sources, a mapping); ``${name}`` inside a longer
string is interpolated as text. ``${site.<key>}`` reads a field of the site
configuration (``${site.longitude_deg}``). Variables may use other variables; a cycle
or an unknown name is a problem at the line where it is used.

A container substituted for ``${name}`` is copied with every line set to the line of
the use, so that a mistake inside it is reported where the schedule used it.

Substitution is bounded (:mod:`.limits`), since variables that use a variable twice
double at each level: a variable's value holds at most
:data:`~.limits.MAX_VALUE_NODES` values nested at most
:data:`~.limits.MAX_VALUE_DEPTH` deep, an interpolated text at most
:data:`~.limits.MAX_TEXT_CHARS` characters, a variable is defined through at most
:data:`~.limits.MAX_NESTING` others, and every value copied counts against
:data:`~.limits.MAX_COPIED_NODES` (:class:`~.limits.Budget`).
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass
from typing import Any

from reach_receiver.config.fields import UNRESOLVED
from reach_receiver.config.site import SiteConfig
from reach_receiver.config.yaml_lines import LineDict, LineList, Problem

from .limits import (
    MAX_NESTING,
    MAX_TEXT_CHARS,
    MAX_VALUE_DEPTH,
    MAX_VALUE_NODES,
    Budget,
    LimitExceeded,
)

_REFERENCE = re.compile(r"\$\{([^}]*)\}")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
#: Site fields a schedule may read (the devices are for the drivers, not for schedules).
SITE_KEYS = ("name", "longitude_deg", "latitude_deg")

__all__ = ["SITE_KEYS", "UNRESOLVED", "Defined", "Variables", "relined", "valid_name"]


@dataclass(frozen=True)
class Defined:
    """A variable as written: its raw value and where it was defined."""

    value: Any
    file: str
    line: int


def valid_name(name: object) -> bool:
    """Whether ``name`` can be a variable's name (an identifier; ``site`` is reserved)."""
    return isinstance(name, str) and bool(_NAME.match(name)) and name != "site"


def relined(value: Any, line: int) -> Any:
    """A copy of ``value`` whose containers all report ``line``."""
    if isinstance(value, LineDict):
        return LineDict(
            {k: relined(v, line) for k, v in value.items()},
            line=line,
            lines=dict.fromkeys(value, line),
        )
    if isinstance(value, LineList):
        return LineList([relined(v, line) for v in value], line=line, lines=[line] * len(value))
    return value


def extent(value: Any) -> tuple[int, int]:
    """How many values ``value`` holds, and how deep its containers nest.

    A container shared by aliases counts at each place it appears, as a copy holds it.
    """
    sizes: dict[int, tuple[int, int]] = {}

    def measure(item: Any) -> tuple[int, int]:
        if not isinstance(item, dict | list):
            return 1, 0
        if id(item) not in sizes:
            inside = item.values() if isinstance(item, dict) else item
            children = [measure(child) for child in inside]
            sizes[id(item)] = (
                1 + sum(size for size, _ in children),
                1 + max((depth for _, depth in children), default=0),
            )
        return sizes[id(item)]

    return measure(value)


def _too_large(size: int, depth: int, chain: int) -> str | None:
    """Why a variable is refused, or ``None``.

    Its value holds ``size`` values nested ``depth`` deep; it is defined through a chain
    of ``chain`` variables, itself included.
    """
    if chain > MAX_NESTING:
        return f"defined through more than {MAX_NESTING} variables, one using the next"
    if depth > MAX_VALUE_DEPTH:
        return f"nests more than {MAX_VALUE_DEPTH} deep once its variables are substituted"
    if size > MAX_VALUE_NODES:
        limit = MAX_VALUE_NODES
        return f"holds {size:,} values once its variables are substituted; at most {limit:,}"
    return None


class Variables:
    """Resolves ``${...}`` references against the schedule's variables and the site.

    Parameters
    ----------
    defined
        Variable name -> its definition (included files' first, overridden by the
        including file's).
    site
        The site configuration, or ``None`` when no site file is given.
    problems
        Where unknown names and cycles are reported.
    budget
        Counts the values copied (a budget of its own by default).
    """

    def __init__(
        self,
        defined: dict[str, Defined],
        site: SiteConfig | None,
        problems: list[Problem],
        budget: Budget | None = None,
    ) -> None:
        self._defined = defined
        self._site = site
        self._problems = problems
        self._budget = budget if budget is not None else Budget()
        self._values: dict[str, Any] = {}
        self._sizes: dict[str, int] = {}
        self._resolving: list[str] = []
        # how many variables deep each one is defined (1: through none), and, while one
        # is resolved, the deepest of those it uses
        self._chains: dict[str, int] = {}
        self._below: list[int] = []

    def values(self) -> dict[str, Any]:
        """Every variable's resolved value (resolving those not used yet)."""
        for name, definition in self._defined.items():
            self.lookup(name, definition.file, definition.line, f"vars.{name}")
        return {k: v for k, v in self._values.items() if v is not UNRESOLVED}

    def lookup(self, name: str, file: str, line: int, key: str) -> Any:
        """The value of variable ``name`` used at ``file:line`` under ``key``."""
        if name.startswith("site."):
            return self._site_value(name.removeprefix("site."), file, line, key)
        value = self._lookup(name, file, line, key)
        if self._below:  # the variable being resolved is defined through this one
            self._below[-1] = max(self._below[-1], self._chains.get(name, 0))
        return value

    def _lookup(self, name: str, file: str, line: int, key: str) -> Any:
        if name in self._values:
            return self._values[name]
        if name in self._resolving:
            chain = " -> ".join([*self._resolving[self._resolving.index(name) :], name])
            self._problems.append(Problem(file, line, key, f"variable cycle: {chain}"))
            return UNRESOLVED
        if name not in self._defined:
            self._problems.append(Problem(file, line, key, self._unknown(name)))
            return UNRESOLVED
        if len(self._resolving) >= MAX_NESTING:
            chain = " -> ".join([*self._resolving[:3], "...", name])
            message = f"variables defined through more than {MAX_NESTING} others ({chain})"
            raise LimitExceeded(Problem(file, line, key, message))
        definition = self._defined[name]
        self._resolving.append(name)
        self._below.append(0)
        try:
            value = self.resolve(definition.value, definition.file, definition.line, f"vars.{name}")
        finally:
            self._resolving.pop()
            self._chains[name] = self._below.pop() + 1
        size, depth = extent(value)
        too_large = _too_large(size, depth, self._chains[name])
        if too_large is not None:
            where = Problem(definition.file, definition.line, f"vars.{name}", too_large)
            self._problems.append(where)
            value = UNRESOLVED
        self._values[name] = value
        self._sizes[name] = size
        return value

    def resolve(self, value: Any, file: str, line: int, key: str) -> Any:
        """``value`` with every reference substituted; :data:`UNRESOLVED` on failure."""
        if isinstance(value, str):
            return self._resolve_text(value, file, line, key)
        if isinstance(value, LineDict):
            self._budget.copy(1, file, line, key)
            out = LineDict(line=value.line, lines=value.lines)
            for k, v in value.items():
                out[k] = self.resolve(v, file, value.line_of(k), f"{key}.{k}")
            return UNRESOLVED if any(v is UNRESOLVED for v in out.values()) else out
        if isinstance(value, LineList):
            self._budget.copy(1, file, line, key)
            items = [
                self.resolve(v, file, value.line_of(i), f"{key}[{i}]") for i, v in enumerate(value)
            ]
            if any(v is UNRESOLVED for v in items):
                return UNRESOLVED
            return LineList(items, line=value.line, lines=value.lines)
        return value

    def _resolve_text(self, text: str, file: str, line: int, key: str) -> Any:
        whole = _REFERENCE.fullmatch(text)
        if whole:
            name = whole.group(1).strip()
            value = self.lookup(name, file, line, key)
            if isinstance(value, dict | list):
                self._budget.copy(self._sizes.get(name, 1), file, line, key)
            return relined(value, line)
        pieces: list[str] = []
        length, start, failed = 0, 0, False
        for match in _REFERENCE.finditer(text):
            value = self.lookup(match.group(1).strip(), file, line, key)
            if value is UNRESOLVED:
                failed = True
            elif isinstance(value, dict | list):
                self._problems.append(
                    Problem(file, line, key, f"${{{match.group(1)}}} is not text: use it alone")
                )
                failed = True
            piece = "" if failed else str(value)
            pieces += [text[start : match.start()], piece]
            start = match.end()
            length += len(pieces[-2]) + len(piece)
            if length > MAX_TEXT_CHARS:
                message = f"expands to more than {MAX_TEXT_CHARS:,} characters"
                self._problems.append(Problem(file, line, key, message))
                return UNRESOLVED
        if failed:
            return UNRESOLVED
        pieces.append(text[start:])
        return "".join(pieces)

    def _site_value(self, field: str, file: str, line: int, key: str) -> Any:
        if field not in SITE_KEYS:
            close = difflib.get_close_matches(field, SITE_KEYS, n=1)
            hint = f"; did you mean 'site.{close[0]}'?" if close else ""
            message = f"unknown site key 'site.{field}'{hint} (known: {', '.join(SITE_KEYS)})"
            self._problems.append(Problem(file, line, key, message))
            return UNRESOLVED
        if self._site is None:
            message = f"${{site.{field}}} needs a site configuration and none was given"
            self._problems.append(Problem(file, line, key, message))
            return UNRESOLVED
        return getattr(self._site, field)

    def _unknown(self, name: str) -> str:
        known = sorted(self._defined)
        close = difflib.get_close_matches(name, known, n=1)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        listed = f" (defined: {', '.join(known)})" if known else " (no variables are defined)"
        return f"unknown variable '{name}'{hint}{listed}"
