"""A job followed through ``reachd`` prints what a local ``reach-run`` prints.

The same calibrating schedule and seed run twice at once: locally (``reach-run --sim``)
and submitted to a ``reachd --sim`` and followed (``reach-run --site``). Both are real
processes of the real commands. Their numbers differ (the simulated iTPM skips spectra
when the machine is busy, so the data differ), so the lines are compared by shape,
every number a ``#`` and the run directory ``<run>``: the same result lines in the same
order on standard output, the same step lines on standard error, every progress line
within 80 columns. While the followed job draws its report, an abort is refused as
coming too late, and the queue is not left paused.
"""

import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sites import planning_site

from reach_receiver.clock import ManualClock
from reach_receiver.daemon.client import DaemonClient
from reach_receiver.daemon.protocol import ControlError
from reach_receiver.run import compile_text
from reach_receiver.run.progress_lines import Throttle, update_line
from reach_receiver.run.session import RunSession

ENTRY = "from reach_receiver.cli import {main}; import sys; sys.exit({main}(sys.argv[1:]))"
SCHEDULE = """\
schedule: follow
steps:
  - initialise: {}
  - temperatures: {period_s: 10}
  - vna_calibrate: {}
  - test_load_check: {}
  - s11: {targets: [cold, hot, c10open, c10short, ant, lna]}
  - dicke: {sources: [cold, hot, c10open, c10short], seconds: 60}
  - dicke: {sources: [ant], seconds: 60}
  - calibrate: {}
  - safe: {}
"""


