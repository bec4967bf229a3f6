"""Hostile and mutated schedules for the schedules fault class.

``hostile`` builds schedules made to exhaust a checker (repeat and alias bombs,
waits adding up past any sane run, FIFOs, huge files, include chains);
``mutate`` damages one real schedule at random (seeded) and says whether the
result must be refused or may be either valid or refused.
"""

from __future__ import annotations

import os
import random
import re
from collections.abc import Callable
from pathlib import Path
from typing import Literal

Expect = Literal["invalid", "either"]


# --------------------------------------------------------------------------- hostile schedules
def _flow_repeats(depth: int) -> str:
    inner = "{connect: {source: hot}}"
    for _ in range(depth):
        inner = f"{{repeat: {{count: 2, steps: [{inner}]}}}}"
    return f"schedule: deep\nsteps:\n  - initialise\n  - {inner}\n"


def _block_repeats(depth: int) -> str:
    lines, indent = ["schedule: deep", "steps:", "  - initialise"], "  "
    for _ in range(depth):
        lines += [f"{indent}- repeat:", f"{indent}    count: 2", f"{indent}    steps:"]
        indent += "    "
    return "\n".join([*lines, f"{indent}- connect: {{source: hot}}"]) + "\n"


def _doubling(section: str, levels: int, first: str, item: Callable[[int], str]) -> str:
    lines = [f"schedule: {section}", f"{section}:", f"  x0: {first}"]
    lines += [f"  x{i}: {item(i - 1)}" for i in range(1, levels)]
    use = f"  - use: x{levels - 1}" if section == "blocks" else "  - safe"
    return "\n".join([*lines, "steps:", "  - initialise", use]) + "\n"


def _alias_bomb(levels: int) -> str:
    lines = ["schedule: lol", "vars:", "  a: &a [x, x, x, x, x, x, x, x, x, x]"]
    for i in range(1, levels):
        name, previous = chr(ord("a") + i), chr(ord("a") + i - 1)
        lines.append(f"  {name}: &{name} [{', '.join([f'*{previous}'] * 10)}]")
    return "\n".join([*lines, "steps: [initialise]"]) + "\n"


def _steps(*steps: str) -> str:
    return "schedule: n\nsteps:\n  - initialise: {rails: [tec]}\n" + "".join(
        f"  - {step}\n" for step in steps
    )


def hostile(rng: random.Random) -> list[tuple[str, str | Callable[[Path], Path]]]:
    """The bombs, the special includes and the absurd numbers, each certainly invalid."""
    depth = rng.randint(17, 22)
    texts: list[tuple[str, str | Callable[[Path], Path]]] = [
        (f"repeats nested {depth} deep (flow)", _flow_repeats(depth)),
        ("repeats nested 25 deep", _block_repeats(25)),
        ("repeats nested 40 deep", _block_repeats(40)),
        ("repeats nested 15 deep, 4 wide", _wide_repeats(15)),
        ("block bomb, 40 levels", _doubling(
            "blocks", 40, "[{connect: {source: hot}}]",
            lambda i: f"[{{use: x{i}}}, {{use: x{i}}}]")),
        ("block bomb, 15 levels", _doubling(
            "blocks", 15, "[{connect: {source: hot}}]",
            lambda i: f"[{{use: x{i}}}, {{use: x{i}}}]")),
        ("variable bomb", _doubling(
            "vars", 40, "[hot, cold]", lambda i: f'["${{x{i}}}", "${{x{i}}}"]')),
        ("string bomb", _doubling(
            "vars", 40, "xxxxxxxxxxxxxxxx", lambda i: f'"${{x{i}}}${{x{i}}}"')),
        ("variable chain 500 long", _doubling("vars", 500, "hot", lambda i: f'"${{x{i}}}"')),
        ("YAML alias bomb", _alias_bomb(9)),
        ("deep flow nesting", "schedule: x\nsteps: [initialise]\nvars:\n  a: "
         + "[" * 20_000 + "]" * 20_000 + "\n"),
        ("huge document", "schedule: x\nsteps: [initialise]\n" + "# x\n" * 2_000_000),
        ("integer of 5000 digits", _steps("wait: {seconds: " + "9" * 5000 + "}")),
        ("huge seconds", _steps("wait: {seconds: 1e300}")),
        ("huge integer seconds", _steps("wait: {seconds: " + "9" * 60 + "}")),
        ("huge count", _steps("repeat: {count: " + "9" * 60 + ", steps: [safe]}")),
        ("huge cycles", _steps("observe: {cycles: 100000000000, seconds: 200}")),
        ("huge setpoint", _steps("tec: {setpoint_c: 1e300}")),
        ("huge integer setpoint", _steps("tec: {setpoint_c: " + "9" * 60 + "}")),
        ("wait until UTC 9999", _steps("wait: {until_utc: 9999-12-31T23:59:59Z}")),
        ("wait until UTC 9999 -05:00", _steps("wait: {until_utc: '9999-12-31T23:59:59-05:00'}")),
        ("wait until UTC 0001 +05:00", _steps("wait: {until_utc: '0001-01-01T00:00:00+05:00'}")),
        ("durations that sum past 10 years", _steps(*["wait: {seconds: 3e8}"] * 4)),
        ("durations that sum to inf", _steps(*["wait: {seconds: 1e308}"] * 3)),
        ("repeat count x period overflows", _steps(
            "repeat: {count: 999999, period_s: 3e8, steps: [safe]}")),
        ("nested repeats of a million", _steps(
            "repeat: {count: 1000000, steps: [{repeat: {count: 1000000,"
            " steps: [{power: {fan: on}}]}}]}")),
        ("seconds NaN", _steps("wait: {seconds: .nan}")),
        ("seconds inf", _steps("wait: {seconds: .inf}")),
        ("seconds -inf", _steps("wait: {seconds: -.inf}")),
        ("seconds negative", _steps("wait: {seconds: -5}")),
        ("frequency 1e300", _steps("calibrate: {f_lo_hz: 1e300}")),
        ("include a FIFO", _including(lambda d: _fifo(d))),
        ("include /dev/stdin", _including(lambda d: Path("/dev/stdin"))),
        ("include /proc/kmsg", _including(lambda d: Path("/proc/kmsg"))),
        ("include /dev/zero", _including(lambda d: Path("/dev/zero"))),
        ("include /dev/urandom", _including(lambda d: Path("/dev/urandom"))),
        ("include a directory", _including(lambda d: d)),
        ("include a 2 MB file", _including(lambda d: _large(d))),
        ("include itself", _including(lambda d: d / "s.yaml")),
        ("includes 12 deep", _including(lambda d: _chain(d, 12))),
        ("a FIFO as the schedule", lambda d: _fifo(d)),
        ("/dev/zero as the schedule", lambda d: Path("/dev/zero")),
    ]
    return texts


