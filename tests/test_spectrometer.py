"""The spectrometer driver over real UDP on loopback, fed by the iTPM simulator.

Time runs 50 times faster than real (CompressedClock): a 1 s spectrum takes 20 ms.
"""

import numpy as np
import pytest

from reach_receiver.clock import CompressedClock
from reach_receiver.devices.spectrometer import Spectrometer
from reach_receiver.errors import DeviceTimeout
from reach_receiver.sim.itpm import ItpmFaults, ItpmSimulator
from reach_receiver.transports.udp import UdpReceiver

FACTOR = 50.0
PERIOD_S = 1.0
SHAPE = (2, 16384)
TRUTH = np.random.default_rng(11).uniform(1e3, 1e7, SHAPE)


def fixed_source(t_start, duration_s):
    return TRUTH


def heap_source(t_start, duration_s):
    """Every channel carries the spectrum's start time: a mixed heap would not be uniform."""
    return np.full(SHAPE, t_start)


@pytest.fixture
def clock():
    return CompressedClock(FACTOR)


@pytest.fixture
def spectrometer(clock):
    device = Spectrometer(("127.0.0.1", 0), clock=clock, timeout_s=2.0, period_s=PERIOD_S)
    device.connect()
    yield device
    device.close()


@pytest.fixture
def run_sim(spectrometer, clock):
    started = []

    def start(source=fixed_source, faults=None, seed=0):
        sim = ItpmSimulator(source, clock, spectrometer.address, PERIOD_S, faults, seed=seed)
        sim.start()
        started.append(sim)
        return sim

    yield start
    for sim in started:
        sim.stop()
        assert sim.error is None


def assert_clean(stats):
    assert stats.packets_malformed == 0
    assert stats.packets_lost == 0
    assert stats.heaps_dropped == 0


def test_exact_recovery_in_physical_channel_order(spectrometer, run_sim):
    run_sim()
    for _ in range(3):
        spectrum = spectrometer.read_spectrum()
        assert spectrum.data.dtype == np.float64
        assert spectrum.data.shape == SHAPE
        np.testing.assert_array_equal(spectrum.data, TRUTH)
    stats = spectrometer.statistics
    assert_clean(stats)
    assert stats.spectra_completed == 3
    assert stats.packets_received >= 3 * 256


def test_spectrum_timestamps_follow_the_period(spectrometer, run_sim, clock):
    started = clock.now()
    run_sim()
    first = spectrometer.read_spectrum()
    second = spectrometer.read_spectrum()
    assert second.timestamp - first.timestamp == pytest.approx(PERIOD_S, abs=1e-4)
    assert second.raw_timestamp > first.raw_timestamp
    assert second.heap_counter == first.heap_counter + 1
    assert started - 1e-3 <= first.timestamp <= clock.now() - PERIOD_S


def test_integration_mean_and_noise(spectrometer, run_sim):
    sigma = 0.05
    rng = np.random.default_rng(5)

    def noisy(t_start, duration_s):
        return TRUTH * (1 + sigma * rng.standard_normal(SHAPE))

    run_sim(noisy)
    n = 16
    result = spectrometer.integrate(n, discard=1)
    assert result.n_spectra == n
    assert result.n_discarded == 1
    assert len(result.timestamps) == n
    assert result.mean.shape == SHAPE
    residual = result.mean / TRUTH - 1
    assert abs(residual.mean()) < 5 * sigma / np.sqrt(n * residual.size)
    # 32768 channels: the standard deviation is estimated to 0.4 %
    assert residual.std() == pytest.approx(sigma / np.sqrt(n), rel=0.03)
    assert result.stop_time - result.start_time == pytest.approx((n - 1) * PERIOD_S, abs=1e-3)
    assert result.packets_lost == result.packets_duplicated == result.packets_malformed == 0


def test_lost_packets_drop_whole_heaps_never_mixed(spectrometer, run_sim):
    sim = run_sim(heap_source, ItpmFaults(drop_fraction=0.004), seed=3)
    spectra = [spectrometer.read_spectrum() for _ in range(12)]
    for spectrum in spectra:
        value = spectrum.data[0, 0]
        assert np.all(spectrum.data == value), "a spectrum mixes packets of two heaps"
        assert value == pytest.approx(spectrum.timestamp, abs=2e-4)
    stats = spectrometer.statistics
    assert stats.heaps_dropped > 0
    assert stats.packets_lost > 0
    assert stats.packets_lost <= sim.stats.packets_dropped
    # the complete spectra are a subset of the sent ones, in order, one period apart
    steps = np.diff([s.timestamp for s in spectra]) / PERIOD_S
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-3)
    assert np.all(steps >= 1 - 1e-3)
    gaps = int(np.sum(np.round(steps) - 1))  # spectra missing between the delivered ones
    assert 1 <= gaps <= stats.heaps_dropped + 1  # the last gap may still be an open heap


def test_integration_with_loss_averages_complete_heaps_only(spectrometer, run_sim):
    run_sim(heap_source, ItpmFaults(drop_fraction=0.006), seed=9)
    result = spectrometer.integrate(6, discard=1)
    np.testing.assert_allclose(result.mean, np.mean(result.timestamps), rtol=0, atol=2e-4)
    assert result.heaps_dropped > 0
    assert result.packets_lost > 0


