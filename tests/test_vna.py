"""VNA driver against the simulated TR1300/1, over real TCP through pyvisa-py."""

from __future__ import annotations

import logging
import time

import numpy as np
import pytest

from calibration.rf.cal_kit import CalKit, OpenStandard
from reach_receiver.clock import ManualClock
from reach_receiver.devices.vna import S11Measurement, ScpiErrorEntry, SweepSettings, Vna
from reach_receiver.devices.vna_host_cal import (
    HostCalibration,
    calibrate_on_host,
    measure_raw,
)
from reach_receiver.errors import (
    ConfigError,
    ConnectionLost,
    DeviceError,
    DeviceTimeout,
    ProtocolError,
)
from reach_receiver.sim.vna import Fault, VnaSimulator, solve_one_port

SETTINGS = SweepSettings(40e6, 180e6, points=201, ifbw_hz=100.0, power_dbm=-5.0, averages=20)
IDEAL = np.array([-1.0, 1.0, 0.0], dtype=complex)
SDAT = "CALC1:TRAC1:DATA:SDAT?"


def dut(freq):
    """A smooth known reflection: a 0.3 mismatch behind 5 ns of line, tilted in band."""
    x = (freq - 110e6) / 70e6
    return 0.3 * (1 + 0.2 * x) * np.exp(-2j * np.pi * freq * 5e-9)


def reference_load(freq):
    """The -40 dB test load whose 'PNA-X' reference is its truth."""
    return 0.01 * np.exp(-2j * np.pi * freq * 1e-9)


class Port:
    """What MS2 connects to the VNA port: the test's stand-in for the front-end."""

    def __init__(self):
        self.connected = "dut"
        self.known = {
            "short": lambda f: -np.ones_like(f, dtype=complex),
            "open": lambda f: np.ones_like(f, dtype=complex),
            "load": lambda f: np.zeros_like(f, dtype=complex),
            "dut": dut,
            "test_load": reference_load,
        }

    def __call__(self, freq):
        return self.known[self.connected](freq)

    def connect(self, name):
        self.connected = name


@pytest.fixture
def clock():
    return ManualClock()


@pytest.fixture
def port():
    return Port()


def make_sim(port, clock, **kwargs):
    kwargs.setdefault("drift_rate_per_s", 0.0)
    return VnaSimulator(port, clock, seed=3, **kwargs)


def make_vna(sim, clock):
    return Vna(
        sim.address,
        timeout_s=0.2,
        clock=clock,
        opc_margin_s=0.5,
        error_query_timeout_s=0.2,
        cal_kit=23,
    )


@pytest.fixture
def sim(port, clock):
    simulator = make_sim(port, clock)
    simulator.start()
    yield simulator
    simulator.close()


@pytest.fixture
def vna(sim, clock):
    driver = make_vna(sim, clock)
    driver.connect()
    driver.configure(SETTINGS)
    yield driver
    driver.close()


def predicted_sigma(sim, clock, settings, truth):
    """Per-point complex rms of corrected S11 from the noise model, by linear propagation.

    Corrected G depends on the DUT reading and the three standards' readings, each with
    complex rms sigma; G is holomorphic in each, so |dG/dm| from one complex step.
    """
    freq = settings.frequencies()
    sigma = sim.noise_sigma(settings.ifbw_hz, settings.power_dbm, settings.averages)
    e00, e11, tracking = sim.model.terms(freq, clock.now())

    def reading(g):
        return e00 + tracking * g / (1 - e11 * g)

    def corrected(stds, m):
        c00, c11, ctr = solve_one_port(stds, IDEAL)
        return (m - c00) / (ctr + c11 * (m - c00))

    stds = np.stack([reading(g * np.ones_like(freq)) for g in IDEAL])
    m = reading(truth)
    base = corrected(stds, m)
    step = 1e-7
    total = np.abs((corrected(stds, m + step) - base) / step) ** 2
    for i in range(3):
        moved = stds.copy()
        moved[i] += step
        total += np.abs((corrected(moved, m) - base) / step) ** 2
    return sigma * np.sqrt(total)


def calibrate(vna, port):
    vna.calibrate_sol(port.connect)


def measure(vna, port, name):
    port.connect(name)
    return vna.measure_s11()


# --- settings --------------------------------------------------------------------------


def test_configure_reads_back_every_setting(vna):
    assert vna.read_settings() == SETTINGS
    assert vna.settings == SETTINGS


