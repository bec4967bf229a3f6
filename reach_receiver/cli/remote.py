"""``reach-run`` as a client of the daemon: submit, follow, detach, re-attach (requests: .steer).

When ``reachd`` owns the hardware (its control socket answers in the site's runtime
directory), ``reach-run schedule.yaml`` checks the schedule locally, sends it with every
file it includes, prints the job's progress as it comes, and exits with the run's
outcome (0 completed, 1 otherwise). What it prints is what a local run prints: its
progress on standard error (each step, progress inside long ones, the run's warnings),
its result on standard output (the checks, the solution, the distance to the noise
floor, the report), then ``job N completed``. Ctrl-C detaches: the run goes on in the daemon and
``reach-run --attach [JOB]`` follows it again. ``--detach`` submits and returns at once.

A daemon that will not talk to this user says so ("refused: not a member of the
service's group"), and one that cannot be reached is named with the reason; neither is
taken for a daemon that is not there.
"""

from __future__ import annotations

import logging
import signal
import sys
import threading
import time
from typing import Any

from reach_receiver.daemon.client import DaemonClient
from reach_receiver.daemon.protocol import Closed, ControlError
from reach_receiver.run.progress_lines import step_lines, update_line
from reach_receiver.schedule.steps import Schedule

from .steer import unreached


def submit(client: DaemonClient, schedule: Schedule, path: str, detach: bool) -> int:
    """Send a compiled schedule's files; follow the job unless ``detach``."""
    try:
        answer = client.request("submit", schedule=path, files=dict(schedule.files))
    except (Closed, OSError) as err:
        print(f"reach-run: {unreached(client, err)}", file=sys.stderr)
        return 1
    except ControlError as err:
        print(f"reach-run: the daemon refused {path}: {err}", file=sys.stderr)
        for problem in err.problems:
            print(problem, file=sys.stderr)
        return 2
    job = answer["job"]
    print(f"submitted to reachd: job {job['id']} ({job['name']})", flush=True)
    if detach:
        print(f"follow it with: reach-run --attach {job['id']}")
        return 0
    return follow(client, int(job["id"]))


def follow(client: DaemonClient, job: int | None) -> int:
    """Print a job's events until it ends (exit 0 if it completed); Ctrl-C detaches.

    Ctrl-C is Python's KeyboardInterrupt, set here explicitly: Python installs it only
    when SIGINT was not ignored at start, and a parent (a non-interactive shell's
    background job, a test runner's worker) may have left it ignored. A local run
    installs its own handlers the same way (``cli/run.py``).
    """
    state = "unknown"
    which = job
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        for message in client.follow(job):
            event = message["event"]
            which = event.get("job", which)
            _print(event)
            if message.get("end"):
                state = str(event.get("state"))
    except KeyboardInterrupt:
        print(f"\ndetached from job {which}; it goes on. Again: reach-run --attach {which}")
        return 0
    except (ControlError, OSError) as err:
        print(f"reach-run: {unreached(client, err)}", file=sys.stderr)
        return 1
    return 0 if state == "completed" else 1


def _print(event: dict[str, Any]) -> None:
    """One event of a followed job, printed as a local run prints the same moment.

    Progress goes to standard error in the lines of a local run's plain display, the
    run's log lines through this command's own logging (so ``-v`` shows what it shows
    locally), and the result of a completed run to standard output, as ``reach-run``
    prints it after a local run.
    """
    kind = event["kind"]
    if kind == "started":
        _err([f"run directory: {event['run']}"])
    elif kind == "step":
        _err(step_lines(
            event["index"], event["total"], event["text"], event["where"],
            event.get("elapsed_s"), event.get("left_s"), event.get("real_s"),
        ))
    elif kind == "progress":
        _err(update_line(event["text"], event["done"], event["total"], event.get("left_s")))
    elif kind == "log":
        level = logging.getLevelName(event["level"])  # a number for a level's name
        record = logging.makeLogRecord({
            "name": event["logger"], "levelname": event["level"],
            "levelno": level if isinstance(level, int) else logging.WARNING,
            "msg": event["message"],
            "created": event.get("created", event.get("time", time.time())),
        })
        logging.getLogger(record.name).handle(record)
    elif kind == "end":
        job, state = event.get("job"), event["state"]
        if state != "completed":
            reason = f": {event['reason']}" if event.get("reason") else ""
            _err([f"reach-run: job {job} {state}{reason}"])
            if event.get("run"):
                _err([f"reach-run: its run directory: {event['run']}"])
            return
        for line in event.get("result") or []:
            print(line)
        if not event.get("result") and event.get("report"):  # a job recorded without its result
            print(f"report: {event['report']}")
        print(f"job {job} completed", flush=True)


def _err(lines: list[str]) -> None:
    print("\n".join(lines), file=sys.stderr, flush=True)
