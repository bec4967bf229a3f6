"""Compile a YAML schedule into a checked :class:`~.steps.Schedule`, or report every mistake.

The document (top level)::

    version: 1                      # optional; no other version is understood
    schedule: nightly calibration   # required: the schedule's name
    include: [site_vars.yaml]       # optional: files holding vars and blocks (and include)
    vars: {calibrators: [hot, cold], dwell_s: 600}
    blocks:
      cycle: [{dicke: {sources: "${calibrators}", seconds: "${dwell_s}"}}]
    steps:                          # required, non-empty
      - initialise
      - use: cycle

Included paths are relative to the including file; the including file's ``vars`` and
``blocks`` override the included ones; cycles and missing files are problems. Values
may use ``${name}`` and ``${site.<key>}`` (:mod:`.variables`); steps are read by
:mod:`.parsing`, each by its kind (:mod:`.kinds`). After the steps are read, the whole
list is checked for interlock violations (:mod:`.interlocks`) and impossible timing
(:mod:`.timing`), with the site's front-end and spectrometer when a site is given.
Every problem of every file is collected; when there is any, a :class:`ScheduleError`
lists them all, one ``file:line: key: message`` per line, and no schedule is returned.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from reach_receiver.config.fields import UNRESOLVED, closest, type_name
from reach_receiver.config.site import SiteConfig
from reach_receiver.config.yaml_lines import LineDict, LineList, Problem, ProblemsError, load_yaml

from . import steps as s
from .interlocks import interlock_problems
from .kinds import KindRegistry
from .parsing import Block, ParseContext, compile_steps
from .timing import timing_problems
from .variables import Defined, Variables, valid_name

__all__ = ["Problem", "ScheduleError", "compile_schedule", "compile_text"]

FORMAT_VERSION = 1
TOP_KEYS = ("version", "schedule", "include", "vars", "blocks", "steps")
INCLUDED_KEYS = ("include", "vars", "blocks")


class ScheduleError(ProblemsError):
    """A schedule with mistakes; ``problems`` holds every one, in file and line order.

    ``str(error)`` gives one ``file:line: key: message`` per line.
    """


def read_file(path: Path) -> str:
    """A schedule file's text (UTF-8)."""
    return path.read_text(encoding="utf-8")


#: How included files are read: from disk, or from texts a client sent with its schedule.
Reader = Callable[[Path], str]


@dataclass
class _Sources:
    """Files read so far, and the definitions they made."""

    problems: list[Problem]
    read: Reader = read_file
    texts: dict[str, str] = field(default_factory=dict)
    variables: dict[str, Defined] = field(default_factory=dict)
    blocks: dict[str, Block] = field(default_factory=dict)

    def add(self, file: str, text: str, stack: tuple[str, ...]) -> LineDict | None:
        """Load one file's text; read its includes, then its vars and blocks."""
        self.texts.setdefault(file, text)
        document, problems = load_yaml(text, file)
        self.problems += problems
        if problems and document is None:
            return None
        if not isinstance(document, LineDict):
            what = "a schedule" if not stack else "an included file"
            message = f"{what} is a mapping of {', '.join(TOP_KEYS)}, not {type_name(document)}"
            self.problems.append(Problem(file, 1, "<document>", message))
            return None
        allowed = TOP_KEYS if not stack else INCLUDED_KEYS
        for key in document:
            if key not in allowed:
                known = ", ".join(allowed)
                message = f"unknown key '{key}'{closest(key, allowed)} (known: {known})"
                if stack and key in TOP_KEYS:
                    message = f"an included file holds only {', '.join(INCLUDED_KEYS)}"
                self.problems.append(Problem(file, document.line_of(key), str(key), message))
        self._includes(document, file, (*stack, _identity(file)))
        self._definitions(document, file)
        return document

    def _includes(self, document: LineDict, file: str, stack: tuple[str, ...]) -> None:
        written = document.get("include")
        if written is None:
            return
        if isinstance(written, str):
            written = LineList([written], line=document.line_of("include"))
        if not isinstance(written, LineList):
            message = f"must be a list of file names, not {type_name(written)}"
            self.problems.append(Problem(file, document.line_of("include"), "include", message))
            return
        for index, name in enumerate(written):
            line, key = written.line_of(index), f"include[{index}]"
            if not isinstance(name, str) or not name:
                message = f"must be a file name, not {type_name(name)}"
                self.problems.append(Problem(file, line, key, message))
                continue
            path = _relative(file, name)
            if _identity(str(path)) in stack:
                looped = stack[stack.index(_identity(str(path))) :]
                chain = " -> ".join(Path(f).name for f in (*looped, str(path)))
                self.problems.append(Problem(file, line, key, f"include cycle: {chain}"))
                continue
            try:
                text = self.read(path)
            except (OSError, UnicodeDecodeError, ValueError) as err:
                message = f"cannot read {path}: {getattr(err, 'strerror', None) or err}"
                self.problems.append(Problem(file, line, key, message))
                continue
            self.add(str(path), text, stack)

    def _definitions(self, document: LineDict, file: str) -> None:
        for section in ("vars", "blocks"):
            written = document.get(section)
            if written is None:
                continue
            if not isinstance(written, LineDict):
                message = f"must be a mapping of names, not {type_name(written)}"
                self.problems.append(Problem(file, document.line_of(section), section, message))
                continue
            for name, value in written.items():
                line = written.line_of(name)
                if not valid_name(name):
                    message = f"{name!r} is not a valid name (letters, digits, _; not 'site')"
                    self.problems.append(Problem(file, line, f"{section}.{name}", message))
                elif section == "vars":
                    self.variables[name] = Defined(value, file, line)
                else:
                    self.blocks[name] = Block(value, file, line)