def test_defaults_are_reach_first_control_code():
    s = SweepSettings()
    assert (s.f_start_hz, s.f_stop_hz, s.ifbw_hz, s.power_dbm, s.averages) == (
        40e6,
        180e6,
        1e3,
        -5.0,
        20,
    )
    assert np.diff(s.frequencies())[0] == pytest.approx(100e3)


@pytest.mark.parametrize(
    "change",
    [
        {"f_start_hz": 1e5},
        {"f_stop_hz": 1.4e9},
        {"f_start_hz": 200e6},
        {"points": 1},
        {"points": 20000},
        {"ifbw_hz": 2000.0},
        {"power_dbm": 5.0},
        {"power_dbm": -5.02},
        {"averages": 0},
    ],
)
def test_out_of_range_settings_rejected(change):
    values = {"f_start_hz": 40e6, "f_stop_hz": 180e6} | change
    with pytest.raises(ConfigError, match="VNA sweep settings"):
        SweepSettings(**values)


def test_rejected_setting_reported_with_error_queue(sim, vna):
    sim.inject(Fault.SCPI_ERROR, on="SOUR1:POW")
    with pytest.raises(DeviceError, match=r"SOUR1:POW set -10.*-222") as info:
        vna.configure(SweepSettings(40e6, 180e6, points=201, ifbw_hz=100.0, power_dbm=-10.0))
    assert info.value.device == "vna"


def test_connect_refuses_an_instrument_that_is_not_a_vna(port, clock):
    with make_sim(port, clock, idn="Keysight Technologies,34465A,MY1,A.03") as other:
        driver = make_vna(other, clock)
        with pytest.raises(DeviceError, match="not a Copper Mountain VNA"):
            driver.connect()
        driver.close()


# --- measurement physics ---------------------------------------------------------------


def test_sweep_waits_for_its_simulated_duration(vna, port, clock):
    start = clock.now()
    result = measure(vna, port, "dut")
    assert isinstance(result, S11Measurement)
    assert clock.now() - start >= SETTINGS.nominal_duration_s()
    assert result.timestamp == pytest.approx(start)
    assert result.idn.startswith("CMT,TR1300/1")
    np.testing.assert_allclose(result.freq_hz, SETTINGS.frequencies(), rtol=0, atol=1e-3)


def test_calibrated_measurement_recovers_truth_within_noise(sim, vna, port, clock):
    calibrate(vna, port)
    result = measure(vna, port, "dut")
    truth = dut(result.freq_hz)
    sigma = predicted_sigma(sim, clock, SETTINGS, truth)
    z = np.abs(result.s11 - truth) / sigma
    assert result.calibrated
    assert vna.errors() == []
    # |err|^2 / sigma^2 is Exp(1) per point: its mean over 201 points is 1 +- 0.07.
    assert 0.7 < np.mean(z**2) < 1.35
    # P(max of 201 Exp(1) > 4.5^2) ~ 3e-7.
    assert np.max(z) < 4.5


def test_uncalibrated_measurement_differs_from_truth(sim, vna, port, clock):
    result = measure(vna, port, "dut")
    truth = dut(result.freq_hz)
    sigma = predicted_sigma(sim, clock, SETTINGS, truth)
    assert not result.calibrated
    assert np.sqrt(np.mean(np.abs(result.s11 - truth) ** 2)) > 100 * np.max(sigma)


def test_wrong_standard_connected_gives_wrong_calibration(sim, vna, port, clock):
    def stuck_switch(name):
        port.connect("open" if name == "load" else name)

    vna.calibrate_sol(stuck_switch)
    result = measure(vna, port, "dut")
    truth = dut(result.freq_hz)
    sigma = predicted_sigma(sim, clock, SETTINGS, truth)
    assert np.all(np.isfinite(result.s11))
    assert np.sqrt(np.mean(np.abs(result.s11 - truth) ** 2)) > 100 * np.max(sigma)


def deviation(result):
    ref = reference_load(result.freq_hz)
    return np.sqrt(np.mean(np.abs(result.s11 - ref) ** 2) / np.mean(np.abs(ref) ** 2))


def test_forced_drift_makes_the_test_load_check_fail(sim, vna, port):
    calibrate(vna, port)
    fresh = deviation(measure(vna, port, "test_load"))
    sim.drift_now(0.2)
    aged = deviation(measure(vna, port, "test_load"))
    assert fresh < 0.05 < aged
    assert aged > 4 * fresh


