"""TC-08 driver against the libusbtc08 stand-in; loader and USB discovery on this host."""

from __future__ import annotations

import ctypes
import math
import threading
import time
from collections.abc import Iterator, Sequence

import numpy as np
import pytest

from reach_receiver.clock import ManualClock, SystemClock
from reach_receiver.devices.tc08 import DEFAULT_PORTS, Tc08
from reach_receiver.errors import ConfigError, DeviceError, DeviceTimeout
from reach_receiver.sim.tc08 import SimulatedTc08Library
from reach_receiver.transports.tc08_library import (
    USBTC08_UNITS_CENTIGRADE,
    USBTC08_UNITS_KELVIN,
    find_tc08_devices,
    load_libusbtc08,
    reset_tc08,
)

T0 = 1.7e9
NOISE_K = 0.05


def truth(t: float) -> Sequence[float]:
    """Cold junction at 22 C; channel n at 24 + n C, all warming 1 mK/s."""
    drift = 1e-3 * (t - T0)
    return [22.0 + drift] + [24.0 + n + drift for n in range(1, 9)]


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock(start=T0)


@pytest.fixture
def lib(clock: ManualClock) -> SimulatedTc08Library:
    return SimulatedTc08Library(truth, clock, noise_k=NOISE_K, seed=1234)


@pytest.fixture
def tc08(lib: SimulatedTc08Library, clock: ManualClock) -> Iterator[Tc08]:
    driver = Tc08(lib, clock, timeout_s=2.0)
    driver.connect()
    yield driver
    driver.close()


def worker_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("tc08")]


def test_constructor_does_no_io(lib: SimulatedTc08Library, clock: ManualClock) -> None:
    Tc08(lib, clock)
    assert lib.calls == []
    assert worker_threads() == []


def test_connect_sets_mains_filter_and_all_channels(tc08: Tc08, lib: SimulatedTc08Library) -> None:
    (handle,) = lib.open_handles
    assert lib.sixty_hertz(handle) == 0
    assert lib.channel_types(handle) == {ch: "K" for ch in range(9)}
    assert tc08.serial == "A0042/123"
    assert tc08.enabled_channels == tuple(range(9))


def test_sixty_hertz_mains_and_disabled_channel(
    lib: SimulatedTc08Library, clock: ManualClock
) -> None:
    channels = {ch: "K" for ch in range(1, 8)} | {8: " "}
    with Tc08(lib, clock, channels=channels, mains_hz=60) as driver:
        (handle,) = lib.open_handles
        assert lib.sixty_hertz(handle) == 1
        reading = driver.read()
    assert sorted(reading.temperatures_c) == list(range(8))
    assert lib.open_handles == ()
    assert worker_threads() == []


@pytest.mark.parametrize(
    "kwargs",
    [{"mains_hz": 55}, {"channels": {9: "K"}}, {"channels": {1: "Q"}}, {"period_s": 0.0}],
)
def test_invalid_configuration_is_rejected(
    lib: SimulatedTc08Library, clock: ManualClock, kwargs: dict[str, object]
) -> None:
    with pytest.raises(ConfigError):
        Tc08(lib, clock, **kwargs)  # type: ignore[arg-type]


def test_reading_values_units_and_timestamp(tc08: Tc08, clock: ManualClock) -> None:
    clock.advance(100.0)
    start = clock.now()
    reading = tc08.read()
    assert reading.timestamp == start
    assert reading.units == "degC"
    assert reading.flags == {}
    expected = truth(start)
    assert set(reading.temperatures_c) == set(range(9))
    for channel, value in reading.temperatures_c.items():
        assert abs(value - expected[channel]) < 5 * NOISE_K
    # nine conversions of 0.1 s each
    assert clock.now() - start == pytest.approx(0.9, abs=1e-6)  # float64 at 1.7e9 s


def test_noise_is_thermocouple_like(tc08: Tc08, clock: ManualClock) -> None:
    residuals = []
    for _ in range(200):
        reading = tc08.read()
        expected = truth(reading.timestamp)
        residuals += [reading.temperatures_c[ch] - expected[ch] for ch in range(9)]
    spread = float(np.std(residuals))
    assert 0.8 * NOISE_K < spread < 1.2 * NOISE_K
    assert abs(float(np.mean(residuals))) < 0.01


def test_log_keeps_the_period_on_the_clock(tc08: Tc08, clock: ManualClock) -> None:
    start = clock.now()
    readings = tc08.log(6, period_s=10.0)
    stamps = np.array([r.timestamp for r in readings])
    np.testing.assert_allclose(stamps - start, 10.0 * np.arange(6), rtol=0, atol=1e-6)
    default = tc08.log(2)
    assert default[1].timestamp - default[0].timestamp == pytest.approx(10.0, abs=1e-6)


def test_log_faster_than_conversion_runs_back_to_back(tc08: Tc08) -> None:
    readings = tc08.log(4, period_s=0.5)
    gaps = np.diff([r.timestamp for r in readings])
    np.testing.assert_allclose(gaps, 0.9, rtol=0, atol=1e-6)


def test_overflow_is_flagged_and_not_used(tc08: Tc08, lib: SimulatedTc08Library) -> None:
    lib.set_overflow(3)
    reading = tc08.read()
    assert reading.overflow_bits == 1 << 3
    assert reading.flags == {3: ("overflow",)}
    assert math.isnan(reading.temperatures_c[3])
    assert math.isfinite(reading.raw_c[3])
    assert 3 not in reading.good()
    assert "MS3 switch" not in tc08.components(reading)