def python(main: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", ENTRY.format(main=main), *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )


def shape(line: str, run: str) -> str:
    """A line with its run directory ``<run>`` and every number ``#``."""
    return re.sub(r"\d+(\.\d+)?", "#", line.replace(run, "<run>"))


#: The result's lines of every run of SCHEDULE (``run.summary``), by their beginnings.
ALWAYS = ("run file: ", "simulated/real time of the run: ", "check test load: PASS",
          "hand-over: ", "solution: orders (", "  averaged over models (orders, weight): ",
          "  noise scale s^2 ", "  on 'ant': noise floor ",
          "  actual calibration error against the simulator's truth: ")


def always(lines: list[str], run: str) -> list[str]:
    """The lines every run prints, by shape (the models averaged: their heading only).

    A line continued on the next ones (indented four spaces, to fit 80 columns) is
    taken whole.
    """
    whole: list[str] = []
    for x in lines:
        if x.startswith("    ") and whole:
            whole[-1] += " " + x.strip()
        else:
            whole.append(x)
    return [x.split(": (")[0] if x.startswith(ALWAYS[5]) else shape(x, run)
            for x in whole if x.startswith(ALWAYS)]


def run_directory(err: str) -> str:
    (line,) = [x for x in err.splitlines() if x.startswith("run directory: ")]
    return line.removeprefix("run directory: ")


def until(predicate, timeout_s: float = 120.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = predicate()
        if found:
            return found
        time.sleep(0.05)
    raise AssertionError("timed out")


@pytest.fixture
def reachd(tmp_path):
    process = python("reachd_main", "--sim", "--seed", "0", "--state-dir", str(tmp_path / "state"),
                     "--runtime-dir", str(tmp_path / "run"), "--site-out",
                     str(tmp_path / "site.yaml"))
    until(lambda: (tmp_path / "run" / "control.sock").exists() or process.poll() is not None)
    assert process.poll() is None, process.communicate()
    yield tmp_path / "site.yaml"
    process.terminate()
    process.communicate(timeout=60)


def abort_while_the_report_is_drawn(socket: Path) -> None:
    """Once the run file is merged (the steps are over), an abort has nothing to stop."""
    with DaemonClient(socket) as client:
        run = until(lambda: next(
            (j["run"] for j in client.request("queue")["jobs"] if j["id"] == 1 and j["run"]),
            None))
        until(lambda: (Path(run) / "run.h5").exists())
        with pytest.raises(ControlError, match=r"job 1 has run all its steps .* nothing to abort"):
            client.request("abort")
        assert client.request("status")["paused"] is False


def test_a_followed_job_prints_the_local_run_s_lines(reachd, tmp_path):
    schedule = tmp_path / "follow.yaml"
    schedule.write_text(SCHEDULE)
    local = python("run_main", "--sim", "--seed", "0", "--no-report", "--out",
                   str(tmp_path / "local"), str(schedule))
    followed = python("run_main", "--site", str(reachd), str(schedule))
    abort_while_the_report_is_drawn(tmp_path / "run" / "control.sock")
    local_out, local_err = local.communicate(timeout=300)
    assert local.returncode == 0, local_err
    out, err = followed.communicate(timeout=300)
    assert followed.returncode == 0, err

    local_run, run = run_directory(local_err), run_directory(err)
    assert run.startswith(str(tmp_path / "state" / "runs"))
    mine = local_out.splitlines()
    theirs = out.splitlines()
    # The schedule's line, then (followed) the job, the same result, its report, its end.
    assert theirs[0] == mine[0]
    assert theirs[1] == "submitted to reachd: job 1 (follow)"
    assert theirs[-2:] == [f"report: {run}/report", "job 1 completed"]
    result = theirs[2:-2]
    # The lines every such run prints, alike but for their numbers, in the same order.
    # Notes that only some data call for (a caution beside the orders, a source whose
    # error is mostly the choice of model) may come in one run and not the other.
    assert always(result, run) == always(mine[1:], local_run), (out, local_out)
    assert len(always(result, run)) == len(ALWAYS)
    wide = [x for x in theirs[1:] if len(x) > 80 and not x.startswith(("run file: ", "report: "))]
    assert not wide, wide  # 80 columns, but for a path (the first line names the schedule)

    # Standard error: the step lines alike, progress inside the steps, 80 columns.
    def steps(text: str, directory: str) -> list[str]:
        lines = text.splitlines()
        return [shape(x + " / " + lines[i + 1], directory)
                for i, x in enumerate(lines) if re.match(r"\[ *\d+/\d+\] ", x)]

    assert steps(err, run) == steps(local_err, local_run)
    assert len(steps(err, run)) == 9
    assert re.search(r"^ +Dicke cold \(1/4\): \w+: \d+/\d+, \d:\d\d:\d\d left in the step$",
                     err, re.M), err
    assert not re.search(r"\],", err)  # no stray comma where a time was missing
    # The progress lines (the daemon's log records keep a line each in a pipe: on a
    # terminal they are wrapped, test_journal_logging; a path is as long as it is).
    progress = [x for x in err.splitlines() if x.startswith(("[", " "))]
    assert len(progress) > 16
    wide = [x for x in progress if len(x) > 80]
    assert not wide, wide


class Updates:
    """A run's progress as it comes: the updates inside its steps."""

    def __init__(self) -> None:
        self.updates: list[tuple[str, int, int, float | None]] = []

    def started(self, directory: Path) -> None:
        pass

    def step(self, index, total, step, text, left_s) -> None:
        pass

    def update(self, text: str, done: int, total: int, left_s: float | None) -> None:
        self.updates.append((text, done, total, left_s))


def test_a_long_wait_reports_its_progress_in_tenths(tmp_path):
    site = planning_site()
    schedule = compile_text("schedule: w\nsteps:\n  - wait: {seconds: 3600}\n", "w.yaml",
                            site=site)
    updates = Updates()
    RunSession(schedule, site, ManualClock(1.8e9), tmp_path, progress=updates).run()
    assert [(done, total) for _, done, total, _ in updates.updates] == [
        (360 * k, 3600) for k in range(11)]
    assert [left for *_, left in updates.updates] == [3600.0 - 360 * k for k in range(11)]
    assert update_line(*updates.updates[3]) == ["         wait 1:00:00: 1080/3600, 0:42:00 left "
                                                "in the step"]


def test_progress_is_shown_at_each_tenth_at_most_once_a_second():
    def shown(seconds_per_unit: float) -> list[int]:
        throttle = Throttle()
        return [done for done in range(101) if throttle.due(done, 100, done * seconds_per_unit)]

    assert shown(0.25) == list(range(0, 101, 10))  # a tenth further each time
    assert shown(0.0625) == [*range(0, 100, 16), 100]  # a real second later; the end always
    throttle = Throttle()
    assert throttle.due(5, 100, 0.0)
    assert not throttle.due(50, 100, 0.5)
    throttle.new_step()
    assert not throttle.due(0, 100, 0.5)  # a new step's first update, a second later
    assert throttle.due(0, 100, 1.0)