def test_drift_with_clock_time_ages_the_calibration(port, clock):
    with make_sim(port, clock, drift_rate_per_s=0.01 / 3600) as sim:
        driver = make_vna(sim, clock)
        driver.connect()
        driver.configure(SETTINGS)
        calibrate(driver, port)
        fresh = deviation(measure(driver, port, "test_load"))
        clock.advance(1 * 3600)
        hour = deviation(measure(driver, port, "test_load"))
        clock.advance(24 * 3600)
        day = deviation(measure(driver, port, "test_load"))
        driver.close()
    assert fresh < 0.05 < day
    assert fresh < hour < day


def test_save_calibration_needs_every_standard(vna, port):
    vna.start_sol()
    port.connect("short")
    vna.measure_standard("short")
    with pytest.raises(DeviceError, match="not measured: open, load"):
        vna.save_calibration()
    with pytest.raises(ValueError, match="unknown standard"):
        vna.measure_standard("thru")


# --- state files -----------------------------------------------------------------------


def test_state_saved_and_recalled_with_calibration(vna, port):
    calibrate(vna, port)
    vna.save_state("reach_cal.sta")
    other = SweepSettings(50e6, 200e6, points=101, ifbw_hz=1000.0, power_dbm=-10.0, averages=2)
    vna.configure(other)
    assert not vna.calibration_active()
    assert vna.recall_state("reach_cal.sta") == SETTINGS
    assert vna.calibration_active()
    with pytest.raises(DeviceError, match="-256"):
        vna.recall_state("missing.sta")


# --- error queue -----------------------------------------------------------------------


def test_errors_read_until_no_error(sim, vna):
    sim.queue_error(-100, "Command error")
    sim.queue_error(-222, "Data out of range")
    assert vna.errors() == [
        ScpiErrorEntry(-100, "Command error"),
        ScpiErrorEntry(-222, "Data out of range"),
    ]
    assert vna.errors() == []
    assert vna.error_queue_supported is True


def test_unsupported_error_queue_reported_once_and_never_hangs(port, clock, caplog):
    caplog.set_level(logging.WARNING, logger="reach_receiver.devices.vna_link")
    with make_sim(port, clock, error_queue_supported=False) as sim:
        driver = make_vna(sim, clock)
        driver.connect()
        assert driver.error_queue_supported is False
        started = time.monotonic()
        assert driver.errors() == []
        assert driver.errors() == []
        assert time.monotonic() - started < 0.1
        driver.configure(SETTINGS)
        driver.close()
    reports = [r for r in caplog.records if "error queue unsupported" in r.getMessage()]
    assert len(reports) == 1


# --- faults ----------------------------------------------------------------------------

FAULTS = [
    (Fault.NO_REPLY, DeviceTimeout),
    (Fault.GARBLED, ProtocolError),
    (Fault.TRUNCATED, ProtocolError),
    (Fault.DROP_MID_REPLY, ConnectionLost),
    (Fault.DROP_BEFORE_REPLY, ConnectionLost),
]


def assert_complete_sweep(result, sim, clock):
    """Whole, uncorrupted raw data: within 6 sigma of the noise-free reading everywhere."""
    assert result.s11.shape == (SETTINGS.points,)
    expected = sim.model.measure(result.freq_hz, dut(result.freq_hz), clock.now())
    sigma = sim.noise_sigma(SETTINGS.ifbw_hz, SETTINGS.power_dbm, SETTINGS.averages)
    assert np.max(np.abs(result.s11 - expected)) < 6 * sigma


@pytest.mark.parametrize(("fault", "error"), FAULTS)
def test_single_fault_on_data_is_retried_with_a_new_sweep(sim, vna, port, clock, fault, error):
    before = sim.triggers
    sim.inject(fault, on=SDAT)
    result = measure(vna, port, "dut")
    assert sim.triggers == before + 2
    assert_complete_sweep(result, sim, clock)


@pytest.mark.parametrize(("fault", "error"), FAULTS)
def test_repeated_fault_on_data_is_reported(sim, vna, port, clock, fault, error):
    sim.inject(fault, on=SDAT, count=2)
    with pytest.raises(error, match=r"vna: .*CALC1:TRAC1:DATA:SDAT\?"):
        measure(vna, port, "dut")
    assert_complete_sweep(measure(vna, port, "dut"), sim, clock)


