"""The daemon's parts on their own: systemd notification, states, timers, lock, queue."""

import json
import os
import random
import signal
import socket
import subprocess
import sys
import time
from datetime import datetime, timedelta, timezone
from pathlib import Path

import pytest

from reach_receiver.config.daemon import DaemonSettings, TimerSettings
from reach_receiver.daemon.jobs import JobQueue
from reach_receiver.daemon.lock import HardwareBusy, HardwareLock
from reach_receiver.daemon.notify import Notifier, Watchdog
from reach_receiver.daemon.states import TRANSITIONS, StateMachine
from reach_receiver.daemon.timers import SIDEREAL_DAY_S, Timers, previous_occurrence
from reach_receiver.schedule.lst import local_sidereal_time_h

LONGITUDE = 21.52


class FakeSystemd:
    """A datagram socket where systemd would listen: what the daemon tells it."""

    def __init__(self, directory: Path) -> None:
        self.path = directory / "notify.sock"
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(str(self.path))
        self.sock.settimeout(0.05)

    def messages(self) -> list[dict[str, str]]:
        out = []
        while True:
            try:
                data = self.sock.recv(4096)
            except TimeoutError:
                return out
            out.append(dict(line.split("=", 1) for line in data.decode().splitlines()))


@pytest.fixture
def systemd(tmp_path):
    fake = FakeSystemd(tmp_path)
    yield fake
    fake.sock.close()


def test_notifications_reach_the_socket_named_by_the_environment(systemd):
    notifier = Notifier({"NOTIFY_SOCKET": str(systemd.path), "WATCHDOG_USEC": "200000"})
    assert notifier.enabled
    assert notifier.watchdog_s == pytest.approx(0.2)
    notifier.ready("idle")
    notifier.status("running: job 1")
    notifier.stopping("signal SIGTERM")
    notifier.close()
    assert systemd.messages() == [
        {"READY": "1", "STATUS": "idle"},
        {"STATUS": "running: job 1"},
        {"STOPPING": "1", "STATUS": "signal SIGTERM"},
    ]


def test_without_systemd_nothing_is_sent():
    notifier = Notifier({})
    assert not notifier.enabled
    assert notifier.ready("idle") is False
    assert Watchdog(notifier).feed(True) is False


def test_the_watchdog_is_fed_at_half_its_interval_and_only_while_healthy(systemd):
    watchdog = Watchdog(Notifier({"NOTIFY_SOCKET": str(systemd.path), "WATCHDOG_USEC": "100000"}))
    fed = [watchdog.feed(True) for _ in range(3)]  # at once: only the first is due
    assert fed == [True, False, False]
    time.sleep(0.06)
    assert watchdog.feed(False) is False  # due, but not healthy
    assert watchdog.feed(True) is True
    watchdog.notifier.close()
    assert systemd.messages() == [{"WATCHDOG": "1"}, {"WATCHDOG": "1"}]


def test_a_watchdog_for_another_pid_is_not_ours(systemd):
    env = {"NOTIFY_SOCKET": str(systemd.path), "WATCHDOG_USEC": "100000", "WATCHDOG_PID": "1"}
    assert Notifier(env).watchdog_s is None


def test_states_change_only_along_the_table():
    machine = StateMachine()
    seen = []
    machine.listeners.append(seen.append)
    machine.go("idle", "started")
    machine.go("running", "job 1")
    machine.go("observing", "observe step")
    with pytest.raises(RuntimeError, match="observing -> starting"):
        machine.go("starting", "no")
    machine.go("faulted", "job 1 failed")
    machine.go("stopping", "SIGTERM")
    machine.go("stopped", "done")
    assert [(t.before, t.after, t.reason) for t in seen][-1] == ("stopping", "stopped", "done")
    assert TRANSITIONS["stopped"] == ()
    for state, targets in TRANSITIONS.items():  # stopping is reachable from everywhere alive
        if state not in ("stopping", "stopped"):
            assert "stopping" in targets, state


# --------------------------------------------------------------------------- timers
START = datetime(2026, 11, 22, 12, 0, tzinfo=timezone.utc).timestamp()


def test_an_lst_timer_fires_when_the_sky_comes_round():
    timer = TimerSettings("night", Path("observe.yaml"), at_lst_h=22.0)
    at = previous_occurrence(timer, START, LONGITUDE)
    assert START - SIDEREAL_DAY_S < at <= START
    lst = local_sidereal_time_h(datetime.fromtimestamp(at, tz=timezone.utc), LONGITUDE)
    assert abs((lst - 22.0 + 12) % 24 - 12) * 3600 < 1.0
    daily = TimerSettings("noon", Path("c.yaml"), at_utc="12:00")
    assert previous_occurrence(daily, START, LONGITUDE) == START
    assert previous_occurrence(daily, START - 1, LONGITUDE) == START - 86400


def timers(tmp_path, policy="late", window_s=3600.0):
    settings = DaemonSettings(
        missed_policy=policy,
        missed_window_s=window_s,
        timers=(TimerSettings("night", Path("observe.yaml"), at_lst_h=22.0),),
    )
    return Timers(settings, LONGITUDE, tmp_path / "timers.json")


def lst_occurrence_after(t: float) -> float:
    timer = TimerSettings("night", Path("observe.yaml"), at_lst_h=22.0)
    return previous_occurrence(timer, t + SIDEREAL_DAY_S, LONGITUDE)


