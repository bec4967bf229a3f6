"""``reachd --check``'s checks, against the simulated receiver and on constructed cases."""

import os
import shutil
import socket
from pathlib import Path

import pytest
from sites import planning_site

from reach_receiver.config.site import replace_devices
from reach_receiver.daemon.doctor import run_checks
from reach_receiver.daemon.doctor.clock import KernelClock, check_clock, clock_check
from reach_receiver.daemon.doctor.devices import device_checks
from reach_receiver.daemon.doctor.disk import check_disk, run_bytes_per_hour
from reach_receiver.daemon.doctor.outcome import STATUSES, Check, failed, format_checks
from reach_receiver.daemon.doctor.paths import (
    check_device_path,
    check_directory,
    check_library_path,
    device_path_checks,
)
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings, free_udp_port
from reach_receiver.sim.tec import TecSimulator

DEVICES = ("teensy", "vna", "spectrometer", "tc08", "tec")


@pytest.fixture(scope="module")
def sim():
    with SimulatedReceiver(SimulationSettings(compression=3000.0)) as receiver:
        yield receiver


@pytest.fixture
def data_dir(tmp_path: Path) -> Path:
    path = tmp_path / "runs"
    path.mkdir()
    path.chmod(0o750)
    return path


def by_name(checks: list[Check]) -> dict[str, Check]:
    found = {check.name: check for check in checks}
    assert len(found) == len(checks), "check names are unique"
    return found


# -- the whole check against the simulated receiver ---------------------------------------


def test_every_device_of_the_simulated_receiver_answers(sim, data_dir, tmp_path):
    site = sim.site()
    changes: list[dict[str, str]] = []
    sim.teensy.on_change(changes.append)
    checks = run_checks(
        site,
        clock=sim.clock,
        data_dir=data_dir,
        runtime_dir=tmp_path / "run",
        min_free_bytes=1,
        timeout_s=5.0,
    )
    sim.teensy.sync()
    found = by_name(checks)
    for name in (*DEVICES, "teensy port", "tc08 library"):
        assert found[name].status == "ok", found[name]
    assert changes == [], "the checks moved a switch or a rail"
    devices = site.devices
    assert devices.teensy.port in found["teensy"].detail
    assert "REACH front-end" in found["teensy"].detail
    assert "firmware" in found["teensy"].detail
    assert devices.vna.resource in found["vna"].detail
    assert "TR1300" in found["vna"].detail
    assert f"{devices.spectrometer.port}" in found["spectrometer"].detail
    assert "(2 x 16384)" in found["spectrometer"].detail
    assert "packets received" in found["spectrometer"].detail
    assert "cold junction" in found["tc08"].detail
    assert "via the Teensy" in found["tec"].detail
    assert found["clock"].status in STATUSES
    for name in ("disk", "data dir", "runtime dir"):
        assert found[name].status == "ok", found[name]
    assert not failed([check for check in checks if check.name != "clock"])


def test_format_checks_gives_one_aligned_line_per_check(sim, data_dir):
    checks = run_checks(
        sim.site(), clock=sim.clock, data_dir=data_dir, runtime_dir=None, min_free_bytes=1
    )
    lines = format_checks(checks).splitlines()
    assert len(lines) == len(checks)
    assert {line.index(check.detail) for line, check in zip(lines, checks, strict=True)} == {
        len("  fail  ") + max(len(check.name) for check in checks) + 1
    }
    for line, check in zip(lines, checks, strict=True):
        assert line.split()[0] == check.status
        assert f" {check.name} " in line
        assert line.endswith(check.detail)
    assert "runtime dir" not in by_name(checks)


def test_unreachable_devices_fail_naming_their_address_and_the_others_still_pass(
    sim, data_dir, tmp_path
):
    teensy = str(tmp_path / "reach-teensy")
    library = str(tmp_path / "libusbtc08.so")
    with socket.socket() as closed:  # bound, never listening: connections are refused
        closed.bind(("127.0.0.1", 0))
        resource = f"TCPIP0::127.0.0.1::{closed.getsockname()[1]}::SOCKET"
        site = replace_devices(
            sim.site(),
            vna={"resource": resource, "timeout_s": 2.0},
            teensy={"port": teensy, "timeout_s": 0.2},
            tc08={"library": library},
        )
        checks = run_checks(
            site, clock=sim.clock, data_dir=data_dir, runtime_dir=None, min_free_bytes=1
        )
    found = by_name(checks)
    for name, address in (
        ("vna", resource),
        ("teensy", teensy),
        ("teensy port", teensy),
        ("tc08", library),
        ("tc08 library", library),
    ):
        assert found[name].status == "fail", found[name]
        assert address in found[name].detail
    assert "udev rules" in found["teensy port"].detail
    assert "Connection refused" in found["vna"].detail
    assert found["spectrometer"].status == "ok", found["spectrometer"]
    assert found["tec"].status == "ok"
    assert found["data dir"].status == "ok"
    assert failed(checks)
    assert format_checks(checks).count("\n  fail  ") >= 4


def test_a_silent_spectrometer_fails_within_the_timeout_with_its_counters(sim):
    port = free_udp_port()
    site = replace_devices(sim.site(), spectrometer={"host": "127.0.0.1", "port": port})
    found = by_name(device_checks(site, sim.clock, timeout_s=0.3))
    assert found["spectrometer"].status == "fail"
    assert f"127.0.0.1:{port}" in found["spectrometer"].detail
    assert "packets received 0" in found["spectrometer"].detail
    assert found["vna"].status == "ok"