def test_drop_during_sweep_retriggers(sim, vna, port, clock):
    before = sim.triggers
    sim.inject(Fault.DROP_BEFORE_REPLY, on="*OPC?")
    result = measure(vna, port, "dut")
    assert sim.triggers == before + 2
    assert_complete_sweep(result, sim, clock)


@pytest.mark.parametrize(("fault", "error"), [FAULTS[0], FAULTS[1], FAULTS[3]])
def test_idempotent_query_retried_once(sim, vna, fault, error):
    sim.inject(fault, on="SENS1:SWE:POIN?")
    assert vna.read_settings() == SETTINGS
    sim.inject(fault, on="SENS1:SWE:POIN?", count=2)
    with pytest.raises((error, ProtocolError), match="vna"):
        vna.read_settings()


def test_drop_on_identification_is_retried(sim, clock):
    sim.inject(Fault.DROP_BEFORE_REPLY, on="*IDN?")
    driver = make_vna(sim, clock)
    assert driver.connect().startswith("CMT,TR1300/1")
    driver.close()


def test_drop_while_measuring_a_standard_measures_it_again(sim, vna, port, clock):
    vna.start_sol()
    for name in ("short", "open", "load"):
        port.connect(name)
        if name == "open":
            sim.inject(Fault.DROP_BEFORE_REPLY, on="*OPC?")
        vna.measure_standard(name)
    vna.save_calibration()
    result = measure(vna, port, "dut")
    sigma = predicted_sigma(sim, clock, SETTINGS, dut(result.freq_hz))
    assert np.max(np.abs(result.s11 - dut(result.freq_hz)) / sigma) < 4.5


# --- host-side calibration --------------------------------------------------------------


def test_host_side_calibration_recovers_truth_within_noise(sim, vna, port, clock):
    """Raw standards solved by the engine correct a raw DUT sweep to the truth."""
    cal = calibrate_on_host(vna, port.connect)
    port.connect("dut")
    raw = measure_raw(vna)
    assert not raw.calibrated
    assert not vna.calibration_active()
    result = cal.correct(raw)
    truth = dut(result.freq_hz)
    z = np.abs(result.s11 - truth) / predicted_sigma(sim, clock, SETTINGS, truth)
    assert result.calibrated
    assert 0.7 < np.mean(z**2) < 1.35  # as for the instrument's own correction
    assert np.max(z) < 4.5


def test_raw_sweep_restores_the_instruments_correction(vna, port):
    """A raw sweep between corrected ones leaves the instrument's calibration on."""
    calibrate(vna, port)
    port.connect("dut")
    raw = measure_raw(vna)
    assert not raw.calibrated
    assert vna.calibration_active()
    corrected = vna.measure_s11()
    assert corrected.calibrated
    assert np.max(np.abs(corrected.s11 - dut(corrected.freq_hz))) < 0.05
    assert np.min(np.abs(raw.s11 - dut(raw.freq_hz))) > 0.01


def test_host_side_calibration_with_a_modelled_kit_differs_from_ideal(sim, vna, port):
    """The kit model enters the correction: a 40 fF open moves the result by its phase."""
    kit = CalKit(open=OpenStandard(c0=40.0))
    ideal = calibrate_on_host(vna, port.connect)
    modelled = HostCalibration(ideal.freq_hz, ideal.raw, kit, solve_one_port(
        np.stack([ideal.raw[s] for s in ("short", "open", "load")]),
        kit.reflections(ideal.freq_hz),
    ), ideal.timestamp)
    port.connect("dut")
    raw = measure_raw(vna)
    shift = np.abs(modelled.correct(raw).s11 - ideal.correct(raw).s11)
    assert np.max(shift) > 1e-3


def test_host_correction_refuses_a_corrected_sweep(vna, port):
    cal = calibrate_on_host(vna, port.connect)
    vna.calibrate_sol(port.connect)
    with pytest.raises(DeviceError, match="already corrected"):
        cal.correct(vna.measure_s11())


def test_a_stuck_switch_is_named_by_the_host_side_calibration(vna):
    """Every standard reads the same DUT: refused before solving, naming the standards."""
    with pytest.raises(DeviceError, match=r"short and open read alike.*MHz"):
        calibrate_on_host(vna, lambda name: None)

