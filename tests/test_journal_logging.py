"""Logs under systemd: a syslog priority on every line, the service's story at INFO.

``reachd --sim`` runs with its standard output and error on one pipe and
``JOURNAL_STREAM`` naming that pipe's device and inode, as systemd sets them for a unit
whose output goes to the journal. A calibrating job goes through it; every line it
writes must start with ``<N>``, and the job's start and end, the state transitions,
who asked for what, and the calibration's result must be there at ``<6>`` (INFO), so
that ``journalctl -u reachd -p info`` tells the story and ``-p warning`` leaves it out.
"""

import os
import pty
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from reach_receiver.daemon.client import DaemonClient

ENTRY = "from reach_receiver.cli import {main}; import sys; sys.exit({main}(sys.argv[1:]))"
#: A calibration in a few seconds of the simulator: four calibrators, the antenna, a solve.
CALIBRATING = """\
schedule: journal
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
PRIORITY = re.compile(r"^<[0-7]>")


class JournalPipe:
    """One pipe for standard output and error, read as the journal would, line by line."""

    def __init__(self) -> None:
        self.read_end, self.write_end = os.pipe()
        info = os.fstat(self.write_end)
        self.stream = f"{info.st_dev}:{info.st_ino}"
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        with os.fdopen(self.read_end, encoding="utf-8", errors="replace") as pipe:
            for line in pipe:
                self.lines.append(line.rstrip("\n"))

    def wait_for(self, pattern: str, timeout_s: float = 120.0) -> str:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            found = [line for line in list(self.lines) if re.search(pattern, line)]
            if found:
                return found[0]
            time.sleep(0.05)
        raise AssertionError(f"no line matches {pattern!r}:\n" + "\n".join(self.lines))

    def close(self) -> list[str]:
        self._reader.join(timeout=30)
        return list(self.lines)


def start_reachd(root: Path, journal: JournalPipe, stream: str) -> subprocess.Popen:
    env = {**os.environ, "JOURNAL_STREAM": stream}
    process = subprocess.Popen(
        [sys.executable, "-c", ENTRY.format(main="reachd_main"), "--sim",
         "--state-dir", str(root / "state"), "--runtime-dir", str(root / "run")],
        stdout=journal.write_end, stderr=journal.write_end, env=env,
    )
    os.close(journal.write_end)  # the child holds it; the reader ends when the child does
    return process


def test_every_line_has_a_priority_and_the_story_is_at_info(tmp_path):
    journal = JournalPipe()
    process = start_reachd(tmp_path, journal, journal.stream)
    try:
        journal.wait_for(r"serving .*control\.sock", timeout_s=90)
        schedule = tmp_path / "journal.yaml"
        schedule.write_text(CALIBRATING)
        with DaemonClient(tmp_path / "run" / "control.sock") as client:
            client.request("status")  # a read: at DEBUG, not in the journal by default
            client.request("submit", schedule=str(schedule), files={str(schedule): CALIBRATING})
            events = [m["event"] for m in client.follow(1)]
        assert events[-1]["state"] == "completed", events[-1]
        journal.wait_for(r"job 1 journal completed")
    finally:
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=60) == 0
    lines = journal.close()
    unprefixed = [line for line in lines if line and not PRIORITY.match(line)]
    assert not unprefixed, unprefixed
    info = [line[3:] for line in lines if line.startswith("<6>")]
    # No timestamp of its own: the journal stamps each line.
    assert not any(re.match(r"\d{4}-\d\d-\d\d \d\d:", line) for line in info), info[:5]
    text = "\n".join(info)
    for expected in (
        r"state starting -> idle",
        r"control: submit from uid \d+",
        r"job 1 journal started: .*journal\.yaml, 9 steps",
        r"state idle -> running: job 1 journal",
        r"journal\.yaml:\d+: calibrated: orders \(.*\), noise scale s\^2 [\d.]+, distance to "
        r"floor [\d.]+ on 'ant'",
        r"check test load: PASS",
        r"solution: orders \(\d+, \d+, \d+, \d+, \d+\)",
        r"noise scale s\^2 \d+\.\d+",
        r"on 'ant': noise floor [\d.]+ mK, predicted calibration std [\d.]+ mK",
        r"session:     distance to floor [\d.]+",
        r"actual calibration error against the simulator's truth",
        r"job 1 journal completed; report in .*report",
        r"state running -> idle: job 1 completed",
        r"state idle -> stopping: signal SIGTERM",
    ):
        assert re.search(expected, text), (expected, text)
    assert "control: status from" not in text  # a poll is no story
    # The monitor's alarms, if any came and went: raised a warning, cleared at INFO.
    for line in lines:
        if "alarm raised" in line:
            assert line.startswith("<4>"), line
        if "alarm cleared" in line:
            assert line.startswith("<6>"), line
    # The same result in the run's own log.
    (run_log,) = (tmp_path / "state" / "runs").glob("*/run.log")
    assert re.search(r"INFO .*solution: orders \(", run_log.read_text())


LOG = """\
import logging, sys
from reach_receiver.cli.logs import configure_logging
configure_logging(False)
log = logging.getLogger("reach_receiver.probe")
log.info("an info line")
log.warning("a warning line")
try:
    1 / 0
