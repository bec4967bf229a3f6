"""Spectra are taken only from the site's iTPM address: real UDP sockets on loopback.

A spoofer binds another loopback address (127.0.0.2, bindable on Linux without set-up)
and sends valid SPEAD packets; the spectrometer must drop and count them, warn once, and
assemble the true spectrum from the source alone.
"""

import logging
import socket
import time

import numpy as np
import pytest
import yaml

from reach_receiver.config.site import SiteError, load_site
from reach_receiver.devices.spectrometer import Spectrometer
from reach_receiver.errors import DeviceTimeout
from reach_receiver.run.instruments import Instruments
from reach_receiver.sim.itpm import encode_spectrum
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings, simulated_site
from reach_receiver.transports.udp import UdpReceiver
from tests.sites import DEVICES

N_CHANNELS = 1024  # 16 packets a spectrum
SYNC = 1_700_000_000
TRUTH = np.random.default_rng(1).uniform(1.0, 2.0, (2, N_CHANNELS))
FAKE = np.full((2, N_CHANNELS), 1e6)


def _socket(host):
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind((host, 0))
    return sock


@pytest.fixture
def senders():
    itpm, spoofer, neighbour = _socket("127.0.0.1"), _socket("127.0.0.2"), _socket("127.0.0.1")
    yield itpm, spoofer, neighbour
    for sock in (itpm, spoofer, neighbour):
        sock.close()


def _send(sock, address, data, stamp=10):
    for packet in encode_spectrum(data, stamp, stamp, SYNC):
        sock.sendto(packet, address)


def _spectrometer(**source):
    return Spectrometer(("127.0.0.1", 0), n_channels=N_CHANNELS, timeout_s=1.0, **source)


def test_a_spoofer_on_another_address_is_dropped_counted_and_warned_once(senders, caplog):
    itpm, spoofer, _ = senders
    with _spectrometer(source="127.0.0.1") as device, caplog.at_level(logging.WARNING):
        _send(spoofer, device.address, FAKE)  # the same timestamp, sent first
        _send(itpm, device.address, TRUTH)
        spectrum = device.read_spectrum()
        stats = device.statistics
    assert np.array_equal(spectrum.data, TRUTH)
    assert stats.packets_foreign == 16
    assert stats.packets_received == 16
    drops = [r for r in caplog.records if "dropped a datagram from 127.0.0.2" in r.getMessage()]
    assert len(drops) == 1, [r.getMessage() for r in caplog.records]


def test_without_a_source_the_same_spoofer_enters_the_spectrum(senders):
    """What the source setting prevents: the first heap of a timestamp is the spoofer's."""
    itpm, spoofer, _ = senders
    with _spectrometer() as device:
        _send(spoofer, device.address, FAKE)
        _send(itpm, device.address, TRUTH)
        spectrum = device.read_spectrum()
    assert np.array_equal(spectrum.data, FAKE)


def test_a_source_port_refuses_other_ports_of_the_same_address(senders):
    itpm, _, neighbour = senders
    port = itpm.getsockname()[1]
    with _spectrometer(source="127.0.0.1", source_port=port) as device:
        _send(neighbour, device.address, FAKE)
        _send(itpm, device.address, TRUTH)
        assert np.array_equal(device.read_spectrum().data, TRUTH)
        assert device.statistics.packets_foreign == 16
    with _spectrometer(source="127.0.0.1") as device:  # any port of the address
        _send(neighbour, device.address, TRUTH)
        assert np.array_equal(device.read_spectrum().data, TRUTH)
        assert device.statistics.packets_foreign == 0


def test_a_flood_from_elsewhere_ends_at_the_deadline_and_flush_is_bounded(senders):
    _, spoofer, _ = senders
    with _spectrometer(source="127.0.0.1") as device:
        packets = encode_spectrum(FAKE, 10, 10, SYNC)
        for k in range(3000):
            spoofer.sendto(packets[k % 16], device.address)
        start = time.monotonic()
        with pytest.raises(DeviceTimeout, match="no complete spectrum"):
            device.read_spectrum(timeout_s=0.3)
        assert time.monotonic() - start < 1.0
        assert device.statistics.packets_received == 0
        assert device.statistics.packets_foreign > 0
        assert device.flush() == 0  # none of it is the source's


