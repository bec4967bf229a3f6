"""SIGHUP, SIGTERM and SIGINT at random moments of a simulated run.

reach-run runs in its own process against a simulator in this one (the site file carries
the simulator's compressed clock), so a real signal reaches a real run. Whenever it
lands, the front-end (as the simulated board itself reports it) ends in its safe state,
the run file is closed as "interrupted" with the signal's name, and every measurement
completed before the signal is in it.
"""

import os
import random
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from reach_receiver.cli import run_main
from reach_receiver.clock import WAIT_SLICE_S, StopEvent
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings
from reach_receiver.store import RUN_FILE, read_run_file
from reach_receiver.store.parts import PartInfo, list_parts

SCHEDULE = """\
schedule: signals
steps:
  - initialise: {rails: [12v, 24v, 6v, fan]}
  - dicke: {sources: [cold, hot, r25, r100, c2r27, c2r36], seconds: 600}
  - s11: {targets: [hot, cold, lna]}
  - safe
"""
#: One Dicke cycle (three positions of 600 s, and the switching) takes ~0.66 s real at
#: 3000x; the whole run ~4.5 s real after its directory appears.
DICKE_SOURCES = 6
ENTRY = "from reach_receiver.cli import run_main; import sys; sys.exit(run_main(sys.argv[1:]))"
SAFE = {
    "ns": "0",
    "6v": "0",
    "12v": "0",
    "ms1": "0",
    "ms2": "0",
    "ms3": "0",
    "ms4": "0",
    "mts": "lna",
}
START_TIMEOUT_S = 60.0


def _cases() -> list[tuple[signal.Signals, int, float]]:
    """(signal, Dicke cycles completed before it, extra delay in s): seeded, repeatable.

    Each signal is sent once before the first Dicke cycle completes and once later, in
    the middle of a cycle or right after a measurement was stored (a delay near 0).
    """
    rng = random.Random(20210521)
    cases = []
    for sig in (signal.SIGHUP, signal.SIGTERM, signal.SIGINT):
        cases.append((sig, 0, round(rng.uniform(0.0, 0.45), 3)))
        cases.append((sig, rng.randint(1, DICKE_SOURCES - 1), round(rng.uniform(0.0, 0.5), 3)))
    return cases


CASES = _cases()


@pytest.fixture(scope="module")
def sim():
    settings = SimulationSettings(compression=3000.0, spectrum_period_s=30.0, seed=7)
    with SimulatedReceiver(settings) as receiver:
        yield receiver


@pytest.fixture(scope="module")
def files(sim, tmp_path_factory):
    folder = tmp_path_factory.mktemp("signals")
    site, schedule = folder / "site.yaml", folder / "signals.yaml"
    site.write_text(sim.site().to_yaml())
    schedule.write_text(SCHEDULE)
    assert run_main([str(schedule), "--site", str(site), "--validate"]) == 0
    return site, schedule