except ZeroDivisionError:
    log.exception("a failure")
print("printed")
print("printed on stderr", file=sys.stderr)
"""


def run_probe(stream_of_pipe: bool, tmp_path: Path) -> list[str]:
    """The probe's output on a file that is (or is not) the stream JOURNAL_STREAM names."""
    out = tmp_path / "out.txt"
    other = tmp_path / "other.txt"
    out.touch()
    other.touch()
    info = os.stat(out if stream_of_pipe else other)
    with out.open("w") as handle:
        subprocess.run(
            [sys.executable, "-c", LOG], stdout=handle, stderr=handle, check=True,
            env={**os.environ, "JOURNAL_STREAM": f"{info.st_dev}:{info.st_ino}"},
        )
    return out.read_text().splitlines()


def test_a_traceback_has_the_priority_on_every_line_and_prints_get_one(tmp_path):
    lines = run_probe(True, tmp_path)
    assert "<6>reach_receiver.probe: an info line" in lines
    assert "<4>reach_receiver.probe: a warning line" in lines
    failure = lines.index("<3>reach_receiver.probe: a failure")
    traceback = lines[failure + 1:lines.index("<6>printed")]
    assert traceback[0] == "<3>Traceback (most recent call last):", lines
    assert traceback[-1] == "<3>ZeroDivisionError: division by zero", lines
    assert all(line.startswith("<3>") for line in traceback), lines
    assert "<6>printed" in lines
    assert "<3>printed on stderr" in lines


def test_a_journal_stream_that_is_not_standard_error_changes_nothing(tmp_path):
    # A child of a service whose output was redirected inherits JOURNAL_STREAM: its own
    # standard error is another file, and the lines are as on a terminal.
    lines = run_probe(False, tmp_path)
    assert not any(PRIORITY.match(line) for line in lines), lines
    assert not any("an info line" in line for line in lines)  # WARNING by default
    assert re.match(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} reach_receiver.probe: a warning line",
                    lines[0]), lines
    assert "printed" in lines


WIDE = """\
import logging
from reach_receiver.cli.logs import configure_logging
configure_logging(False)
logging.getLogger("reach_receiver.monitor.access").warning(
    "monitor: spectrometer does not answer: spectrometer: no datagram for 66 s, and a few "
    "more words to go well past the edge of an eighty-column terminal")
"""


def test_on_a_terminal_a_long_log_line_is_wrapped_within_80_columns(tmp_path):
    main, child = pty.openpty()
    env = {k: v for k, v in os.environ.items() if k != "JOURNAL_STREAM"}
    process = subprocess.Popen([sys.executable, "-c", WIDE], stderr=child, env=env)
    os.close(child)
    chunks = []
    while True:
        try:
            chunk = os.read(main, 4096)
        except OSError:  # EIO: the child closed the terminal
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(main)
    assert process.wait(timeout=30) == 0
    lines = b"".join(chunks).decode().replace("\r\n", "\n").splitlines()
    assert len(lines) >= 3, lines
    assert all(len(line) <= 80 for line in lines), lines
    assert re.match(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} reach_receiver.monitor.access: ",
                    lines[0]), lines
    assert all(line.startswith("    ") for line in lines[1:]), lines
    assert " ".join(x.strip() for x in lines).endswith("edge of an eighty-column terminal")