def test_duplicates_are_counted_and_ignored(spectrometer, run_sim):
    sim = run_sim(faults=ItpmFaults(duplicate_fraction=0.05), seed=4)
    for _ in range(4):
        np.testing.assert_array_equal(spectrometer.read_spectrum().data, TRUTH)
    stats = spectrometer.statistics
    assert_clean(stats)
    assert stats.packets_duplicated > 0
    assert stats.packets_duplicated <= sim.stats.packets_duplicated


def test_reordered_packets_within_a_heap_are_accepted(spectrometer, run_sim):
    run_sim(faults=ItpmFaults(reorder=True), seed=6)
    for _ in range(4):
        np.testing.assert_array_equal(spectrometer.read_spectrum().data, TRUTH)
    assert_clean(spectrometer.statistics)


def test_garbage_datagrams_are_counted_never_raised(spectrometer, run_sim):
    sim = run_sim(faults=ItpmFaults(garbage_fraction=0.05, reorder=True), seed=7)
    for _ in range(4):
        np.testing.assert_array_equal(spectrometer.read_spectrum().data, TRUTH)
    stats = spectrometer.statistics
    assert stats.packets_malformed > 0
    assert stats.packets_malformed <= sim.stats.garbage_sent
    assert stats.packets_lost == 0


def test_faults_switched_at_run_time(spectrometer, run_sim):
    sim = run_sim(heap_source)
    spectrometer.read_spectrum()
    sim.set_faults(drop_fraction=0.01, duplicate_fraction=0.02)
    for _ in range(3):
        data = spectrometer.read_spectrum().data
        assert np.all(data == data[0, 0])
    sim.set_faults(drop_fraction=0.0, duplicate_fraction=0.0)
    assert sim.faults == ItpmFaults()
    spectrometer.integrate(2, discard=1)
    assert spectrometer.statistics.heaps_dropped > 0


def test_stall_raises_device_timeout_naming_the_count(spectrometer, run_sim):
    spectrometer.timeout_s = 0.3
    sim = run_sim()
    spectrometer.read_spectrum()
    sim.set_faults(stall=True)
    with pytest.raises(DeviceTimeout, match=r"0 of 3 spectra arrived") as info:
        spectrometer.integrate(3, discard=1)
    assert info.value.device == "itpm"
    assert info.value.command == "integrate"


def test_whole_integration_deadline(spectrometer, run_sim):
    run_sim()
    # 50 spectra take 1 s of real time at this compression; 0.2 s cannot be enough
    with pytest.raises(DeviceTimeout, match=r"of 50 spectra arrived"):
        spectrometer.integrate(50, discard=0, timeout_s=0.2)


def test_discard_and_flush_skip_spectra_older_than_the_request(spectrometer, run_sim, clock):
    run_sim(heap_source)
    clock.sleep(5 * PERIOD_S)  # five spectra queue up unread
    result = spectrometer.integrate(2, discard=0)
    # the flush dropped the queued ones: the first kept spectrum ended after the request
    assert result.start_time > result.requested_at - PERIOD_S
    assert spectrometer.statistics.packets_flushed >= 4 * 256
    result = spectrometer.integrate(2, discard=1)
    assert result.n_discarded == 1
    # a spectrum that straddles the request is the one discarded
    assert result.start_time >= result.requested_at - 1e-3
    np.testing.assert_allclose(result.mean, np.mean(result.timestamps), rtol=0, atol=2e-4)


def test_small_spectra_and_integer_mode(clock):
    shape = (2, 1024)
    truth = np.arange(2 * 1024, dtype=float).reshape(shape) * 3
    with Spectrometer(
        ("127.0.0.1", 0), n_channels=1024, clock=clock, timeout_s=2.0, floating_point=False
    ) as device:
        sim = ItpmSimulator(lambda t, d: truth, clock, device.address, floating_point=False)
        with sim:
            np.testing.assert_array_equal(device.read_spectrum().data, truth)
        assert device.n_packets == 16


def test_wrong_mode_packets_are_malformed(clock):
    with Spectrometer(("127.0.0.1", 0), clock=clock, timeout_s=0.3) as device:
        sim = ItpmSimulator(fixed_source, clock, device.address, floating_point=False)
        with sim, pytest.raises(DeviceTimeout):
            device.read_spectrum()
        assert device.statistics.packets_malformed > 0
        assert device.statistics.spectra_completed == 0


def test_period_estimated_from_consecutive_spectra(clock):
    with Spectrometer(("127.0.0.1", 0), clock=clock, timeout_s=2.0) as device:
        sim = ItpmSimulator(heap_source, clock, device.address, period_s=2.0)
        with sim:
            assert device.period is None
            device.read_spectrum()
            device.read_spectrum()
            assert device.period == pytest.approx(2.0, abs=1e-3)
            result = device.integrate(1, discard=0)
            assert result.start_time > result.requested_at - 2.0


def test_udp_transport_reports_buffer_and_times_out():
    receiver = UdpReceiver("127.0.0.1", 0, rcvbuf_bytes=8 * 1024 * 1024, timeout_s=0.05)
    receiver.open()
    try:
        assert receiver.rcvbuf_granted > 0
        assert receiver.address[1] > 0
        buffer = bytearray(2048)
        assert receiver.recv_into_nowait(buffer) == 0
        with pytest.raises(DeviceTimeout, match="no datagram"):
            receiver.recv_into(buffer)
    finally:
        receiver.close()
        receiver.close()
    assert not receiver.is_open