def test_nan_is_flagged(tc08: Tc08, lib: SimulatedTc08Library) -> None:
    lib.set_nan(5)
    reading = tc08.read()
    assert reading.flags == {5: ("nan",)}
    assert reading.flagged == frozenset({5})
    assert set(reading.good()) == set(range(9)) - {5}


def test_stuck_readings_are_detected(tc08: Tc08, lib: SimulatedTc08Library) -> None:
    assert tc08.stuck_reads == 5
    tc08.read()
    lib.stick()
    for _ in range(3):  # 4 identical values so far: not yet stuck
        assert tc08.read().flags == {}
    stuck = tc08.read()
    assert stuck.flags == {ch: ("stuck",) for ch in range(9)}
    assert all(math.isnan(v) for v in stuck.temperatures_c.values())
    lib.stick(False)
    assert tc08.read().flags == {}


def test_jittering_channels_are_never_called_stuck(tc08: Tc08) -> None:
    assert all(not tc08.read().flags for _ in range(300))


def test_get_single_failure_names_the_error(tc08: Tc08, lib: SimulatedTc08Library) -> None:
    lib.fail_get_single(1)
    with pytest.raises(DeviceError, match="USBTC08_ERROR_NOT_RESPONDING") as info:
        tc08.read()
    assert info.value.command == "usb_tc08_get_single"
    assert tc08.read().flags == {}


def test_no_unit_found(lib: SimulatedTc08Library, clock: ManualClock) -> None:
    lib.fail_open(result=0)
    driver = Tc08(lib, clock)
    with pytest.raises(DeviceError, match="no TC-08 found"):
        driver.connect()
    assert worker_threads() == []


def test_open_error_is_translated(lib: SimulatedTc08Library, clock: ManualClock) -> None:
    lib.fail_open(result=-1, error=9)
    with pytest.raises(DeviceError, match="USBTC08_ERROR_CONFIG_FAIL") as info:
        Tc08(lib, clock).connect()
    assert info.value.command == "usb_tc08_open_unit"
    assert worker_threads() == []


def test_hung_conversion_times_out(lib: SimulatedTc08Library, clock: ManualClock) -> None:
    driver = Tc08(lib, clock, timeout_s=0.2)
    driver.connect()
    lib.hang_get_single()
    started = time.monotonic()
    try:
        with pytest.raises(DeviceTimeout, match=r"no return within 0\.2 s"):
            driver.read()
        assert time.monotonic() - started < 1.5
        with pytest.raises(DeviceError, match="reconnect"):
            driver.read()
    finally:
        lib.release()
        driver.close()
    for thread in worker_threads():
        thread.join(timeout=2.0)
    assert worker_threads() == []


def test_read_before_connect_is_an_error(lib: SimulatedTc08Library, clock: ManualClock) -> None:
    with pytest.raises(DeviceError, match="not connected"):
        Tc08(lib, clock).read()


def test_ports_default_to_thesis_table_and_can_be_overridden(
    lib: SimulatedTc08Library, clock: ManualClock
) -> None:
    assert DEFAULT_PORTS[0] == "cold junction"
    assert DEFAULT_PORTS[2] == "heated load thermistor"
    assert DEFAULT_PORTS[8] == "antenna (laboratory)"
    with Tc08(lib, clock, ports={8: "hexagonal dipole"}) as driver:
        names = driver.components(driver.read())
    assert set(names) == (set(DEFAULT_PORTS.values()) - {"antenna (laboratory)"}) | {
        "hexagonal dipole"
    }
    assert names["low noise amplifier"] == pytest.approx(31.0, abs=5 * NOISE_K)


def test_stand_in_follows_the_c_calling_convention(lib: SimulatedTc08Library) -> None:
    handle = lib.usb_tc08_open_unit()
    assert handle > 0
    temp = (ctypes.c_float * 9)()
    flags = (ctypes.c_int16 * 1)()
    assert lib.usb_tc08_get_single(handle, temp, flags, USBTC08_UNITS_CENTIGRADE) == 0
    assert lib.usb_tc08_get_last_error(handle) == 2  # NO_CHANNELS_SET
    assert lib.usb_tc08_set_channel(handle, 1, ord("K")) == 1
    assert lib.usb_tc08_set_channel(handle, 1, ord("Q")) == 0
    assert lib.usb_tc08_get_last_error(handle) == 3  # INVALID_PARAMETER
    assert lib.usb_tc08_get_single(handle, temp, flags, USBTC08_UNITS_KELVIN) == 1
    assert temp[1] == pytest.approx(25.0 + 273.15, abs=5 * NOISE_K)
    assert math.isnan(temp[2])  # not enabled
    assert lib.usb_tc08_close_unit(handle) == 1
    assert lib.usb_tc08_close_unit(handle) == 0


def test_loader_explains_a_missing_library() -> None:
    with pytest.raises(DeviceError, match=r"libusbtc08.*Pico") as info:
        load_libusbtc08()
    assert info.value.command == "load"
    with pytest.raises(DeviceError, match=r"/nonexistent/libusbtc08\.so"):
        load_libusbtc08("/nonexistent/libusbtc08.so")


def test_usb_discovery_and_reset_are_safe_without_a_device() -> None:
    devices = find_tc08_devices()
    assert isinstance(devices, list)
    with pytest.raises(DeviceError) as info:
        reset_tc08(255, 127)
    assert info.value.command == "reset 255:127"


@pytest.mark.skipif(not find_tc08_devices(), reason="no Pico TC-08 (0ce9:1000) on the USB")
def test_real_tc08_reads_the_cold_junction() -> None:
    with Tc08(load_libusbtc08(), SystemClock(), timeout_s=10.0) as driver:
        reading = driver.read()
    assert 0.0 < reading.temperatures_c[0] < 60.0
