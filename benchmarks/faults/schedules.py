"""Faults of schedules: mutated and hostile schedules, each judged through ``reach-run``.

Every trial is one schedule file checked by ``reach-run --sim --validate <file>`` (the
real command's ``run_main``, in a process of its own) and judged by how it ended:

* ``clean``: refused (non-zero exit) with a ``file:line: key: message`` line and no
  traceback; or accepted when the schedule really is valid (below);
* ``crash``: a traceback, no answer within :data:`HANG_S`, more than :data:`CPU_S` of
  CPU, or killed (out of memory under :data:`MEMORY_BYTES` of address space);
* ``silent``: an invalid schedule accepted (exit 0), or a refusal that names no line.

The schedules are the real ones of ``schedules/`` mutated at random (seeded): bad
numbers written in a step, keys misspelt, sources unknown, control characters, lines
deleted, duplicated, swapped or re-indented, the text cut short, the steps wrapped in
repeats, includes of special files, waits to far-away times; and the hostile ones
("bombs"): repeats nested 15-40 deep, blocks and variables that double at each level,
strings that double, YAML alias bombs and deep flow nesting, a huge document, includes
of a FIFO, ``/dev/stdin``, ``/dev/zero``, ``/dev/urandom``, ``/proc/kmsg``, a directory.

A mutation is either certainly invalid (exit 0 is ``silent``) or may happen to be
valid (a deleted comment, a duplicated step). For the latter an accepted schedule is
judged by what it compiled to, independently of the checks that accepted it: it is
valid when every number in its steps is finite and within the language's bounds, its
times fall within 2000-2199 and its estimated duration is at most 10 years; an accepted
schedule failing that is ``silent``.

Loading ``reach-run`` costs seconds (numpy, astropy's sidereal tables), so the command
runs in a fork server (:func:`serve`): one process imports it and checks a real schedule
once (loading what a first check loads), then forks a child per schedule that calls
``run_main`` with the command line, its
standard output and error in files, its address space and CPU limited; the server
reports the child's exit status, output and CPU time. A few trials of the full set also
run the installed ``reach-run`` itself (:func:`~.core.run_command`), to hold the fork
server's verdicts to the real command's.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import random
import re
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .core import HANG_S, Answer, Trial, run_command
from .schedule_cases import Expect, hostile, mutate

CLASS = "schedules"

SCHEDULES = Path(__file__).resolve().parents[2] / "schedules"
#: The command every schedule is checked with (10 s simulated spectra: the real
#: schedules, REACH's 60 s spectra every 300 s included, are valid with them).
ARGV = ("--sim", "--compression", "1000", "--validate")
#: More CPU than this for one check is unbounded checking.
CPU_S = 5.0
#: Address space a check may add to what the command's imports take.
MEMORY_BYTES = 1 << 30
#: ``file:line: key: message``, the form of every problem.
PROBLEM = re.compile(r"^\S.*:\d+: \S+: .+", re.MULTILINE)

@dataclass(frozen=True)
class Case:
    """One schedule to check: its name, its file, and whether it must be refused."""

    name: str
    path: Path
    expect: Expect


# --------------------------------------------------------------------------- the fork server
def serve() -> None:
    """Answer check requests on stdin, one JSON line each, forking a child per check.

    A request is ``{"args": [...], "out": dir, "oracle": bool}``; the answer
    ``{"code": int | null, "cpu_s": float, "stdout": str, "stderr": str, "valid": ...}``
    (``code`` null: killed, hung or by a signal). ``valid`` is the oracle's judgement of
    an accepted schedule (:func:`sane`), when asked.
    """
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    import resource

    from reach_receiver.cli import run_main

    with contextlib.redirect_stdout(io.StringIO()):  # what a first check loads, once
        run_main([*ARGV, str(SCHEDULES / "quick.yaml")])
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        request = json.loads(line)
        out = Path(request["out"])
        pid = os.fork()
        if pid == 0:  # the child: the command, then the oracle
            code = 1
            try:
                for fd, name in ((1, "stdout"), (2, "stderr")):
                    target = os.open(out / name, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
                    os.dup2(target, fd)
                null = os.open(os.devnull, os.O_RDONLY)
                os.dup2(null, 0)
                space = _address_space() + MEMORY_BYTES
                resource.setrlimit(resource.RLIMIT_AS, (space, space))
                resource.setrlimit(resource.RLIMIT_CPU, (int(CPU_S) + 1, int(CPU_S) + 2))
                code = _checked(run_main, request["args"])
                if code == 0 and request.get("oracle"):
                    (out / "valid").write_text(json.dumps(sane(Path(request["args"][-1]))))
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(code)
        status, cpu_s = _wait(pid, HANG_S)
        texts = {n: (out / n).read_text(errors="replace") for n in ("stdout", "stderr")}
        valid_file = out / "valid"
        valid = json.loads(valid_file.read_text()) if valid_file.exists() else None
        answer = {"code": status, "cpu_s": cpu_s, **texts, "valid": valid}
        print(json.dumps(answer), flush=True)


def _checked(run_main: Callable[[list[str]], int], args: list[str]) -> int:
    """``run_main(args)``'s exit code; an exception escaping it printed as a traceback."""
    import traceback

    try:
        return int(run_main(args))
    except SystemExit as done:
        return done.code if isinstance(done.code, int) else 1
    except BaseException:
        traceback.print_exc()
        return 1