def test_a_running_daemon_fires_each_occurrence_once(tmp_path):
    t = timers(tmp_path)
    assert t.start(START) == []  # the first start ever fires nothing from the past
    at = lst_occurrence_after(START)
    assert t.due(at - 1) == []
    (trigger,) = t.due(at + 0.5)
    assert trigger.at == pytest.approx(at)
    assert not trigger.late
    assert t.due(at + 10) == []



def test_remembered_occurrences_are_those_of_the_sky_at_any_turn(tmp_path):
    # turns forwards, backwards (a clock set back) and days apart: each turn's answer is
    # the one a fresh question gives, and the next occurrence is at the timer's LST
    t = timers(tmp_path)
    t.start(START)
    rng = random.Random(38)
    for now in [START + rng.uniform(-3, 3) * 86_400 for _ in range(30)]:
        got = t.next_occurrences(now)["night"]
        assert now < got <= now + SIDEREAL_DAY_S + 1e-3
        lst = local_sidereal_time_h(datetime.fromtimestamp(got, tz=timezone.utc), LONGITUDE)
        assert abs((lst - 22.0 + 12) % 24 - 12) * 3600 < 1e-3
        assert got == pytest.approx(lst_occurrence_after(now), abs=1e-3)

@pytest.mark.parametrize(
    ("policy", "down_after_s", "expected"),
    [
        ("late", 600.0, "late"),  # back 10 min after the trigger: within the hour's window
        ("late", 7200.0, "skipped"),  # two hours late: beyond the window
        ("skip", 600.0, "skipped"),
    ],
)
def test_a_trigger_missed_while_down_follows_the_policy(tmp_path, caplog, policy, down_after_s,
                                                        expected):
    at = lst_occurrence_after(START)
    before = timers(tmp_path, policy)
    before.start(START)
    before.due(at - 300)  # the daemon was last alive 5 minutes before the trigger
    after = timers(tmp_path, policy)  # a restart reads timers.json
    late = after.start(at + down_after_s)
    if expected == "late":
        (trigger,) = late
        assert trigger.late
        assert trigger.at == pytest.approx(at)
    else:
        assert late == []
        assert "skipped" in caplog.text
    again = timers(tmp_path, policy)  # a second restart does not fire it again
    assert again.start(at + down_after_s + 60) == []


# --------------------------------------------------------------------------- lock and queue
HOLD = """
import sys, time
from pathlib import Path
from reach_receiver.daemon.lock import HardwareLock
lock = HardwareLock(Path(sys.argv[1]), "holder")
lock.acquire()
print("held", flush=True)
time.sleep(60)
"""


def test_one_owner_of_the_hardware_until_it_dies(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(tmp_path)], stdout=subprocess.PIPE)
    try:
        assert holder.stdout.readline().strip() == b"held"
        with pytest.raises(HardwareBusy, match=r"holder \(pid \d+\)"):
            HardwareLock(tmp_path, "second").acquire()
        os.kill(holder.pid, signal.SIGKILL)  # no clean-up at all
        holder.wait(timeout=10)
    finally:
        if holder.poll() is None:
            holder.kill()
        holder.stdout.close()
    with HardwareLock(tmp_path, "second") as lock:
        assert lock.held
        assert "second" in (tmp_path / "hardware.lock").read_text()


def test_the_queue_survives_a_restart(tmp_path):
    queue = JobQueue(tmp_path / "queue.json")
    first = queue.add("a", "a.yaml", {"a.yaml": "text"}, "uid 0", 1.0)
    second = queue.add("b", "b.yaml", {"b.yaml": "text"}, "uid 0", 2.0)
    queue.update(first, state="running", run="/runs/1")
    again = JobQueue(tmp_path / "queue.json")
    assert [j.id for j in again.jobs("queued")] == [second.id]
    assert again.get(first.id).run == "/runs/1"
    third = again.add("c", "c.yaml", {}, "timer", 3.0, first=True)
    assert third.id == 3
    assert again.next_queued().id == 3
    assert json.loads((tmp_path / "queue.json").read_text())["next_id"] == 4
    assert "files" not in third.public()


def test_timers_json_is_written_atomically(tmp_path):
    t = timers(tmp_path)
    t.start(START)
    assert json.loads((tmp_path / "timers.json").read_text())["checked"] == START
    assert not list(tmp_path.glob(".timers.json*"))
    del t
    assert timedelta(seconds=SIDEREAL_DAY_S) < timedelta(days=1)


@pytest.mark.parametrize("text", ["", "garbage{", '{"jobs": 3, "next_id": 1}',
                                  '{"jobs": [{"id": 5}], "next_id": 2}'])
def test_an_unreadable_queue_file_is_kept_aside_and_the_queue_starts_empty(tmp_path, text):
    path = tmp_path / "queue.json"
    path.write_text(text)
    queue = JobQueue(path)
    assert queue.jobs() == []
    assert "unreadable" in str(queue.read_error)
    (aside,) = tmp_path.glob("queue.json.unreadable-*")
    assert aside.read_text() == text
    queue.add("x", "x.yaml", {}, "test", 0.0)
    assert [j.id for j in JobQueue(path).jobs()] == [1]


def test_an_unreadable_timers_file_is_kept_aside_and_nothing_counts_as_missed(tmp_path):
    path = tmp_path / "timers.json"
    path.write_text('{"fired": {"nightly": "soon"}, "checked": 1}')
    timers = Timers(DaemonSettings(), 21.0, path)
    assert "unreadable" in str(timers.read_error)
    assert (timers.fired, timers.checked) == ({}, None)
    assert len(list(tmp_path.glob("timers.json.unreadable-*"))) == 1
