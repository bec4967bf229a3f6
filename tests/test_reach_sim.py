"""``reach-sim`` as its own process: the site file it prints reaches every instrument."""

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from reach_receiver.cli import run_main
from reach_receiver.clock import SystemClock
from reach_receiver.config.site import load_site
from reach_receiver.devices.spectrometer import Spectrometer
from reach_receiver.devices.tc08 import Tc08
from reach_receiver.devices.teensy import Teensy
from reach_receiver.devices.vna import Vna
from reach_receiver.sim.receiver import free_udp_port
from reach_receiver.transports.tc08_library import load_libusbtc08


@pytest.fixture
def reach_sim(tmp_path):
    site_file = tmp_path / "site.yaml"
    port = free_udp_port()
    entry = "from reach_receiver.cli import sim_main; raise SystemExit(sim_main())"
    options = ["--site-out", str(site_file), "--spectrometer-port", str(port)]
    process = subprocess.Popen(
        [sys.executable, "-c", entry, *options, "--spectrum-period", "60"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 60
    while not site_file.exists() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    yield process, site_file
    if process.poll() is None:
        process.kill()
    process.communicate(timeout=10)


def test_reach_sim_serves_its_site_file_and_stops_cleanly(reach_sim):
    process, site_file = reach_sim
    assert site_file.exists(), process.stderr.read() if process.poll() is not None else "no site"
    site = load_site(site_file)
    clock = SystemClock()
    devices = site.devices
    with Teensy(devices.teensy.port) as teensy:
        assert teensy.read_state().boot == "por"
    with Vna(devices.vna.resource) as vna:
        assert "TR1300" in vna.connect()
    spectrometer = devices.spectrometer
    with Spectrometer((spectrometer.host, spectrometer.port), clock=clock) as itpm:
        spectrum = itpm.read_spectrum(timeout_s=10.0)
        assert spectrum.data.shape == (2, 16384)
    with Tc08(load_libusbtc08(devices.tc08.library), clock) as tc08:
        assert 20.0 < tc08.read().temperatures_c[1] < 30.0
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=20) == 0


def test_reach_run_follows_a_reach_sim_in_another_process(reach_sim, tmp_path, capsys):
    """The site file carries the simulator's compressed clock, which reach-run shares."""
    process, site_file = reach_sim
    schedule = Path(__file__).resolve().parents[1] / "schedules" / "quick.yaml"
    out = tmp_path / "runs"
    assert run_main(["--site", str(site_file), str(schedule), "--out", str(out), "-q"]) == 0
    printed = capsys.readouterr().out
    assert "check test load: PASS" in printed
    assert "distance to floor" in printed
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=20) == 0


def test_the_i2c_sensors_follow_the_enclosure():
    from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings

    # A slow enclosure (tau 10 h) starting 10 K above the TEC's 25 C setpoint.
    settings = SimulationSettings(enclosure_start_c=35.0, tec_tau_s=36000.0)
    with SimulatedReceiver(settings) as sim, Teensy(sim.site().devices.teensy.port) as teensy:
        first = teensy.temperatures()[0x18]
        deadline = time.monotonic() + 30
        later = first
        while later > first - 0.5 and time.monotonic() < deadline:
            time.sleep(0.05)  # polling the sensors, a few simulated minutes each time
            later = teensy.temperatures()[0x18]
    assert first > 30.0
    assert later <= first - 0.5
