"""Typed, range-checked reading of a YAML mapping, every mistake recorded.

A :class:`Fields` wraps one mapping as written: a schedule step's arguments (``dicke:
{sources: [hot], seconds: 600}``) or a section of the site file (``devices.vna``). On
creation it reports every key it does not know (with the closest known one); each
accessor then substitutes variables (schedules only), checks the type and the range,
records a :class:`~.yaml_lines.Problem` naming the file, line and dotted key when
something is wrong, and returns a harmless fallback so that reading goes on and every
mistake of the file is found in one pass.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Iterable, Sequence
from typing import Any

from .yaml_lines import LineDict, LineList, Problem


class _Marker:
    def __init__(self, name: str) -> None:
        self.name = name

    def __repr__(self) -> str:
        return self.name


#: Default marking a key that must be written.
REQUIRED: Any = _Marker("REQUIRED")
#: A value whose substitution failed (its problem is already reported).
UNRESOLVED: Any = _Marker("UNRESOLVED")
_MISSING: Any = object()

#: ``resolve(value, file, line, key)``: a value with its references substituted, or
#: :data:`UNRESOLVED` after reporting why not.
Resolver = Callable[[Any, str, int, str], Any]


def _as_written(value: Any, file: str, line: int, key: str) -> Any:
    """The resolver of documents without variables: every value as written."""
    del file, line, key
    return value


def closest(word: object, known: Iterable[str]) -> str:
    """``"; did you mean 'x'?"`` for the known word closest to ``word``, or ``""``."""
    close = difflib.get_close_matches(str(word), list(known), n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""


def type_name(value: object) -> str:
    """The YAML name of a value's type, for messages."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list" if value else "an empty list"
    if isinstance(value, str):
        return f"text {value!r}"
    return f"{type(value).__name__} {value!r}"


