"""The Teensy driver against the real firmware logic (host build on a pty), faults included."""

import time

import pytest
import serial

from reach_receiver.clock import ManualClock
from reach_receiver.devices.tec import Tec
from reach_receiver.devices.tec_via_teensy import TeensyTecLink
from reach_receiver.devices.teensy import Teensy
from reach_receiver.errors import ConnectionLost, DeviceTimeout, InterlockError, ProtocolError
from reach_receiver.frontend.paths import FrontEnd
from reach_receiver.sim.faulty_link import FaultyLink, LinkFault
from reach_receiver.sim.tec import TecSimulator
from reach_receiver.sim.teensy_firmware import FirmwareTeensy


@pytest.fixture
def tec_sim():
    sim = TecSimulator(ManualClock(), ambient_c=25.0)
    sim.start()
    yield sim
    sim.stop()


@pytest.fixture
def board(tec_sim):
    with FirmwareTeensy(uart1=tec_sim.port) as firmware:
        yield firmware


@pytest.fixture
def teensy(board):
    with Teensy(board.port, timeout_s=0.5) as driver:
        yield driver


@pytest.fixture
def link(board):
    with FaultyLink(board.port) as faulty:
        yield faulty


def test_identity_and_power_on_state(teensy):
    assert teensy.identity.startswith("REACH front-end")
    state = teensy.read_state()
    assert state.boot == "por"
    assert not any(state.rails.values())
    assert state.switches == {"ms1": 0, "ms2": 0, "ms3": 0, "ms4": 0, "mts": "lna"}


def test_frontend_connect_sets_the_pins_the_simulator_sees(teensy, board):
    state = FrontEnd(teensy).connect("c2r69", "vna")
    assert state.switches["ms1"] == 7
    assert state.switches["ms3"] == 3
    assert state.switches["mts"] == "vna"
    # PINS lines lag the replies, one per change: wait for the line that counts them all.
    pins = board.wait_for_state(
        lambda s: s.get("changes") == str(state.changes), timeout_s=2.0
    )
    assert (pins["ms1"], pins["ms2"], pins["ms3"], pins["mts"]) == ("7", "1", "3", "vna")


def test_interlocks_refused_by_the_board_change_nothing(teensy):
    before = teensy.read_state()
    with pytest.raises(InterlockError, match="needs rail 12v"):
        teensy.select("ms1", 4)
    teensy.set_rail("12v", True)
    teensy.select("ms1", 4)
    with pytest.raises(InterlockError, match="drives"):
        teensy.set_rail("12v", False)
    assert teensy.read_state().switches["ms1"] == 4
    assert before.switches["ms1"] == 0


def test_fixed_rails_refused_before_anything_is_sent(teensy, board):
    with pytest.raises(InterlockError, match="never switched"):
        teensy.set_rail("5v", False)


def test_safe_state_keeps_thermal_control(teensy):
    frontend = FrontEnd(teensy)
    frontend.connect("ns", "lna")
    teensy.set_rail("fan", True)
    teensy.set_rail("tec", True)
    state = frontend.safe()
    assert not state.rails["ns"]
    assert not state.rails["6v"]
    assert state.switches["ms1"] == 0
    assert state.rails["fan"]
    assert state.rails["tec"]


def test_i2c_temperatures(teensy, board):
    board.set_sensor(0x18, 24.5)
    board.set_sensor(0x1A, -3.25)
    assert teensy.temperatures() == {0x18: pytest.approx(24.5, abs=0.07), 0x1A: -3.25}


def test_a_second_driver_on_the_same_port_is_refused(teensy, board):
    with pytest.raises(ConnectionLost, match="cannot open serial port"):
        Teensy(board.port, timeout_s=0.5).connect()
    assert teensy.command("ping") == "pong"  # the first driver's line is untouched
    teensy.close()
    with Teensy(board.port, timeout_s=0.5) as second:
        assert second.command("ping") == "pong"


def test_replies_to_another_program_on_the_line_are_not_taken_for_ours(teensy, board):
    # A program that ignores the port's lock asks for the temperatures (tags 1-64) before
    # any sensor answers and leaves the replies unread: they wait in the line's one input
    # queue, numbered as a driver that counts from 1 numbers its own requests.
    with serial.Serial(board.port, timeout=0.05) as intruder:
        intruder.write(b"".join(b"#%x temps\n" % tag for tag in range(1, 65)))
        intruder.flush()
        time.sleep(0.3)
    board.set_sensor(0x18, 24.5)
    assert teensy.temperatures() == {0x18: pytest.approx(24.5, abs=0.07)}


@pytest.mark.parametrize("fault", [LinkFault.GARBLE, LinkFault.TRUNCATE, LinkFault.DROP])
def test_a_damaged_reply_is_retried_after_resync(link, fault):
    with Teensy(link.port, timeout_s=0.3) as teensy:
        link.inject(fault)
        teensy.set_rail("24v", True)  # idempotent: repeating it is safe
        assert teensy.rail("24v") is True


def test_a_late_answer_to_the_resync_line_is_dropped_not_taken_for_garbage(link):
    """The board answers resync's lone LF with an untagged ``ERR 06``; under load that
    answer can come after the driver stopped waiting for quiet, ahead of the pong."""
    with Teensy(link.port, timeout_s=0.5) as teensy:
        link.inject(LinkFault.DELAY)
        teensy.resync()
        teensy.set_rail("24v", True)
        assert teensy.rail("24v") is True


def test_persistent_damage_is_reported_not_guessed(link):
    with Teensy(link.port, timeout_s=0.2, retries=1) as teensy:
        link.inject(LinkFault.GARBLE, count=10)
        with pytest.raises((ProtocolError, DeviceTimeout), match="teensy"):
            teensy.read_state()


def test_hung_board_times_out_then_recovers_in_power_on_state(teensy, board):
    teensy.set_rail("12v", True)
    board.hang()
    teensy.retries = 0
    with pytest.raises(DeviceTimeout, match="teensy"):
        teensy.read_state()
    teensy.retries = 3
    teensy.timeout_s = 1.0
    state = teensy.read_state()  # the watchdog reset the board meanwhile
    assert state.boot == "wdog"
    assert not state.rails["12v"]


def test_tec_through_the_teensy_passthrough_retries_a_bad_checksum(teensy, tec_sim):
    teensy.set_rail("tec", True)
    with Tec(TeensyTecLink(teensy), ManualClock()) as tec:
        tec_sim.corrupt_next_replies(1)
        tec.set_setpoint(21.5)
        assert tec.setpoint() == pytest.approx(21.5)


def test_tec_passthrough_needs_the_tec_rail(teensy):
    from reach_receiver.devices.teensy import TeensyError

    with pytest.raises(TeensyError, match="tec rail is off"):
        teensy.tec_query(b"\x01j0000")
