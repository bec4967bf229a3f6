"""TEC controller: frames by hand, then the driver over a real pty against the simulator."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import pytest

from reach_receiver.clock import ManualClock
from reach_receiver.devices.tec import SerialTecLink, Tec, TecFaults
from reach_receiver.devices.tec_frames import (
    FrameError,
    build_frame,
    build_reply,
    checksum,
    format_fields,
    parse_frame,
    split_requests,
)
from reach_receiver.errors import ConnectionLost, DeviceError, DeviceTimeout, ProtocolError
from reach_receiver.sim.tec import TecSimulator

TAU_S = 600.0
AMBIENT_C = 25.0
MAX_DELTA_K = 20.0

# -- frames -----------------------------------------------------------------------------


def test_checksum_of_status_request_by_hand() -> None:
    # 'j' = 106, '0' = 48, '0' = 48: 106 + 48 + 48 + 1 = 203 = 0xCB
    assert checksum("j00") == 0xCB
    assert build_frame("j") == b"\x01j00CB"


def test_checksum_of_output_drive_set_by_hand() -> None:
    # "m04" + "1;0;": 109 + 48 + 52 + 49 + 59 + 48 + 59 = 424; (424 + 1) & 0xFF = 169 = 0xA9
    assert build_frame("m", "1;0;") == b"\x01m041;0;A9"


def test_checksum_wraps_and_is_upper_case_hex() -> None:
    data = "1;25.000;10.000;0.000;"
    body = "i22" + data
    expected = (sum(body.encode("ascii")) + 1) % 256
    frame = build_frame("i", data)
    assert frame == b"\x01" + body.encode() + f"{expected:02X}".encode()
    assert frame[-2:].upper() == frame[-2:]


def test_fields_are_formatted_with_three_decimals() -> None:
    assert format_fields((1, 25.0, 10, -0.5, "C", True)) == "1;25.000;10;-0.500;C;1;"
    with pytest.raises(ValueError, match="plain ASCII"):
        format_fields(("a;b",))


def test_reply_round_trip_and_lower_case_checksum() -> None:
    reply = build_reply("q", "1;18.500;10.000;0.000;")
    assert reply.endswith(b"\r\n")
    frame = parse_frame(reply)
    assert frame.command == "q"
    assert frame.fields == ("1", "18.500", "10.000", "0.000")
    lower = reply[:-4] + reply[-4:-2].lower() + b"\r\n"
    assert parse_frame(lower).fields == frame.fields


@pytest.mark.parametrize(
    ("frame", "reason"),
    [
        (b"j00CB", "SOH"),
        (b"\x01j00CC", "checksum mismatch"),
        (b"\x01j0", "too short"),
        (b"\x01jx0CB", "two decimal digits"),
        (b"\x01j00ZZ", "not hexadecimal"),
        (b"\x01j0512;", "length field"),
        (b"\x01j\xff0CB", "not ASCII"),
    ],
)
def test_bad_frames_are_rejected(frame: bytes, reason: str) -> None:
    with pytest.raises(FrameError, match=reason):
        parse_frame(frame)


def test_truncated_reply_fails_even_without_length_check() -> None:
    reply = build_reply("j", "25.000;25.000;1;0.000;0;0;1;22.000;1.0;0;0;")
    cut = reply[: len(reply) // 2]
    with pytest.raises(FrameError):
        parse_frame(cut, check_length=False)


def test_split_requests_skips_garbage_and_keeps_partial_frames() -> None:
    first, second = build_frame("j"), build_frame("i", "1;20.000;10.000;0.000;")
    buffer = bytearray(b"noise" + first + second[:7])
    assert split_requests(buffer) == [first]
    assert bytes(buffer) == second[:7]
    buffer += second[7:]
    assert split_requests(buffer) == [second]
    assert buffer == bytearray()


# -- driver against the simulator over a pty --------------------------------------------


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock(start=1.7e9)


@pytest.fixture
def sim(clock: ManualClock) -> Iterator[TecSimulator]:
    simulator = TecSimulator(clock, ambient_c=AMBIENT_C, tau_s=TAU_S, max_delta_k=MAX_DELTA_K)
    simulator.start()
    yield simulator
    simulator.stop()


@pytest.fixture
def tec(sim: TecSimulator, clock: ManualClock) -> Iterator[Tec]:
    link = SerialTecLink(sim.port, timeout_s=0.3)
    driver = Tec(link, clock, retries=2, timeout_s=0.3, settle_s=0.0)
    driver.connect()
    yield driver
    driver.close()


def test_constructor_does_no_io(clock: ManualClock) -> None:
    link = SerialTecLink("/dev/does-not-exist")
    driver = Tec(link, clock)
    assert not link.is_open
    assert driver.link is link


def test_status_fields_at_power_on(tec: Tec) -> None:
    status = tec.status()
    assert status.setpoint == pytest.approx(25.0, abs=1e-9)
    assert status.temperature == pytest.approx(AMBIENT_C, abs=1e-9)
    assert status.controlled is True
    assert status.output_percent == pytest.approx(0.0, abs=1e-9)
    assert status.faults == TecFaults.from_bits(0)
    assert status.faults.active == ()
    assert status.temperature_ok is True
    assert status.supply_v == pytest.approx(22.0, abs=1e-9)
    assert status.version == "1.0"
    assert (status.test_cycles, status.test_mode_completed) == (0, False)


def test_setpoint_is_set_and_read_back(tec: Tec, sim: TecSimulator) -> None:
    tec.set_setpoint(18.25)
    assert tec.setpoint() == pytest.approx(18.25, abs=1e-9)
    assert tec.get_parameters("q") == ("1", "18.250", "10.000", "0.000")
    assert sim.received.count("i") == 1


def test_lost_set_is_resent_until_read_back_agrees(tec: Tec, sim: TecSimulator) -> None:
    sim.ignore_next_sets(1)
    tec.set_setpoint(19.0)
    assert tec.setpoint() == pytest.approx(19.0, abs=1e-9)
    assert sim.received.count("i") == 2


def test_persistently_lost_set_raises_naming_the_command(tec: Tec, sim: TecSimulator) -> None:
    sim.ignore_next_sets(3)
    with pytest.raises(DeviceError, match="command 'i'") as info:
        tec.set_setpoint(19.0)
    assert info.value.command == "i"
    assert sim.received.count("i") == 3


def test_temperature_relaxes_with_time_constant(
    tec: Tec, sim: TecSimulator, clock: ManualClock
) -> None:
    tec.set_setpoint(15.0)
    t0, temp0 = clock.now(), tec.status().temperature
    for target_elapsed in (60.0, 600.0, 1800.0):
        clock.advance(t0 + target_elapsed - clock.now())
        expected = 15.0 + (temp0 - 15.0) * math.exp(-target_elapsed / TAU_S)
        status = tec.status()
        assert status.temperature == pytest.approx(expected, abs=6e-4)  # 3 decimals on the wire
        assert status.output_percent == pytest.approx(-50.0, abs=1e-6)  # (15-25)/20
    assert sim.temperature_c() == pytest.approx(expected, abs=1e-9)


def test_output_saturates_and_plate_stops_at_reachable_limit(tec: Tec, clock: ManualClock) -> None:
    tec.set_setpoint(0.0)  # 25 K below ambient; the module holds at most 20 K
    clock.advance(20 * TAU_S)
    status = tec.status()
    assert status.output_percent == pytest.approx(-100.0, abs=1e-6)
    assert status.temperature == pytest.approx(AMBIENT_C - MAX_DELTA_K, abs=1e-3)
    assert status.temperature_ok is False


def test_disable_lets_plate_drift_to_ambient_and_enable_restores_pid(
    tec: Tec, clock: ManualClock
) -> None:
    tec.set_setpoint(20.0)
    clock.advance(10 * TAU_S)
    assert tec.status().temperature == pytest.approx(20.0, abs=1e-3)
    tec.enable(False)
    status = tec.status()
    assert status.controlled is False
    assert status.output_percent == pytest.approx(0.0, abs=1e-9)
    assert tec.get_parameters("b")[0] == "0"
    clock.advance(TAU_S)
    expected = AMBIENT_C + (20.0 - AMBIENT_C) * math.exp(-1.0)
    assert tec.status().temperature == pytest.approx(expected, abs=2e-3)
    tec.enable(True)
    control = tec.get_parameters("b")
    assert control == ("4", "10.000", "60.000", "0.000", "0.500", "0.200", "2")
    assert tec.status().controlled is True


def test_wait_until_stable_returns_after_the_hold(tec: Tec, clock: ManualClock) -> None:
    tec.set_setpoint(20.0)
    t0 = clock.now()
    status = tec.wait_until_stable(tolerance_c=0.1, hold_s=300.0, timeout_s=1e4, poll_s=10.0)
    elapsed = clock.now() - t0
    # within 0.1 K of 20 after tau ln(5 / 0.1) = 2347 s, then held 300 s; polls every 10 s
    reach = TAU_S * math.log(5.0 / 0.1)
    assert reach + 300.0 - 1e-6 <= elapsed <= reach + 300.0 + 10.0 + 1e-6
    assert abs(status.temperature - 20.0) <= 0.1


def test_wait_until_stable_times_out_when_setpoint_unreachable(
    tec: Tec, clock: ManualClock
) -> None:
    tec.set_setpoint(0.0)
    t0 = clock.now()
    with pytest.raises(DeviceTimeout, match="not stable"):
        tec.wait_until_stable(tolerance_c=0.5, hold_s=60.0, timeout_s=3600.0, poll_s=30.0)
    assert clock.now() - t0 == pytest.approx(3600.0, abs=1e-6)


def test_wait_until_stable_raises_at_once_on_a_fault(
    tec: Tec, sim: TecSimulator, clock: ManualClock
) -> None:
    sim.set_fault_bits(1 << 4)
    t0 = clock.now()
    with pytest.raises(DeviceError, match="inhibited"):
        tec.wait_until_stable(tolerance_c=0.1, hold_s=60.0, timeout_s=3600.0)
    assert clock.now() == t0


def test_fault_bits_are_decoded(tec: Tec, sim: TecSimulator) -> None:
    sim.set_fault_bits(0b01000 | 0b00001 | 1 << 6)
    faults = tec.status().faults
    assert (faults.adc, faults.adcr, faults.vdc_limit) == (True, False, False)
    assert (faults.temperature_limit, faults.inhibited) == (True, False)
    assert faults.active == ("adc", "temperature_limit", "bit6")


def test_temperature_outside_alarm_limits_sets_the_limit_bit(tec: Tec, clock: ManualClock) -> None:
    tec.set_parameters("c", (0, -40.0, 85.0, 0.5, 0.5, 10.0, 30.0))
    tec.set_setpoint(5.0)
    clock.advance(10 * TAU_S)
    assert tec.status().faults.temperature_limit is True


def test_stuck_temperature_reading(tec: Tec, sim: TecSimulator, clock: ManualClock) -> None:
    sim.stick_temperature(True)
    tec.set_setpoint(15.0)
    clock.advance(TAU_S)
    assert tec.status().temperature == pytest.approx(AMBIENT_C, abs=1e-9)
    assert sim.temperature_c() < AMBIENT_C - 5.0


@pytest.mark.parametrize("fault", ["corrupt", "garble", "truncate", "drop"])
def test_single_bad_reply_is_retried(tec: Tec, sim: TecSimulator, fault: str) -> None:
    getattr(sim, f"{fault}_next_replies")(1)
    status = tec.status()
    assert status.temperature == pytest.approx(AMBIENT_C, abs=1e-9)
    assert sim.received.count("j") == 3  # connect, failed attempt, retry


@pytest.mark.parametrize("fault", ["corrupt", "garble", "truncate"])
def test_persistently_bad_replies_raise_protocol_error(
    tec: Tec, sim: TecSimulator, fault: str
) -> None:
    getattr(sim, f"{fault}_next_replies")(3)
    with pytest.raises(ProtocolError, match="command 'j'") as info:
        tec.status()
    assert not isinstance(info.value, DeviceTimeout)
    assert info.value.command == "j"


def test_no_reply_raises_device_timeout_after_retries(tec: Tec, sim: TecSimulator) -> None:
    sim.drop_next_replies(3)
    started = time.monotonic()
    with pytest.raises(DeviceTimeout, match="no reply after 3 attempts"):
        tec.setpoint()
    assert 0.85 <= time.monotonic() - started <= 3.0  # 3 attempts of 0.3 s
    assert tec.setpoint() == pytest.approx(25.0, abs=1e-9)


def test_garbled_values_are_never_returned(tec: Tec, sim: TecSimulator, clock: ManualClock) -> None:
    tec.set_setpoint(12.0)
    clock.advance(123.0)
    truth = sim.temperature_c()
    for _ in range(5):
        sim.garble_next_replies(2)
        assert tec.status().temperature == pytest.approx(truth, abs=6e-4)


def test_connect_fails_cleanly_when_controller_is_silent(
    sim: TecSimulator, clock: ManualClock
) -> None:
    sim.drop_next_replies(10)
    link = SerialTecLink(sim.port, timeout_s=0.05)
    driver = Tec(link, clock, retries=0, timeout_s=0.05)
    with pytest.raises(DeviceTimeout):
        driver.connect()
    assert not link.is_open


def test_link_can_be_closed_and_reopened(tec: Tec, sim: TecSimulator) -> None:
    tec.close()
    tec.connect()
    assert tec.status().temperature == pytest.approx(AMBIENT_C, abs=1e-9)


def test_simulator_stopping_under_an_open_port_is_a_lost_connection(
    sim: TecSimulator, clock: ManualClock
) -> None:
    link = SerialTecLink(sim.port, timeout_s=0.3)
    driver = Tec(link, clock, retries=0, timeout_s=0.3)
    driver.connect()
    sim.stop()
    try:
        with pytest.raises((ConnectionLost, DeviceTimeout)):
            driver.status()
    finally:
        driver.close()
    assert not link.is_open