class Fields:
    """The arguments of one step (or of a mapping inside one).

    Parameters
    ----------
    args
        The mapping as loaded.
    file
        The file it was written in.
    key
        Its dotted key (``dicke``, ``tec.wait``), prefixed to each argument's name.
    allowed
        The argument names this mapping may hold.
    problems
        Where mistakes are recorded.
    resolve
        Substitutes ``${...}`` in values (a schedule's variables); values are taken as
        written by default.
    line
        Where a missing key is reported: the line of the key this mapping is written
        under (by default the mapping's own first line).
    """

    def __init__(
        self,
        args: LineDict,
        *,
        file: str,
        key: str,
        allowed: Sequence[str],
        problems: list[Problem],
        resolve: Resolver = _as_written,
        line: int | None = None,
    ) -> None:
        self.args = args
        self._line = args.line if line is None else line
        self.file = file
        self.key = key
        self.resolve = resolve
        self.problems = problems
        self._start = len(problems)
        for name in args:
            if name not in allowed:
                known = f" (known: {', '.join(allowed)})" if allowed else " (it takes none)"
                self.report(name, f"unknown key '{name}'{closest(name, allowed)}{known}")

    @property
    def failed(self) -> bool:
        """Whether any problem was recorded since this reader was made."""
        return len(self.problems) > self._start

    def line(self, name: object) -> int:
        """The line of argument ``name`` (the mapping's line when it is absent)."""
        return self.args.line_of(name)

    def report(self, name: object, message: str, line: int | None = None) -> None:
        """Record a problem about argument ``name``."""
        where = self.line(name) if line is None else line
        self.problems.append(Problem(self.file, where, f"{self.key}.{name}", message))

    def has(self, name: str) -> bool:
        """Whether argument ``name`` was written."""
        return name in self.args

    def raw(self, name: str, default: Any = _MISSING) -> Any:
        """The argument with variables substituted; ``default`` when it is absent.

        A missing :data:`REQUIRED` argument is reported and gives :data:`UNRESOLVED`,
        as does a failed substitution (already reported).
        """
        if name not in self.args:
            if default is REQUIRED:
                self.report(name, "missing required key", self._line)
                return UNRESOLVED
            return default
        return self.resolve(self.args[name], self.file, self.line(name), f"{self.key}.{name}")

    # ----------------------------------------------------------------- scalars
    def number(
        self,
        name: str,
        default: Any,
        *,
        low: float | None = None,
        high: float | None = None,
        open_low: bool = False,
        open_high: bool = False,
        fallback: float = 0.0,
    ) -> float:
        """A finite real number in ``[low, high]`` (open ends when asked)."""
        value = self.raw(name, default)
        if value is UNRESOLVED:
            return fallback
        if value is default:
            return float(default) if default is not None else fallback
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.report(name, f"must be a number, not {type_name(value)}")
            return fallback
        if not math.isfinite(value):
            self.report(name, f"must be finite, not {value}")
            return fallback
        too_low = low is not None and (value <= low if open_low else value < low)
        too_high = high is not None and (value >= high if open_high else value > high)
        if too_low or too_high:
            left = "(" if open_low else "["
            right = ")" if open_high or high is None else "]"
            span = f"{left}{'-inf' if low is None else f'{low:g}'}, "
            span += f"{'inf' if high is None else f'{high:g}'}{right}"
            self.report(name, f"must be in {span}, not {value:g}")
            return fallback
        return float(value)

    def seconds(self, name: str, default: Any = REQUIRED) -> float:
        """A duration: finite and > 0."""
        return self.number(name, default, low=0.0, open_low=True)

    def optional_seconds(self, name: str) -> float | None:
        """A duration that may be left out (``None``); ``null`` is not a duration."""
        return self.seconds(name) if self.has(name) else None

    def fraction(self, name: str, default: float) -> float:
        """A tolerance: in (0, 1)."""
        return self.number(
            name, default, low=0.0, high=1.0, open_low=True, open_high=True, fallback=default
        )

    def count(self, name: str, default: Any = REQUIRED, minimum: int = 1) -> int:
        """An integer >= ``minimum``."""
        value = self.raw(name, default)
        if value is UNRESOLVED:
            return minimum
        if value is default:
            return int(default)
        if isinstance(value, bool) or not isinstance(value, int):
            self.report(name, f"must be an integer, not {type_name(value)}")
            return minimum
        if value < minimum:
            self.report(name, f"must be an integer >= {minimum}, not {value}")
            return minimum
        return value

    def text(self, name: str, default: Any = REQUIRED) -> str | None:
        """A non-empty string (``None`` when absent without a default, or wrong)."""
        value = self.raw(name, default)
        if value is UNRESOLVED:
            return None
        if value is default:
            return default if isinstance(default, str) else None
        if not isinstance(value, str) or not value:
            self.report(name, f"must be non-empty text, not {type_name(value)}")
            return None
        return value

    def choice(self, name: str, options: Sequence[str], default: Any = REQUIRED) -> str | None:
        """One of ``options``."""
        value = self.text(name, default)
        if value is not None and value not in options:
            message = f"must be one of {', '.join(options)}, not {value!r}"
            self.report(name, message + closest(value, options))
            return None
        return value

    # ----------------------------------------------------------------- containers
    def names(
        self,
        name: str,
        known: Sequence[str],
        what: str,
        default: Any = REQUIRED,
        *,
        empty: bool = False,
    ) -> list[str]:
        """A list of names (non-empty unless ``empty``), each one of ``known``."""
        value = self.raw(name, default)
        if value is UNRESOLVED:
            return []
        if value is default:
            return list(default)
        if not isinstance(value, list) or not (value or empty):
            article = "a" if empty else "a non-empty"
            self.report(name, f"must be {article} list of {what}s, not {type_name(value)}")
            return []
        good: list[str] = []
        lines = value.lines if isinstance(value, LineList) else []
        for index, item in enumerate(value):
            line = lines[index] if index < len(lines) else self.line(name)
            if isinstance(item, str) and item in known:
                good.append(item)
                continue
            message = f"unknown {what} {item!r}{closest(item, known)} (known: {', '.join(known)})"
            if not isinstance(item, str):
                message = f"each {what} is a name, not {type_name(item)}"
            self.problems.append(Problem(self.file, line, f"{self.key}.{name}[{index}]", message))
        return good

    def mapping(self, name: str, allowed: Sequence[str]) -> Fields | None:
        """A nested mapping's reader (``None`` when absent or not a mapping)."""
        value = self.raw(name, None)
        if value is None or value is UNRESOLVED:
            return None
        if not isinstance(value, LineDict):
            self.report(name, f"must be a mapping of {', '.join(allowed)}, not {type_name(value)}")
            return None
        return Fields(
            value,
            file=self.file,
            key=f"{self.key}.{name}",
            allowed=allowed,
            problems=self.problems,
            resolve=self.resolve,
            line=self.line(name),
        )
