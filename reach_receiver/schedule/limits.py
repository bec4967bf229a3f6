"""The bounds of schedule validation: every schedule is checked in bounded time and memory.

A schedule may come from any member of the daemon's group, so checking one must not
hang, exhaust memory or crash whatever it holds: ``repeat`` nested 40 deep, blocks or
variables that double at each level ("bombs"), an include of a FIFO or ``/dev/zero``,
a number of 400 digits, a ``wait`` until the year 9999. Each bound below is far above
any real schedule (REACH's ``calibrate.yaml`` is 11 steps over 7.5 h in 2 KiB with its
include; a year of ``observe.yaml`` nights as a ``repeat`` is ~10 steps written and
~4,000 run, a year of ``reach_operations.yaml``'s 300 s repetitions ~3 x 10^5 run); a
schedule past one is refused with a problem at its ``file:line: key`` like any other
mistake, and checking stops there. YAML itself is bounded by the loader
(:mod:`reach_receiver.config.yaml_lines`: nesting 64 deep, integers of 100 characters,
10^5 values once aliases are expanded).

==========================  ===========  ==================================================
bound                       value        what it limits
==========================  ===========  ==================================================
:data:`MAX_FILE_BYTES`      64 KiB       one schedule or included file (read with this
                                         bound, never whole; only regular files)
:data:`MAX_TOTAL_BYTES`     128 KiB      the schedule and all it includes (the YAML
                                         parser takes ~8 us a byte: ~1 s)
:data:`MAX_FILES`           32           files read, counting an include read twice
:data:`MAX_INCLUDE_DEPTH`   8            files including files
:data:`MAX_NESTING`         16           step lists inside steps (``repeat``, ``use``);
                                         variables defined through variables
:data:`MAX_STEPS`           10,000       steps compiled (blocks written out, a repeat's
                                         body once)
:data:`MAX_RUN_STEPS`       10^7         steps a run would execute (repeats multiplied)
:data:`MAX_VALUE_NODES`     10^4         values in one variable once expanded
:data:`MAX_VALUE_DEPTH`     64           containers nested in one variable's value
:data:`MAX_COPIED_NODES`    10^5         values copied substituting all variables
:data:`MAX_TEXT_CHARS`      64 Ki        characters of one interpolated text
:data:`MAX_CHECKED_STEPS`   10^5         steps visited by the interlock and timing walks
:data:`MAX_DURATION_S`      10 years     one duration, and the whole schedule's
:data:`MAX_COUNT`           10^6         an integer that counts (``count``, ``cycles``)
:data:`MAX_NUMBER`          10^12        the magnitude of any other number (frequencies
                                         in Hz included)
:data:`UTC_YEARS`           2000-2199    a time written under a ``*_utc`` key
==========================  ===========  ==================================================

Numbers are bounded by their key's unit suffix (:func:`number_problem`): ``*_s`` and
``seconds`` are durations, ``*_utc`` times, ``*_hz``, ``*_c`` ... quantities
(:data:`UNIT_SUFFIXES`), and other integers counts; a value written under any key must
be finite. The kinds then check their own ranges (a duration > 0,
a TEC setpoint within the TEC's range) on a value that can no longer overflow.
"""

from __future__ import annotations

import math
from datetime import date, datetime

from reach_receiver.config.yaml_lines import Problem

MAX_FILE_BYTES = 64 * 1024
MAX_TOTAL_BYTES = 128 * 1024
MAX_FILES = 32
MAX_INCLUDE_DEPTH = 8
MAX_NESTING = 16
MAX_STEPS = 10_000
MAX_RUN_STEPS = 10_000_000
MAX_VALUE_NODES = 10_000
MAX_VALUE_DEPTH = 64
MAX_COPIED_NODES = 100_000
MAX_TEXT_CHARS = 64 * 1024
MAX_CHECKED_STEPS = 100_000
MAX_DURATION_S = 10 * 365.25 * 86_400.0
MAX_COUNT = 1_000_000
MAX_NUMBER = 1e12
UTC_YEARS = (2000, 2199)
#: Keys ending so name a quantity in a unit (``f_lo_hz``, ``setpoint_c``), never a count.
UNIT_SUFFIXES = ("_hz", "_c", "_dbm", "_db", "_deg", "_h", "_k", "_sigma")