def test_the_transport_names_its_source_and_refuses_a_host_name():
    assert UdpReceiver("127.0.0.1", 0, source="10.0.0.5", source_port=7).sender == "10.0.0.5:7"
    assert UdpReceiver("127.0.0.1", 0).sender == "anyone"
    with pytest.raises(ValueError, match=r"itpm\.local"):
        UdpReceiver("127.0.0.1", 0, source="itpm.local")


def test_no_source_on_an_interface_beyond_loopback_is_a_warning_at_connect(caplog):
    with caplog.at_level(logging.INFO), Spectrometer(("0.0.0.0", 0), n_channels=N_CHANNELS):
        pass
    loud = [r for r in caplog.records if "from any sender" in r.getMessage()]
    assert loud
    assert loud[0].levelno == logging.WARNING
    assert "devices.spectrometer.source" in loud[0].getMessage()
    caplog.clear()
    with caplog.at_level(logging.INFO), _spectrometer(source="127.0.0.1"):
        pass
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]


# ---------------------------------------------------------------- the site file


def _site(tmp_path, spectrometer):
    devices = {**DEVICES, "spectrometer": {**DEVICES["spectrometer"], **spectrometer}}
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump({"devices": devices}))
    return path


def test_the_site_file_names_the_source_and_the_driver_takes_it(tmp_path):
    path = _site(tmp_path, {"host": "127.0.0.1", "source": "127.0.0.9", "source_port": 4661})
    site = load_site(path)
    settings = site.devices.spectrometer
    assert (settings.host, settings.source) == ("127.0.0.1", "127.0.0.9")
    assert settings.source_port == 4661
    transport = Instruments.from_site(site, site.clock()).spectrometer.transport
    assert (transport.source, transport.source_port) == ("127.0.0.9", 4661)
    assert "source: 127.0.0.9" in site.to_yaml()


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"source": "itpm.local"}, "spectrometer.source: must be an IPv4 address"),
        ({"source": "10.0.0.300"}, "spectrometer.source: must be an IPv4 address"),
        ({"host": "eth0"}, "spectrometer.host: must be an IPv4 address"),
        ({"source_port": 70000}, "spectrometer.source_port: must be at most 65535"),
        ({"source_port": -1}, "spectrometer.source_port: must be an integer >= 0"),
    ],
)
def test_a_bad_source_is_refused_at_its_line(tmp_path, values, message):
    path = _site(tmp_path, values)
    with pytest.raises(SiteError) as caught:
        load_site(path)
    assert message in str(caught.value)
    assert f"{path}:" in str(caught.value)


# ---------------------------------------------------------------- the simulated receiver


def test_the_simulated_site_listens_on_loopback_and_names_its_itpm():
    planned = simulated_site(SimulationSettings()).devices.spectrometer
    assert (planned.host, planned.source) == ("127.0.0.1", "127.0.0.1")
    # 10 spectra a real second: few enough that no datagram is lost in the kernel.
    with SimulatedReceiver(SimulationSettings(compression=100.0, spectrum_period_s=10.0)) as sim:
        settings = sim.site().devices.spectrometer
        assert settings.host == "127.0.0.1"
        assert (settings.source, settings.source_port) == sim.itpm.sender
        assert settings.source_port > 0
        spoofer = _socket("127.0.0.2")
        try:
            with Spectrometer(
                (settings.host, settings.port), source=settings.source,
                source_port=settings.source_port, timeout_s=5.0,
            ) as device:
                fake = encode_spectrum(np.zeros((2, 16384)), 1, 1, SYNC)
                for packet in fake:
                    spoofer.sendto(packet, device.address)
                device.read_spectrum()
                spectrum = device.read_spectrum()  # began after every spoofed one was sent
                assert device.statistics.packets_foreign == len(fake)
        finally:
            spoofer.close()
    assert spectrum.data.shape == (2, 16384)
    assert np.all(spectrum.data > 0)  # the simulated sky, not the spoofer's zeros