def _address_space() -> int:
    """The address space (bytes) of the calling process, for a limit above it."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
    return 4 << 30


def _wait(pid: int, timeout_s: float) -> tuple[int | None, float]:
    """A child's exit code (None: killed or hung) and CPU seconds, killed past the limit."""
    import time

    deadline = time.monotonic() + timeout_s
    while True:
        done, status, usage = os.wait4(pid, os.WNOHANG)
        if done:
            cpu = usage.ru_utime + usage.ru_stime
            return (os.waitstatus_to_exitcode(status) if os.WIFEXITED(status) else None), cpu
        if time.monotonic() > deadline:
            os.kill(pid, 9)
            _, _, usage = os.wait4(pid, 0)
            return None, usage.ru_utime + usage.ru_stime
        time.sleep(0.005)


def sane(path: Path) -> dict[str, Any]:
    """Whether an accepted schedule is valid, judged on what it compiled to.

    Independent of the checks that accepted it: every number in the steps finite and
    within the bounds (|x| <= 1e12, counts <= 1e6), every time in 2000-2199, the
    estimated duration at most 10 years.
    """
    import dataclasses
    import math
    from datetime import date, datetime, timezone

    from reach_receiver.run import compile_schedule
    from reach_receiver.schedule.timing import estimated_duration_s
    from reach_receiver.sim.receiver import SimulationSettings, simulated_site, spectrum_period_for

    settings = SimulationSettings(compression=1000, spectrum_period_s=spectrum_period_for(1000))
    site = simulated_site(settings)
    schedule = compile_schedule(path, site=site)
    wrong: list[str] = []

    def visit(value: Any, where: str) -> None:
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            for item in dataclasses.fields(value):
                visit(getattr(value, item.name), f"{where}.{item.name}")
        elif isinstance(value, tuple | list):
            for index, item in enumerate(value):
                visit(item, f"{where}[{index}]")
        elif not isinstance(value, bool) and not _within(value):
            wrong.append(f"{where} = {value}")

    def _within(value: Any) -> bool:
        if isinstance(value, float):
            return math.isfinite(value) and abs(value) <= 1e12
        if isinstance(value, int):
            return abs(value) <= 1e12
        return not isinstance(value, date) or 2000 <= value.year <= 2199

    visit(schedule.steps, "steps")
    duration = estimated_duration_s(
        schedule, start_utc=datetime.now(timezone.utc), longitude_deg=site.longitude_deg,
        spectrum_period_s=site.devices.spectrometer.period_s,
    )
    if not duration <= 10 * 365.25 * 86_400:
        wrong.append(f"duration {duration:.3g} s")
    return {"valid": not wrong, "why": "; ".join(wrong[:3])}