class LimitExceeded(Exception):
    """Checking stopped at a bound; ``problem`` says which, where it was passed."""

    def __init__(self, problem: Problem) -> None:
        self.problem = problem
        super().__init__(str(problem))


def duration_text(seconds: float) -> str:
    """A long duration in words: ``10 years``, ``3.2 days``."""
    if seconds >= 365.25 * 86_400:
        return f"{seconds / (365.25 * 86_400):.4g} years"
    return f"{seconds / 86_400:.4g} days"


def number_problem(key: str, value: object) -> str | None:
    """What is wrong with ``value`` written under ``key`` (a dotted key), or ``None``.

    Only what no kind could accept is judged here: numbers that are not finite or past
    the bounds of their unit, and times outside :data:`UTC_YEARS`. A value of any other
    type passes (the kind reports a wrong type in its own words).
    """
    name = key.rsplit(".", 1)[-1]
    if name.endswith("_utc"):
        return _time_problem(value)
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    if isinstance(value, float) and not math.isfinite(value):
        return f"must be finite, not {value}"
    if name == "seconds" or name.endswith("_s"):
        if abs(value) > MAX_DURATION_S:
            return f"must be at most {MAX_DURATION_S:.4g} s ({duration_text(MAX_DURATION_S)})"
        return None
    if isinstance(value, int) and not name.endswith(UNIT_SUFFIXES):
        if abs(value) > MAX_COUNT:
            return f"must be at most {MAX_COUNT:,} (in magnitude)"
        return None
    if abs(value) > MAX_NUMBER:
        return f"must be at most {MAX_NUMBER:g} in magnitude, not {value:.4g}"
    return None


def _time_problem(value: object) -> str | None:
    """A time must fall in :data:`UTC_YEARS` (text that is no time is the kind's to judge)."""
    if isinstance(value, str):
        try:
            value = datetime.fromisoformat(value.strip().replace("Z", "+00:00"))
        except (ValueError, OverflowError):
            return None
    if not isinstance(value, date):
        return None
    first, last = UTC_YEARS
    if not first <= value.year <= last:
        return f"must be a time in the years {first}-{last}, not {value.year}"
    return None


class Budget:
    """The work of one compilation, counted against the bounds as it is done.

    Shared by the parser (steps compiled, nesting), the variables (values copied) and
    the interlock and timing walks (steps visited); each raises :class:`LimitExceeded`
    at the place where its bound is passed.
    """

    def __init__(self) -> None:
        self.steps = 0
        self.copied = 0
        self.checked = 0

    def step(self, file: str, line: int, key: str) -> None:
        """One step compiled (a block's steps count at each use)."""
        self.steps += 1
        if self.steps > MAX_STEPS:
            message = (
                f"the schedule has more than {MAX_STEPS:,} steps with its blocks written out"
                " (blocks using blocks several times?)"
            )
            raise LimitExceeded(Problem(file, line, key, message))

    def copy(self, nodes: int, file: str, line: int, key: str) -> None:
        """``nodes`` values copied substituting a variable."""
        self.copied += nodes
        if self.copied > MAX_COPIED_NODES:
            message = (
                f"substituting the variables copies more than {MAX_COPIED_NODES:,} values"
                " (a large variable used many times?)"
            )
            raise LimitExceeded(Problem(file, line, key, message))

    def visit(self, file: str, line: int, key: str) -> None:
        """One step visited by the interlock or the timing walk."""
        self.checked += 1
        if self.checked > MAX_CHECKED_STEPS:
            message = (
                f"checking visits more than {MAX_CHECKED_STEPS:,} steps"
                " (repeats nested in repeats?)"
            )
            raise LimitExceeded(Problem(file, line, key, message))
