"""The site file's ``daemon`` section: where ``reachd`` keeps its state, and its timers.

::

    daemon:
      runtime_dir: /run/reach        # control socket, hardware lock ($RUNTIME_DIRECTORY)
      state_dir: /var/lib/reach      # queue, runs/ ($STATE_DIRECTORY)
      resume: true                   # an interrupted run carries on after a restart
      missed: {policy: late, window_s: 3600}   # a trigger missed while down
      status_port: 8470              # the status page on 127.0.0.1 only; 0 = any free port
      timers:
        - {name: night, schedule: schedules/observe.yaml, at_lst_h: 22.0}
        - {name: calibration, schedule: schedules/calibrate.yaml, at_utc: "12:00"}

A timer fires once a sidereal day at ``at_lst_h`` (hours of local sidereal time) or once
a day at ``at_utc`` (``HH:MM``). Its schedule path is relative to the site file. A
trigger missed while the daemon was down (or busy) is run late if it is at most
``window_s`` old (``policy: late``), and otherwise, or with ``policy: skip``, skipped
with a log line; either way a missed trigger runs at most once.

Without the section, ``runtime_dir`` and ``state_dir`` come from systemd's
``$RUNTIME_DIRECTORY`` and ``$STATE_DIRECTORY``, else ``/run/reach`` and
``/var/lib/reach``; nothing resumes, nothing is timed. Without ``status_port`` there is
no status page (:mod:`reach_receiver.daemon.status_page`); its host is always
``127.0.0.1`` and cannot be set.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from .fields import REQUIRED, Fields, type_name
from .yaml_lines import LineDict, LineList, Problem

DEFAULT_RUNTIME_DIR = Path("/run/reach")
DEFAULT_STATE_DIR = Path("/var/lib/reach")
DAEMON_KEYS = ("runtime_dir", "state_dir", "resume", "missed", "timers", "status_port")
TIMER_KEYS = ("name", "schedule", "at_lst_h", "at_utc")
_UTC = re.compile(r"^([01]\d|2[0-3]):([0-5]\d)$")


@dataclass(frozen=True)
class TimerSettings:
    """One daily or sidereal-daily trigger of a schedule."""

    name: str
    schedule: Path
    at_lst_h: float | None = None
    at_utc: str | None = None

    @property
    def utc_minutes(self) -> int | None:
        """Minutes after midnight UTC of an ``at_utc`` timer."""
        if self.at_utc is None:
            return None
        hours, minutes = self.at_utc.split(":")
        return int(hours) * 60 + int(minutes)


@dataclass(frozen=True)
class DaemonSettings:
    """Where the daemon keeps its files, what it resumes, when it runs schedules."""

    runtime_dir: Path | None = None
    state_dir: Path | None = None
    resume: bool = False
    missed_policy: Literal["late", "skip"] = "late"
    missed_window_s: float = 3600.0
    timers: tuple[TimerSettings, ...] = field(default=())
    status_port: int | None = None

    def runtime_directory(self, environ: Mapping[str, str] = os.environ) -> Path:
        """The runtime directory: the site's, else systemd's, else ``/run/reach``."""
        return _directory(self.runtime_dir, environ.get("RUNTIME_DIRECTORY"), DEFAULT_RUNTIME_DIR)

    def state_directory(self, environ: Mapping[str, str] = os.environ) -> Path:
        """The state directory: the site's, else systemd's, else ``/var/lib/reach``."""
        return _directory(self.state_dir, environ.get("STATE_DIRECTORY"), DEFAULT_STATE_DIR)


def _directory(given: Path | None, systemd: str | None, default: Path) -> Path:
    if given is not None:
        return given
    if systemd:
        return Path(systemd.split(":")[0])  # systemd lists several, ':'-separated
    return default


def read_daemon(section: Fields, site_file: str, problems: list[Problem]) -> DaemonSettings:
    """Read the ``daemon`` section (``section`` reports each mistake with its line)."""
    base = Path(site_file).parent if not site_file.startswith("<") else Path(".")
    settings = DaemonSettings()
    runtime = section.text("runtime_dir", None)
    state = section.text("state_dir", None)
    resume = section.raw("resume", False)
    if not isinstance(resume, bool):
        section.report("resume", f"must be true or false, not {type_name(resume)}")
        resume = False
    policy: str = settings.missed_policy
    window = settings.missed_window_s
    missed = section.mapping("missed", ("policy", "window_s"))
    if missed is not None:
        policy = missed.choice("policy", ("late", "skip"), "late") or "late"
        window = missed.number("window_s", window, low=0.0, fallback=window)
    timers: list[TimerSettings] = []
    written = section.raw("timers", None)
    if written is not None and not isinstance(written, LineList):
        section.report("timers", f"must be a list of timers, not {type_name(written)}")
    for index, item in enumerate(written if isinstance(written, LineList) else []):
        line = written.line_of(index)
        key = f"daemon.timers[{index}]"
        if not isinstance(item, LineDict):
            message = f"must be a mapping, not {type_name(item)}"
            problems.append(Problem(site_file, line, key, message))
            continue
        timer = Fields(item, file=site_file, key=key, allowed=TIMER_KEYS, problems=problems)
        timers.append(_timer(timer, base))
    status_port = None
    if section.has("status_port"):
        port = section.raw("status_port")
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            section.report("status_port", f"must be a port number in [0, 65535], not {port!r}")
        else:
            status_port = port
    names = [t.name for t in timers]
    for name in {n for n in names if names.count(n) > 1}:
        section.report("timers", f"two timers are named {name!r}")
    return DaemonSettings(
        runtime_dir=Path(runtime) if runtime else None,
        state_dir=Path(state) if state else None,
        resume=resume,
        missed_policy="skip" if policy == "skip" else "late",
        missed_window_s=window,
        timers=tuple(timers),
        status_port=status_port,
    )


def _timer(timer: Fields, base: Path) -> TimerSettings:
    name = timer.text("name") or ""
    schedule = timer.text("schedule") or ""
    lst = None
    if timer.has("at_lst_h"):
        lst = timer.number("at_lst_h", REQUIRED, low=0.0, high=24.0, open_high=True)
    utc = timer.text("at_utc", None)
    if utc is not None and not _UTC.match(utc):
        timer.report("at_utc", f"must be HH:MM (UTC), not {utc!r}")
        utc = None
    if (lst is None) == (utc is None) and not timer.failed:
        timer.report("<when>", "give exactly one of at_lst_h, at_utc", timer.args.line)
    path = Path(schedule)
    return TimerSettings(name, path if path.is_absolute() else base / path, lst, utc)


def daemon_yaml(daemon: DaemonSettings) -> dict[str, Any]:
    """The ``daemon`` section that :func:`read_daemon` reads back as ``daemon``."""
    out: dict[str, Any] = {"resume": daemon.resume}
    if daemon.runtime_dir is not None:
        out["runtime_dir"] = str(daemon.runtime_dir)
    if daemon.state_dir is not None:
        out["state_dir"] = str(daemon.state_dir)
    out["missed"] = {"policy": daemon.missed_policy, "window_s": daemon.missed_window_s}
    if daemon.status_port is not None:
        out["status_port"] = daemon.status_port
    if daemon.timers:
        out["timers"] = [
            {
                "name": t.name,
                "schedule": str(t.schedule),
                **({"at_lst_h": t.at_lst_h} if t.at_lst_h is not None else {}),
                **({"at_utc": t.at_utc} if t.at_utc is not None else {}),
            }
            for t in daemon.timers
        ]
    return out