def _wide_repeats(depth: int) -> str:
    body = "{connect: {source: hot}}"
    inner = body
    for _ in range(depth):
        inner = f"{{repeat: {{count: 2, steps: [{body}, {body}, {body}, {inner}]}}}}"
    return f"schedule: wide\nsteps:\n  - initialise\n  - {inner}\n"


def _fifo(directory: Path) -> Path:
    path = directory / "pipe.yaml"
    os.mkfifo(path)
    return path


def _large(directory: Path) -> Path:
    path = directory / "large.yaml"
    path.write_text("vars: {a: 1}\n" + "# x\n" * 500_000)
    return path


def _chain(directory: Path, depth: int) -> Path:
    for i in range(depth):
        text = f"include: [c{i + 1}.yaml]\n" if i + 1 < depth else "vars: {y: 1}\n"
        (directory / f"c{i}.yaml").write_text(text)
    return directory / "c0.yaml"


def _including(target: Callable[[Path], Path]) -> Callable[[Path], Path]:
    def make(directory: Path) -> Path:
        path = directory / "s.yaml"
        path.write_text(f"schedule: i\ninclude: ['{target(directory)}']\nsteps: [initialise]\n")
        return path

    return make


# --------------------------------------------------------------------------- mutations
BAD_NUMBERS = (".nan", ".inf", "-.inf", "1e300", "-1", "0", "9" * 40, "1e999")
SOURCES = ("ant", "cold", "hot", "ns", "r25", "r100")


def _step_lines(lines: list[str]) -> list[int]:
    """Indexes of the lines inside the top-level ``steps:`` list."""
    inside, found = False, []
    for index, line in enumerate(lines):
        if re.match(r"^\w", line):
            inside = line.startswith("steps:")
        elif inside and line.strip() and not line.lstrip().startswith("#"):
            found.append(index)
    return found


