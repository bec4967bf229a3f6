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
``blocks`` override the included ones; cycles and missing files are problems
(:mod:`.sources`, which reads regular files only, with a bound). Values may use
``${name}`` and ``${site.<key>}`` (:mod:`.variables`); steps are read by
:mod:`.parsing`, each by its kind (:mod:`.kinds`). After the steps are read, the whole
list is checked for interlock violations (:mod:`.interlocks`) and impossible timing
(:mod:`.timing`), with the site's front-end and spectrometer when a site is given.
Every problem of every file is collected; when there is any, a :class:`ScheduleError`
lists them all, one ``file:line: key: message`` per line, and no schedule is returned.

Checking is bounded in time and memory whatever the files hold (:mod:`.limits`): a
schedule past a bound (nesting, steps, expansion, sizes, numbers, duration) is refused
with a problem where the bound was passed, and checking stops there.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from reach_receiver.config.fields import UNRESOLVED, type_name
from reach_receiver.config.site import SiteConfig
from reach_receiver.config.yaml_lines import LineDict, Problem, ProblemsError

from . import steps as s
from .interlocks import interlock_problems
from .kinds import KindRegistry
from .limits import MAX_RUN_STEPS, Budget, LimitExceeded
from .parsing import ParseContext, compile_steps
from .sources import Reader, Sources, read_file
from .timing import timing_problems
from .variables import Variables

__all__ = ["Problem", "Reader", "ScheduleError", "compile_schedule", "compile_text", "read_file"]

FORMAT_VERSION = 1


class ScheduleError(ProblemsError):
    """A schedule with mistakes; ``problems`` holds every one, in file and line order.

    ``str(error)`` gives one ``file:line: key: message`` per line.
    """


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
    sources = Sources(problems, read)
    try:
        steps, variables, name = _checked(
            text, file, sources, kinds, site, start_utc or datetime.now(timezone.utc)
        )
    except LimitExceeded as limit:
        problems.append(limit.problem)
    if problems:
        raise ScheduleError(_order(problems, list(sources.texts)))
    return s.Schedule(
        name=name,
        steps=tuple(steps),
        files=tuple(sources.texts.items()),
        variables=tuple((k, _plain(v)) for k, v in variables.items()),
        kinds=kinds,
    )


def _checked(
    text: str,
    file: str,
    sources: Sources,
    kinds: KindRegistry,
    site: SiteConfig | None,
    start_utc: datetime,
) -> tuple[list[s.Step], dict[str, object], str]:
    """Read, compile and check; problems go to ``sources.problems``, a bound raises."""
    problems = sources.problems
    document = sources.add(file, text, ())
    if document is None:
        return [], {}, ""
    budget = Budget()
    variables = Variables(sources.variables, site, problems, budget)
    name = _header(document, file, variables, problems)
    context = ParseContext(kinds, variables, problems, site, sources.blocks, budget=budget)
    steps: list[s.Step] = []
    if "steps" in document:
        steps = compile_steps(document["steps"], file, document.line_of("steps"), "steps", context)
    for block_name, block in sources.blocks.items():  # unused blocks are checked too
        context.using = [block_name]
        compile_steps(block.steps, block.file, block.line, f"blocks.{block_name}", context)
    values = variables.values()
    _count_run_steps(steps, kinds)
    problems += interlock_problems(
        steps, kinds, site.sources if site is not None else None, budget=budget
    )
    problems += timing_problems(
        steps,
        kinds,
        start_utc=start_utc,
        longitude_deg=site.longitude_deg if site is not None else 0.0,
        spectrum_period_s=site.devices.spectrometer.period_s if site is not None else 0.0,
        budget=budget,
    )
    return steps, values, name


def _count_run_steps(steps: Sequence[s.Step], kinds: KindRegistry) -> None:
    """Refuse a schedule that would run more than :data:`~.limits.MAX_RUN_STEPS` steps.

    A step with children runs them ``count`` times when it has a ``count`` (a repeat);
    each body is visited once, with its multiplier.
    """
    total = 0

    def visit(items: Sequence[s.Step], times: int) -> None:
        nonlocal total
        for step in items:
            total += times
            if total > MAX_RUN_STEPS:
                message = (
                    f"the schedule would run more than {MAX_RUN_STEPS:,} steps"
                    " (counts multiplied by the counts of repeats around them)"
                )
                key = kinds.of(step).name if kinds.knows(step) else "<step>"
                raise LimitExceeded(Problem(step.where.file, step.where.line, key, message))
            children = kinds.of(step).children(step) if kinds.knows(step) else ()
            if children:
                count = getattr(step, "count", 1)
                visit(children, times * (count if isinstance(count, int) else 1))

    visit(steps, 1)


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
        text = read_file(path)
    except (OSError, UnicodeDecodeError) as err:
        message = f"cannot read the schedule: {getattr(err, 'strerror', None) or err}"
        raise ScheduleError([Problem(str(path), 1, "<file>", message)]) from err
    return compile_text(text, str(path), kinds=kinds, site=site, start_utc=start_utc)
