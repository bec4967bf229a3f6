"""Schedule variables: ``${name}`` and ``${site.<key>}`` substitution, with lines kept.

A scalar that is exactly ``"${name}"`` is replaced by the variable's value, whatever
its YAML type (a number, a list of sources, a mapping); ``${name}`` inside a longer
string is interpolated as text. ``${site.<key>}`` reads a field of the site
configuration (``${site.longitude_deg}``). Variables may use other variables; a cycle
or an unknown name is a problem at the line where it is used.

A container substituted for ``${name}`` is copied with every line set to the line of
the use, so that a mistake inside it is reported where the schedule used it.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass
from typing import Any

from reach_receiver.config.fields import UNRESOLVED
from reach_receiver.config.site import SiteConfig
from reach_receiver.config.yaml_lines import LineDict, LineList, Problem

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
    """

    def __init__(
        self, defined: dict[str, Defined], site: SiteConfig | None, problems: list[Problem]
    ) -> None:
        self._defined = defined
        self._site = site
        self._problems = problems
        self._values: dict[str, Any] = {}
        self._resolving: list[str] = []

    def values(self) -> dict[str, Any]:
        """Every variable's resolved value (resolving those not used yet)."""
        for name, definition in self._defined.items():
            self.lookup(name, definition.file, definition.line, f"vars.{name}")
        return {k: v for k, v in self._values.items() if v is not UNRESOLVED}

    def lookup(self, name: str, file: str, line: int, key: str) -> Any:
        """The value of variable ``name`` used at ``file:line`` under ``key``."""
        if name.startswith("site."):
            return self._site_value(name.removeprefix("site."), file, line, key)
        if name in self._values:
            return self._values[name]
        if name in self._resolving:
            chain = " -> ".join([*self._resolving[self._resolving.index(name) :], name])
            self._problems.append(Problem(file, line, key, f"variable cycle: {chain}"))
            return UNRESOLVED
        if name not in self._defined:
            self._problems.append(Problem(file, line, key, self._unknown(name)))
            return UNRESOLVED
        definition = self._defined[name]
        self._resolving.append(name)
        try:
            value = self.resolve(definition.value, definition.file, definition.line, f"vars.{name}")
        finally:
            self._resolving.pop()
        self._values[name] = value
        return value

    def resolve(self, value: Any, file: str, line: int, key: str) -> Any:
        """``value`` with every reference substituted; :data:`UNRESOLVED` on failure."""
        if isinstance(value, str):
            return self._resolve_text(value, file, line, key)
        if isinstance(value, LineDict):
            out = LineDict(line=value.line, lines=value.lines)
            for k, v in value.items():
                out[k] = self.resolve(v, file, value.line_of(k), f"{key}.{k}")
            return UNRESOLVED if any(v is UNRESOLVED for v in out.values()) else out
        if isinstance(value, LineList):
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
            return relined(self.lookup(whole.group(1).strip(), file, line, key), line)
        failed = False

        def interpolate(match: re.Match[str]) -> str:
            nonlocal failed
            value = self.lookup(match.group(1).strip(), file, line, key)
            if value is UNRESOLVED:
                failed = True
                return ""
            if isinstance(value, dict | list):
                self._problems.append(
                    Problem(file, line, key, f"${{{match.group(1)}}} is not text: use it alone")
                )
                failed = True
                return ""
            return str(value)

        result = _REFERENCE.sub(interpolate, text)
        return UNRESOLVED if failed else result

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