def mutate(text: str, rng: random.Random) -> tuple[str, str, Expect] | None:
    """One random mutation of a schedule's text: (what, new text, expectation)."""
    lines = text.splitlines()
    steps = _step_lines(lines)
    kind = rng.choice((
        "number", "number", "key", "source", "control", "delete", "duplicate", "swap",
        "indent", "truncate", "wrap", "include", "utc", "durations",
    ))
    if kind == "number":  # a bad number written in a step: certainly refused
        number = r"(?<=: )-?[0-9.][0-9.e+-]*"
        spots = [(i, m) for i in steps for m in re.finditer(number, lines[i])]
        if not spots:
            return None
        index, match = rng.choice(spots)
        bad = rng.choice(BAD_NUMBERS)
        line = lines[index]
        lines[index] = line[: match.start()] + bad + line[match.end() :]
        return f"number {match.group()} -> {bad[:12]} on line {index + 1}", _join(lines), "invalid"
    if kind == "key":  # a key misspelt: an unknown key or step kind
        spots = [(i, m) for i, line in enumerate(lines) if not line.lstrip().startswith("#")
                 for m in re.finditer(r"\b([a-z_0-9]+):(?= |$)", line.split("#")[0])]
        if not spots:
            return None
        index, match = rng.choice(spots)
        line = lines[index]
        lines[index] = line[: match.end(1)] + "x" + line[match.end(1) :]
        return f"key {match.group(1)} misspelt on line {index + 1}", _join(lines), "invalid"
    if kind == "source":
        source = r"\b(" + "|".join(SOURCES) + r")\b"
        spots = [(i, m) for i in steps for m in re.finditer(source, lines[i])]
        if not spots:
            return None
        index, match = rng.choice(spots)
        line = lines[index]
        lines[index] = line[: match.start()] + "nosuch" + line[match.end() :]
        return f"source {match.group()} unknown on line {index + 1}", _join(lines), "invalid"
    if kind == "control":
        at = rng.randrange(len(text))
        char = rng.choice(("\x00", "\x07", "\x1b", "\ufffe"))
        return f"control character {char!r} at {at}", text[:at] + char + text[at:], "invalid"
    if kind == "delete":
        index = rng.randrange(len(lines))
        del lines[index]
        return f"line {index + 1} deleted", _join(lines), "either"
    if kind == "duplicate":
        index = rng.randrange(len(lines))
        lines.insert(index, lines[index])
        return f"line {index + 1} duplicated", _join(lines), "either"
    if kind == "swap":
        first, second = rng.randrange(len(lines)), rng.randrange(len(lines))
        lines[first], lines[second] = lines[second], lines[first]
        return f"lines {first + 1} and {second + 1} swapped", _join(lines), "either"
    if kind == "indent":
        index = rng.randrange(len(lines))
        lines[index] = ("  " + lines[index]) if rng.random() < 0.5 else lines[index][2:]
        return f"line {index + 1} re-indented", _join(lines), "either"
    if kind == "truncate":
        at = rng.randrange(len(text))
        return f"cut at character {at}", text[:at], "either"
    if kind == "wrap":
        depth = rng.choice((1, 3, 8, 15, 16, 17, 25, 40))
        return f"steps wrapped in {depth} repeats", _join(_wrap(lines, steps, depth)), "either"
    if kind == "include":
        target = rng.choice((
            "/dev/zero", "/dev/urandom", "/dev/null", "/tmp", "/nonexistent.yaml",
            "/proc/self/mem", "/dev/stdin", "/proc/kmsg",
        ))
        return f"include {target}", f"include: ['{target}']\n" + _drop_include(lines), "invalid"
    if kind == "utc":
        year = rng.choice((1, 1970, 1999, 2200, 2500, 9999))
        at = steps[0] + 1 if steps else len(lines)
        lines.insert(at, f"  - wait: {{until_utc: {year:04d}-06-01T00:00:00Z}}")
        return f"wait until {year}", _join(lines), "invalid"
    # durations adding up past ten years, each within the bound
    at = steps[0] + 1 if steps else len(lines)
    for _ in range(rng.randint(2, 5)):
        lines.insert(at, "  - wait: {seconds: 3.0e+8}")
    return "waits adding up past 10 years", _join(lines), "invalid"


def _join(lines: list[str]) -> str:
    return "\n".join(lines) + "\n"


def _drop_include(lines: list[str]) -> str:
    return _join([line for line in lines if not line.startswith("include:")])


def _wrap(lines: list[str], steps: list[int], depth: int) -> list[str]:
    """The steps list wrapped in ``depth`` repeats of count 1."""
    if not steps:
        return lines
    body = [lines[i] for i in steps]
    head = [line for i, line in enumerate(lines) if i not in steps]
    wrapped, indent = [], "  "
    for _ in range(depth):
        wrapped += [f"{indent}- repeat:", f"{indent}    count: 1", f"{indent}    steps:"]
        indent += "    "
    shift = " " * (len(indent) - 2)  # the steps were written 2 deep
    wrapped += [shift + line for line in body]
    at = next(i for i, line in enumerate(head) if line.startswith("steps:")) + 1
    return head[:at] + wrapped + head[at:]
