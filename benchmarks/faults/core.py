"""What a fault trial is, how a command's answer is judged, and the table of verdicts."""

from __future__ import annotations

import importlib
import os
import pkgutil
import subprocess
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Literal

Verdict = Literal["clean", "crash", "lost", "silent"]
VERDICTS: tuple[Verdict, ...] = ("clean", "crash", "lost", "silent")

#: A command that has not answered in this long is a hang.
HANG_S = 30.0


@dataclass(frozen=True)
class Trial:
    """One fault tried: what, its verdict, and what was seen (the message, or why not)."""

    name: str
    verdict: Verdict
    detail: str = ""


@dataclass(frozen=True)
class Answer:
    """How a command ended: its exit code (None: hung, killed), stdout and stderr."""

    code: int | None
    stdout: str
    stderr: str

    @property
    def traceback(self) -> bool:
        """Whether it printed a Python traceback or an internal error."""
        text = self.stdout + self.stderr
        return "Traceback (most recent call last)" in text or "internal error" in text

    @property
    def message(self) -> str:
        """Its last line on stderr (or stdout): what a user reads."""
        lines = (self.stderr or self.stdout).strip().splitlines()
        return lines[-1] if lines else ""


def run_command(
    argv: Sequence[str], *, cwd: Path | None = None, timeout_s: float = HANG_S,
    stdin: str | None = None, env: dict[str, str] | None = None,
) -> Answer:
    """Run a command with a time limit; a hang is killed and answers ``code=None``."""
    try:
        done = subprocess.run(
            list(argv), cwd=cwd, input=stdin, capture_output=True, text=True,
            timeout=timeout_s, env={**os.environ, **(env or {})},
            stdin=None if stdin is not None else subprocess.DEVNULL,
        )
    except subprocess.TimeoutExpired as err:
        out = err.stdout.decode(errors="replace") if isinstance(err.stdout, bytes) else ""
        return Answer(None, out, f"hung: no answer in {timeout_s:g} s")
    return Answer(done.returncode, done.stdout, done.stderr)


def python_command(module: str, *args: str) -> list[str]:
    """``python -m module args`` with this interpreter (the installed entry points' code)."""
    return [sys.executable, "-m", module, *args]


def judge_refusal(name: str, answer: Answer, *, intact: bool = True, says: str = "") -> Trial:
    """A bad input must be refused: a non-zero exit, one clear message, nothing lost.

    ``intact`` is whether every input (and stored measurement) is as it was; ``says`` a
    word the message must hold (case-insensitive), naming what was wrong.
    """
    if answer.code is None or answer.code < 0 or answer.traceback:
        why = answer.stderr.strip().splitlines()[-1:] or [f"exit {answer.code}"]
        return Trial(name, "crash", why[0][:200])
    if not intact:
        return Trial(name, "lost", answer.message[:200])
    if answer.code == 0:
        return Trial(name, "silent", "accepted (exit 0)")
    if not answer.message or (says and says.lower() not in answer.message.lower()):
        return Trial(name, "silent", f"refused without saying {says!r}: {answer.message[:160]}")
    return Trial(name, "clean", answer.message[:200])


# ------------------------------------------------------------------ the classes and the table
TrialsOf = Callable[[Path, bool], Iterable[Trial]]


def fault_classes() -> Iterator[ModuleType]:
    """Every module of :mod:`benchmarks.faults` that defines a class of faults."""
    package = importlib.import_module("benchmarks.faults")
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda i: i.name):
        module = importlib.import_module(f"benchmarks.faults.{info.name}")
        if hasattr(module, "CLASS") and hasattr(module, "trials"):
            yield module


def tally(trials: Iterable[Trial]) -> dict[Verdict, int]:
    """How many trials had each verdict."""
    counts: dict[Verdict, int] = dict.fromkeys(VERDICTS, 0)
    for trial in trials:
        counts[trial.verdict] += 1
    return counts


def table(rows: Sequence[tuple[str, dict[Verdict, int]]]) -> str:
    """The table "class, tried, clean, crash, lost, silent", one row a class and a total."""
    width = max([len("class"), *(len(name) for name, _ in rows)])
    head = f"{'class':<{width}}  {'tried':>5}" + "".join(f"  {v:>6}" for v in VERDICTS)
    lines = [head, "-" * len(head)]
    total: dict[Verdict, int] = dict.fromkeys(VERDICTS, 0)
    for name, counts in [*rows]:
        for v in VERDICTS:
            total[v] += counts[v]
        lines.append(_row(name, counts, width))
    lines.append("-" * len(head))
    lines.append(_row("all", total, width))
    return "\n".join(lines)


def _row(name: str, counts: dict[Verdict, int], width: int) -> str:
    tried = sum(counts.values())
    return f"{name:<{width}}  {tried:>5}" + "".join(f"  {counts[v]:>6}" for v in VERDICTS)
