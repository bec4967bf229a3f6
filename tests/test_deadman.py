"""The firmware's dead-man switch through the driver, against the firmware's host build.

The simulator runs the dead-man on the host's real clock, so these tests really fall
silent for a second (``SILENCE_S``) with a 300 ms timeout armed.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator

import pytest

from reach_receiver.config.site import replace_devices
from reach_receiver.devices.board import FrontEndState
from reach_receiver.devices.teensy import FrontEndTripped, Teensy
from reach_receiver.errors import DeviceError, ReceiverError
from reach_receiver.run.instruments import Instruments
from reach_receiver.sim.receiver import SimulatedReceiver
from reach_receiver.sim.teensy_firmware import FirmwareTeensy

TIMEOUT_S = 0.3
SILENCE_S = 1.0  # over three timeouts: a trip is certain, a keep-alive has time to act
WAIT_S = 5.0  # longest wait for something that should happen at once (a loaded machine)


@pytest.fixture
def board() -> Iterator[FirmwareTeensy]:
    with FirmwareTeensy() as firmware:
        yield firmware


@pytest.fixture
def teensy(board: FirmwareTeensy) -> Iterator[Teensy]:
    with Teensy(board.port, timeout_s=0.5) as driver:
        yield driver


def busy(teensy: Teensy) -> FrontEndState:
    """Rails on (the fan too) and two switches over; the state read back."""
    for rail in ("24v", "fan", "12v", "6v", "ns"):
        teensy.set_rail(rail, True)
    teensy.select("ms1", 4)
    teensy.select("mts", "vna")
    return teensy.read_state()


def test_frontend_tripped_fails_runs_safe() -> None:
    assert issubclass(FrontEndTripped, DeviceError)
    assert issubclass(FrontEndTripped, ReceiverError)


def test_silence_trips_the_board_into_its_safe_state(teensy: Teensy, board: FirmwareTeensy):
    before = busy(teensy)
    teensy.arm_deadman(TIMEOUT_S)
    assert teensy.read_state().deadman_ms == 300
    # The board goes safe on its own: the simulator reports it with nobody asking. The trip's
    # PINS line is the first to count more changes than the host made; an older line, still
    # unread, can also show 12v=0.
    pins = board.wait_for_state(
        lambda s: int(s.get("changes", "0")) > before.changes, timeout_s=WAIT_S
    )
    assert pins["12v"] == "0"
    assert pins["ms1"] == "0"
    with pytest.raises(FrontEndTripped, match=r"safe state on its own.*after 300 ms") as tripped:
        teensy.select("ms1", 2)  # not run
    assert tripped.value.code == 50
    after = teensy.read_state()  # told once: the board answers again
    assert after.is_safe
    assert after.rails["fan"]  # the enclosure stays controlled
    assert after.rails["24v"]
    assert after.switches["ms1"] == 0
    assert after.deadman_ms == 0  # disarmed by the trip
    assert after.boot == before.boot
    assert after.uptime_ms > before.uptime_ms
    assert after.changes == before.changes + 5  # ns, ms1, mts, 6v, 12v
    assert after.change_since(before) is not None
    assert not after.same_outputs_as(before)
    teensy.set_rail("12v", True)  # the host is back in charge
    teensy.select("ms1", 2)
    assert teensy.read_state().switches["ms1"] == 2


def test_any_request_renews_it(teensy: Teensy) -> None:
    before = busy(teensy)
    teensy.arm_deadman(TIMEOUT_S)
    deadline = time.monotonic() + SILENCE_S
    while time.monotonic() < deadline:
        time.sleep(TIMEOUT_S / 6)
        teensy.rail("12v")
    after = teensy.read_state()
    assert after.same_outputs_as(before)
    assert after.change_since(before) is None
    assert after.deadman_ms == 300


def test_keepalive_holds_it_over_the_same_silence(teensy: Teensy) -> None:
    before = busy(teensy)
    teensy.arm_deadman(TIMEOUT_S)
    teensy.start_keepalive(TIMEOUT_S / 6)
    time.sleep(SILENCE_S)
    teensy.stop_keepalive()
    after = teensy.read_state()
    assert after.unchanged_since(before)
    assert after.deadman_ms == 300
    assert teensy.keepalive_failures == 0
    teensy.disarm_deadman()
    time.sleep(SILENCE_S)
    assert teensy.read_state().unchanged_since(before)


def test_deadman_zero_never_trips(teensy: Teensy) -> None:
    before = busy(teensy)
    teensy.arm_deadman(TIMEOUT_S)
    teensy.arm_deadman(0)
    time.sleep(SILENCE_S)
    after = teensy.read_state()
    assert after.unchanged_since(before)
    assert after.deadman_ms == 0


def test_a_trip_seen_by_the_keepalive_reaches_the_run(teensy: Teensy, caplog):
    busy(teensy)
    teensy.arm_deadman(TIMEOUT_S)
    time.sleep(SILENCE_S)  # the host is gone...
    with caplog.at_level(logging.ERROR, logger="reach_receiver.devices.teensy"):
        teensy.start_keepalive(0.05)  # ...and back: its keep-alive talks first
        time.sleep(0.3)
        teensy.stop_keepalive()
    assert "safe state on its own" in caplog.text
    with pytest.raises(FrontEndTripped, match="reported to the keep-alive"):
        teensy.read_state()
    state = teensy.read_state()
    assert state.is_safe
    assert state.deadman_ms == 300  # the keep-alive re-armed it after the report


def test_the_keepalive_rearms_after_a_watchdog_reset(board: FirmwareTeensy) -> None:
    with Teensy(board.port, timeout_s=0.5, retries=3) as teensy:
        teensy.arm_deadman(TIMEOUT_S)
        teensy.start_keepalive(0.05)
        board.hang()  # the simulated watchdog resets the board after 1 s
        board.wait_for_state(lambda s: s.get("boot") == "wdog", timeout_s=WAIT_S)
        time.sleep(0.5)
        teensy.stop_keepalive()
        state = teensy.read_state()
        assert state.boot == "wdog"
        assert state.deadman_ms == 300


def test_driver_is_thread_safe_with_the_keepalive(teensy: Teensy) -> None:
    teensy.set_rail("12v", True)
    teensy.arm_deadman(TIMEOUT_S)
    teensy.start_keepalive(0.001)  # as often as it can: every exchange interleaves
    errors: list[BaseException] = []

    def hammer(position: int) -> None:
        try:
            for _ in range(30):
                teensy.select("ms4", position)
                assert teensy.read_state().switches["ms4"] in (1, 2)
        except BaseException as err:  # reported below
            errors.append(err)

    threads = [threading.Thread(target=hammer, args=(p,)) for p in (1, 2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(30)
    teensy.stop_keepalive()
    assert not errors
    assert teensy.keepalive_failures == 0


def test_arming_checks_its_range_before_sending(teensy: Teensy) -> None:
    for bad in (0.05, 3600.5, -1.0):
        with pytest.raises(ValueError, match="dead-man timeout"):
            teensy.arm_deadman(bad)
    with pytest.raises(ValueError, match="positive"):
        teensy.start_keepalive(0.0)
    assert teensy.read_state().deadman_ms == 0


def test_a_trip_before_connecting_is_logged_not_raised(board: FirmwareTeensy, caplog) -> None:
    with Teensy(board.port, timeout_s=0.5) as first:
        first.arm_deadman(TIMEOUT_S)
    time.sleep(SILENCE_S)  # closed without disarming: the board goes safe
    with caplog.at_level(logging.WARNING), Teensy(board.port, timeout_s=0.5) as second:
        assert second.read_state().deadman_ms == 0
    assert "on connecting" in caplog.text


def test_the_run_layer_arms_it_keeps_it_alive_and_disarms_it() -> None:
    with SimulatedReceiver() as sim:
        # A keep-alive every 0.2 s renews a 0.6 s timeout.
        site = replace_devices(sim.site(), teensy={"deadman_s": 0.6})
        instruments = Instruments.from_site(site, sim.clock)
        instruments.connect()
        try:
            before = instruments.frontend.connect("cold", "lna")
            assert before.deadman_ms == 600
            time.sleep(1.5)  # the run integrates; only the keep-alive talks
            assert instruments.teensy.read_state().unchanged_since(before)
        finally:
            instruments.close()
        with Teensy(sim.site().devices.teensy.port) as teensy:
            state = teensy.read_state()
        assert state.deadman_ms == 0  # disarmed on closing: the path stays as left
        assert state.switches["ms1"] != 0