def test_a_tec_on_its_own_serial_port_reports_its_status_and_faults(sim):
    tec = TecSimulator(sim.clock)
    port = tec.start()
    try:
        site = replace_devices(sim.site(), tec={"via": "serial", "port": port})
        healthy = by_name(device_checks(site, sim.clock) + device_path_checks(site))
        tec.set_fault_bits(1)
        faulty = by_name(device_checks(site, sim.clock))
    finally:
        tec.stop()
    assert healthy["tec"].status == "ok", healthy["tec"]
    assert port in healthy["tec"].detail
    assert "setpoint" in healthy["tec"].detail
    assert healthy["tec port"].status == "ok"
    assert faulty["tec"].status == "warn"
    assert "faults: adc" in faulty["tec"].detail


# -- device names ---------------------------------------------------------------------------


def test_a_serial_port_must_be_an_accessible_character_device(tmp_path):
    assert check_device_path("teensy port", "/dev/null", "hint").status == "ok"
    plain = tmp_path / "not-a-device"
    plain.write_text("")
    wrong = check_device_path("teensy port", str(plain), "hint")
    assert wrong.status == "fail"
    assert "not a character device" in wrong.detail
    missing = check_device_path("teensy port", str(tmp_path / "gone"), "plug it in?")
    assert missing.status == "fail"
    assert missing.detail == f"no {tmp_path / 'gone'}: plug it in?"


def test_a_named_library_must_exist(tmp_path):
    library = tmp_path / "libusbtc08.so"
    assert check_library_path("tc08 library", str(library)).status == "fail"
    library.write_bytes(b"\x7fELF")
    assert check_library_path("tc08 library", str(library)).status == "ok"
    assert check_library_path("tc08 library", None).status in ("ok", "warn")


# -- clock ----------------------------------------------------------------------------------


def test_a_synchronised_kernel_clock_reports_its_estimated_error():
    # STA_PLL | STA_NANO, as chrony leaves them; errors in microseconds
    check = clock_check(KernelClock(state=0, status=0x2001, esterror_us=512, maxerror_us=16500))
    assert check == Check("clock", "ok", "synchronised (estimated error 512 us, at most 16.5 ms)")


@pytest.mark.parametrize(
    ("state", "status", "reason"),
    [
        (5, 0x40, "clock state TIME_ERROR, STA_UNSYNC set"),
        (0, 0x40, "STA_UNSYNC set"),
        (5, 0x2001, "clock state TIME_ERROR"),
    ],
)
def test_an_unsynchronised_kernel_clock_fails(state, status, reason):
    check = clock_check(KernelClock(state, status, esterror_us=16_000_000, maxerror_us=16_000_000))
    assert check.status == "fail"
    assert f"not synchronised ({reason})" in check.detail


def test_this_machine_s_clock_gives_a_sensible_line():
    check = check_clock()
    assert check.name == "clock"
    assert check.status in STATUSES
    assert "synchronised" in check.detail or "NTP state" in check.detail


# -- disk -----------------------------------------------------------------------------------


def test_free_space_below_the_minimum_fails_and_above_twice_it_passes(tmp_path):
    free = shutil.disk_usage(tmp_path).free
    rate = run_bytes_per_hour(planning_site(period_s=1.0))
    short = check_disk(tmp_path, 2 * free + 2**30, rate)
    assert short.status == "fail"
    assert "below the minimum" in short.detail
    plenty = check_disk(tmp_path / "runs" / "not-yet", 1, rate)
    assert plenty.status == "ok"
    assert " GiB free of " in plenty.detail
    assert " h of observation at 9.6 MB/h" in plenty.detail
    assert check_disk(tmp_path, free * 3 // 4, rate).status == "warn"


def test_the_data_rate_follows_the_spectrometer_s_period():
    one_second = run_bytes_per_hour(planning_site(period_s=1.0))
    thirty_seconds = run_bytes_per_hour(planning_site(period_s=30.0))
    spectra_only = 2 * 6 * 3 * 2 * 16384 * 8  # merge factor, cycles/h, positions, inputs
    assert spectra_only < thirty_seconds < one_second < 1.02 * spectra_only


# -- directories ----------------------------------------------------------------------------


def test_a_world_writable_directory_fails(tmp_path):
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o777)
    check = check_directory("data dir", shared, private=True)
    assert check.status == "fail"
    assert "world-writable" in check.detail
    assert "mode 0777" in check.detail


def test_a_group_directory_passes_and_one_readable_by_others_warns(tmp_path, data_dir):
    ok = check_directory("data dir", data_dir, private=True)
    assert ok.status == "ok"
    assert "mode 0750" in ok.detail
    assert "group " in ok.detail
    data_dir.chmod(0o755)
    assert check_directory("data dir", data_dir, private=True).status == "warn"
    assert check_directory("runtime dir", data_dir, private=False).status == "ok"


def test_a_missing_directory_that_can_be_made_passes_and_a_file_fails(tmp_path):
    later = check_directory("runtime dir", tmp_path / "run" / "reach", private=False)
    assert later.status == "ok"
    assert "does not exist yet" in later.detail
    assert not (tmp_path / "run").exists(), "a check creates nothing"
    plain = tmp_path / "file"
    plain.write_text("")
    assert check_directory("data dir", plain, private=True).status == "fail"


def test_check_statuses_are_checked():
    with pytest.raises(ValueError, match="status"):
        Check("disk", "bad", "")  # type: ignore[arg-type]
    assert not failed([Check("disk", "warn", "low"), Check("clock", "ok", "")])
    assert failed([Check("disk", "fail", "full")])
    assert os.linesep not in format_checks([Check("x", "ok", "two\nlines")])