class Checker:
    """The fork server, started once: ``check(path)`` runs ``reach-run`` on one schedule."""

    def __init__(self, workdir: Path) -> None:
        self.out = workdir / "answers"
        self.out.mkdir(parents=True, exist_ok=True)
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
        self.process = subprocess.Popen(
            [sys.executable, "-c", "from benchmarks.faults.schedules import serve; serve()"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env,
            cwd=Path(__file__).resolve().parents[2],
        )
        assert self.process.stdout is not None
        ready = self.process.stdout.readline()
        if not ready:
            raise RuntimeError("the fork server did not start")

    def check(self, path: Path, oracle: bool) -> tuple[Answer, float, dict[str, Any] | None]:
        """The command's answer on ``path``, its CPU seconds and the oracle's judgement."""
        assert self.process.stdin is not None
        assert self.process.stdout is not None
        for name in ("stdout", "stderr", "valid"):
            with contextlib.suppress(FileNotFoundError):
                (self.out / name).unlink()
        request = {"args": [*ARGV, str(path)], "out": str(self.out), "oracle": oracle}
        self.process.stdin.write(json.dumps(request) + "\n")
        self.process.stdin.flush()
        line = self.process.stdout.readline()
        if not line:
            raise RuntimeError(f"the fork server stopped while checking {path}")
        answer = json.loads(line)
        code = answer["code"]
        return Answer(code, answer["stdout"], answer["stderr"]), answer["cpu_s"], answer["valid"]

    def close(self) -> None:
        """Stop the server."""
        if self.process.stdin is not None:
            self.process.stdin.close()
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        if self.process.stdout is not None:
            self.process.stdout.close()


def judge(case: Case, answer: Answer, cpu_s: float, valid: dict[str, Any] | None) -> Trial:
    """The verdict on one schedule's check (see the module's docstring)."""
    detail = answer.message[:160]
    if answer.code is None or answer.code < 0 or answer.traceback:
        why = answer.stderr.strip().splitlines()[-1:] or [f"exit {answer.code}"]
        return Trial(case.name, "crash", f"{why[0][:160]} ({cpu_s:.2f} s CPU)")
    if cpu_s > CPU_S:
        return Trial(case.name, "crash", f"{cpu_s:.1f} s of CPU: {detail}")
    if answer.code == 0:
        if case.expect == "invalid":
            return Trial(case.name, "silent", "an invalid schedule accepted (exit 0)")
        if valid is None or not valid.get("valid"):
            reason = valid.get("why") if valid else "no judgement"
            return Trial(case.name, "silent", f"accepted, but {reason}")
        return Trial(case.name, "clean", f"valid, accepted ({cpu_s:.2f} s CPU)")
    if not PROBLEM.search(answer.stderr):
        return Trial(case.name, "silent", f"refused without file:line: key: {detail}")
    return Trial(case.name, "clean", f"{detail} ({cpu_s:.2f} s CPU)")


# --------------------------------------------------------------------------- the trials
def cases(workdir: Path, quick: bool, seed: int = 35) -> Iterator[Case]:
    """The schedules to check, written under ``workdir`` (each in a directory of its own)."""
    rng = random.Random(seed)
    made = 0

    def directory() -> Path:
        nonlocal made
        made += 1
        path = workdir / f"case{made:04d}"
        path.mkdir(parents=True)
        shutil.copy(SCHEDULES / "common.yaml", path / "common.yaml")
        return path

    bombs = hostile(rng)
    if quick:
        bombs = bombs[:: max(1, len(bombs) // 12)]
    for name, made_by in bombs:
        where = directory()
        if isinstance(made_by, str):
            path = where / "s.yaml"
            path.write_text(made_by)
        else:
            path = made_by(where)
        yield Case(name, path, "invalid")
    originals = sorted(p for p in SCHEDULES.glob("*.yaml") if p.name != "common.yaml")
    for original in originals:
        where = directory()
        path = where / original.name
        shutil.copy(original, path)
        yield Case(f"{original.name} as shipped", path, "either")
    count = 12 if quick else 300
    while count > 0:
        original = rng.choice(originals)
        mutation = mutate(original.read_text(), rng)
        if mutation is None:
            continue
        what, text, expect = mutation
        where = directory()
        path = where / original.name
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        count -= 1
        yield Case(f"{original.name}: {what}", path, expect)


def trials(workdir: Path, quick: bool) -> Iterator[Trial]:
    """Check every schedule through ``reach-run``; the full set also runs a few directly."""
    checker = Checker(workdir)
    checked: list[tuple[Case, Trial]] = []
    try:
        for case in cases(workdir / "schedules", quick):
            answer, cpu_s, valid = checker.check(case.path, oracle=case.expect == "either")
            trial = judge(case, answer, cpu_s, valid)
            checked.append((case, trial))
            yield trial
    finally:
        checker.close()
    if not quick:  # the installed command agrees with the fork server
        for case, trial in checked[:: max(1, len(checked) // 6)]:
            if case.path.is_fifo() or not case.path.exists():
                continue
            # a cold start (imports, astropy's tables) takes seconds, more on a busy machine
            direct = run_command(["reach-run", *ARGV, str(case.path)], timeout_s=4 * HANG_S)
            agrees = (direct.code == 0) == (trial.detail.startswith("valid"))
            verdict = trial.verdict if agrees and not direct.traceback else "crash"
            yield Trial(f"reach-run itself: {case.name}", verdict, direct.message[:160])


if __name__ == "__main__":
    serve()