def _relative(file: str, name: str) -> Path:
    written = Path(name)
    if written.is_absolute() or file.startswith("<"):
        return written
    return Path(os.path.normpath(Path(file).parent / written))


def _identity(file: str) -> str:
    """The same string for every spelling of one file's path."""
    if file.startswith("<"):
        return file
    try:
        return str(Path(file).resolve())
    except (OSError, ValueError, RuntimeError):
        return file


def _plain(value: Any) -> Any:
    """Ordinary dicts and lists in place of the line-carrying ones."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


def _header(document: LineDict, file: str, variables: Variables, problems: list[Problem]) -> str:
    version = document.get("version", FORMAT_VERSION)
    if isinstance(version, bool) or version != FORMAT_VERSION:
        message = f"only version {FORMAT_VERSION} is understood, not {version!r}"
        problems.append(Problem(file, document.line_of("version"), "version", message))
    name = variables.resolve(
        document.get("schedule"), file, document.line_of("schedule"), "schedule"
    )
    if "schedule" not in document:
        problems.append(Problem(file, document.line, "schedule", "missing required key"))
    elif name is UNRESOLVED:
        pass
    elif not isinstance(name, str | int | float) or isinstance(name, bool) or name == "":
        message = f"must be the schedule's name, not {type_name(name)}"
        problems.append(Problem(file, document.line_of("schedule"), "schedule", message))
    if "steps" not in document:
        problems.append(Problem(file, document.line, "steps", "missing required key"))
    return str(name)


def _order(problems: list[Problem], files: Sequence[str]) -> list[Problem]:
    """Problems without repeats, by file (in reading order) then line."""
    rank = {file: index for index, file in enumerate(files)}
    unique = list(dict.fromkeys(problems))
    return sorted(unique, key=lambda p: (rank.get(p.file, len(rank)), p.line))


def compile_text(
    text: str,
    file: str = "<string>",
    *,
    kinds: KindRegistry,
    site: SiteConfig | None = None,
    start_utc: datetime | None = None,
    read: Reader = read_file,
) -> s.Schedule:
    """Compile a schedule given as text.

    Parameters
    ----------
    text
        The YAML document.
    file
        Its name in problems and in the steps' :class:`~.steps.Where`; includes are
        relative to its directory (to the working directory for ``"<...>"`` names).
    kinds
        The step kinds the schedule may use.
    site
        The site configuration: its sources, ``${site.<key>}``, the longitude of LST
        waits and the spectrometer's period. Without one: table A.2, longitude 0, and
        timing checked as a lower bound (spectra taking only their seconds).
    start_utc
        When the schedule will start, for the timing checks; now by default.
    read
        Reads an included file (from disk by default; a daemon compiling what a client
        sent reads the texts it was sent).

    Returns
    -------
    Schedule
        The checked steps, the texts of every file read and the variables' values.

    Raises
    ------
    ScheduleError
        With every problem found, when there is any.
    """
    problems: list[Problem] = []
    sources = _Sources(problems, read)
    document = sources.add(file, text, ())
    if document is None:
        raise ScheduleError(_order(problems, list(sources.texts)))
    variables = Variables(sources.variables, site, problems)
    name = _header(document, file, variables, problems)
    context = ParseContext(kinds, variables, problems, site, sources.blocks)
    steps: list[s.Step] = []
    if "steps" in document:
        steps = compile_steps(document["steps"], file, document.line_of("steps"), "steps", context)
    for block_name, block in sources.blocks.items():  # unused blocks are checked too
        context.using = [block_name]
        compile_steps(block.steps, block.file, block.line, f"blocks.{block_name}", context)
    values = variables.values()
    problems += interlock_problems(steps, kinds, site.sources if site is not None else None)
    problems += timing_problems(
        steps,
        kinds,
        start_utc=start_utc or datetime.now(timezone.utc),
        longitude_deg=site.longitude_deg if site is not None else 0.0,
        spectrum_period_s=site.devices.spectrometer.period_s if site is not None else 0.0,
    )
    if problems:
        raise ScheduleError(_order(problems, list(sources.texts)))
    return s.Schedule(
        name=name,
        steps=tuple(steps),
        files=tuple(sources.texts.items()),
        variables=tuple((k, _plain(v)) for k, v in values.items()),
        kinds=kinds,
    )


def compile_schedule(
    path: Path,
    *,
    kinds: KindRegistry,
    site: SiteConfig | None = None,
    start_utc: datetime | None = None,
) -> s.Schedule:
    """Read and compile a schedule file (see :func:`compile_text`).

    Raises
    ------
    ScheduleError
        With every problem found, including an unreadable file.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        message = f"cannot read the schedule: {getattr(err, 'strerror', None) or err}"
        raise ScheduleError([Problem(str(path), 1, "<file>", message)]) from err
    return compile_text(text, str(path), kinds=kinds, site=site, start_utc=start_utc)