def _start(schedule: Path, site: Path, out: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-c", ENTRY, str(schedule), "--site", str(site), "--out", str(out), "-q"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_until(condition, proc: subprocess.Popen[str], what: str, timeout_s: float) -> None:
    """Poll ``condition()`` (another process is working towards it) until it holds."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"reach-run ended ({proc.returncode}) before {what}:\n{out}\n{err}")
        if time.monotonic() > deadline:
            proc.kill()
            out, err = proc.communicate()
            pytest.fail(f"no {what} within {timeout_s} s:\n{out}\n{err}")
        time.sleep(0.02)


def _run_directory(out: Path, proc: subprocess.Popen[str]) -> Path:
    _wait_until(lambda: out.is_dir() and any(out.iterdir()), proc, "run directory", 60.0)
    (directory,) = out.iterdir()
    return directory


def _dicke_parts(directory: Path) -> int:
    return sum(1 for p in list_parts(directory) if p.kind == "dicke")


def _measurements(parts: list[PartInfo]) -> list[PartInfo]:
    """The parts that are measurements (not the run's description, which every run has)."""
    return [p for p in parts if p.kind != "run"]


def _board(sim) -> dict[str, str]:
    """The pins as the simulated board reports them, every line it wrote taken in."""
    sim.teensy.sync()
    return sim.teensy.state


def _unsafe(pins: dict[str, str]) -> dict[str, str]:
    return {pin: pins.get(pin) for pin, value in SAFE.items() if pins.get(pin) != value}


def _finish(proc: subprocess.Popen[str]) -> tuple[int, str]:
    try:
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
        pytest.fail(f"reach-run did not end within 60 s of the signal:\n{err}")
    return proc.returncode, err


def _check_closed(directory: Path, name: str, err: str):
    run_file = directory / RUN_FILE
    assert run_file.is_file(), f"no run file; reach-run said:\n{err}"
    contents = read_run_file(run_file)
    assert contents.merged
    assert contents.status == "interrupted", (contents.status, contents.reason, err)
    assert name in contents.reason, contents.reason
    assert "front-end in its safe state" in contents.reason, contents.reason
    assert "reads otherwise" not in contents.reason, contents.reason
    assert not list_parts(directory), "parts left over: the run was not merged"
    events = [(m.name, m.attrs.get("message", "")) for m in contents.of_kind("event")]
    assert any(kind == "interrupted" and name in message for kind, message in events), events
    return contents


@pytest.mark.parametrize(
    ("sig", "cycles", "delay_s"),
    CASES,
    ids=[f"{s.name}-after{c}-{d:.3f}s" for s, c, d in CASES],
)
def test_a_signal_mid_run_ends_safe_and_keeps_every_measurement(
    sim, files, tmp_path, sig, cycles, delay_s
):
    site, schedule = files
    out = tmp_path / "runs"
    proc = _start(schedule, site, out)
    directory = _run_directory(out, proc)
    # initialise has switched the rails on: from here the board is not in its safe state.
    _wait_until(
        lambda: _board(sim).get("12v") == "1" and _board(sim).get("6v") == "1",
        proc,
        "rails on",
        START_TIMEOUT_S,
    )
    _wait_until(lambda: _dicke_parts(directory) >= cycles, proc, f"{cycles} Dicke", 30.0)
    time.sleep(delay_s)
    before = _board(sim)
    done = list_parts(directory)
    proc.send_signal(sig)
    assert proc.poll() is None, "the run ended before the signal: choose an earlier moment"
    assert _unsafe(before), f"the board was already safe before the signal: {before}"

    code, err = _finish(proc)

    assert code == 1, err
    assert f"signal {sig.name}" in err, err  # in full: a device fault names itself here
    contents = _check_closed(directory, sig.name, err)
    stored = {(m.sequence, m.kind, m.name) for m in contents.measurements}
    missing = [(p.sequence, p.kind, p.name) for p in _measurements(done)]
    missing = [key for key in missing if key not in stored]
    assert not missing, f"completed before the signal but not in the run file: {missing}"
    assert len(contents.of_kind("dicke")) >= sum(1 for p in done if p.kind == "dicke")
    pins = _board(sim)
    assert not _unsafe(pins), f"the board is not safe after the run: {pins}"
    assert pins.get("boot") == "por", "a watchdog reset, not the run, made the board safe"


def test_a_second_signal_stops_at_once_and_still_ends_safe(sim, files, tmp_path):
    site, schedule = files
    out = tmp_path / "runs"
    proc = _start(schedule, site, out)
    directory = _run_directory(out, proc)
    _wait_until(lambda: _dicke_parts(directory) >= 1, proc, "a Dicke cycle", 30.0)
    time.sleep(0.2)
    before = _board(sim)
    done = list_parts(directory)
    proc.send_signal(signal.SIGTERM)
    proc.send_signal(signal.SIGINT)  # at once: it escalates before the run sees the first
    assert _unsafe(before), f"the board was already safe before the signals: {before}"

    code, err = _finish(proc)

    assert code == 1, err
    contents = _check_closed(directory, "signal SIG", err)
    stored = {(m.sequence, m.kind) for m in contents.measurements}
    assert {(p.sequence, p.kind) for p in _measurements(done)} <= stored
    pins = _board(sim)
    assert not _unsafe(pins), f"the board is not safe after the run: {pins}"


def test_a_hang_up_of_the_whole_process_group_with_sim_ends_safe(files, tmp_path):
    """A terminal hang-up signals reach-run's whole group: its simulated Teensy must outlive it.

    The firmware's host build is reach-run's child; were it in reach-run's process group,
    the hang-up would end it too, before reach-run had put the front-end in its safe state.
    """
    _, schedule = files
    out = tmp_path / "runs"
    command = [sys.executable, "-c", ENTRY, str(schedule), "--sim", "--compression", "3000"]
    proc = subprocess.Popen(
        [*command, "--out", str(out), "-q"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # it leads its own process group, as in a terminal
    )
    try:
        directory = _run_directory(out, proc)
        _wait_until(lambda: _dicke_parts(directory) >= 1, proc, "a Dicke cycle", 30.0)
        time.sleep(0.1)
        os.killpg(proc.pid, signal.SIGHUP)
        code, err = _finish(proc)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()

    assert code == 1, err
    contents = _check_closed(directory, "SIGHUP", err)
    assert "could not reach the safe state" not in contents.reason
    # The board is gone with reach-run: the state it read back is in the interrupted event.
    (event,) = [m for m in contents.of_kind("event") if m.name == "interrupted"]
    pins = dict(re.findall(r"(\w+)=(\w+)", event.attrs["message"]))
    assert not _unsafe(pins), event.attrs["message"]


_HANDLER_STRIKES_IN_WAIT = """
import os, signal, threading
from reach_receiver.clock import StopEvent
event = {kind}()
# The lock wait() holds while it checks and re-checks the flag (private: this is where a
# signal handler can strike in the thread it interrupts).
lock = event._signal_safe if isinstance(event, StopEvent) else event._cond
signal.signal(signal.SIGUSR1, lambda *_: event.set())
with lock:
    os.kill(os.getpid(), signal.SIGUSR1)
    for _ in range(1000):  # bytecode boundaries, where the handler runs
        pass
print(event.wait(0.0))
"""


@pytest.mark.parametrize(("kind", "hangs"), [("threading.Event", True), ("StopEvent", False)])
def test_a_signal_handler_sets_the_stop_event_its_thread_is_waiting_on(kind, hangs):
    """reachd once hung for good on SIGTERM: the handler set the halt event while the main
    thread, interrupted inside its wait, held the event's lock. A threading.Event's set()
    then waits for ever (the check that this test can fail); a StopEvent is set at once."""
    try:
        done = subprocess.run(
            [sys.executable, "-c", _HANDLER_STRIKES_IN_WAIT.format(kind=kind)],
            capture_output=True, text=True, timeout=3.0,
        )
    except subprocess.TimeoutExpired:
        assert hangs, f"{kind}: set() from the handler hung"
        return
    assert not hangs, f"{kind} did not hang: {done.stdout} {done.stderr}"
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True"


def test_a_stop_event_set_without_a_notify_is_seen_within_a_slice():
    """A handler that strikes between wait()'s check of the flag and its registering as a
    waiter sets the flag with no one to notify. The state that leaves (the flag set, the
    waiter not woken) is made here directly: the wait must see it within one slice, not
    at the end of its 30 s."""
    event = StopEvent()
    seen: list[float] = []

    def wait() -> None:
        if event.wait(30.0):
            seen.append(time.monotonic())

    waiter = threading.Thread(target=wait)
    waiter.start()
    time.sleep(0.1)  # the waiter is asleep in the condition
    set_at = time.monotonic()
    event._set = True  # private: the flag as a handler leaves it when its notify found no one
    waiter.join(timeout=5.0)
    assert not waiter.is_alive(), "the wait did not see the flag"
    assert seen[0] - set_at <= WAIT_SLICE_S + 0.5
