"""End-to-end tests of the C++ firmware core run as ``teensy-sim`` behind a real pty.

The program is built once per module with ``make -C firmware sim``; each test starts a
fresh instance through :class:`FirmwareTeensy`, opens its pseudo-terminal with pyserial
and speaks PROTOCOL.md to it byte for byte.
"""

from __future__ import annotations

import os
import select
import subprocess
import threading
import tty
from collections.abc import Iterator
from pathlib import Path

import pytest
import serial

from reach_receiver.errors import ReceiverError
from reach_receiver.sim.teensy_firmware import FIRMWARE_DIR, FirmwareTeensy, parse_pins

REPLY_TIMEOUT_S = 2.0
WATCHDOG_MS = 300

POWER_ON = {
    "ms1": "0", "ms2": "0", "ms3": "0", "ms4": "0", "mts": "lna",
    "6v": "0", "12v": "0", "24v": "0", "ns": "0", "fan": "0", "tec": "0",
}  # fmt: skip


@pytest.fixture(scope="module")
def built() -> None:
    done = subprocess.run(
        ["make", "-C", str(FIRMWARE_DIR), "sim"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr


@pytest.fixture
def sim(built: None) -> Iterator[FirmwareTeensy]:
    with FirmwareTeensy(watchdog_ms=WATCHDOG_MS, build=False) as teensy:
        yield teensy


@pytest.fixture
def port(sim: FirmwareTeensy) -> Iterator[serial.Serial]:
    link = serial.Serial(sim.port, timeout=REPLY_TIMEOUT_S)
    yield link
    link.close()


@pytest.fixture
def tec_pty() -> Iterator[tuple[int, str]]:
    """A pty pair standing in for the TEC controller: (master fd, slave path)."""
    master, slave = os.openpty()
    tty.setraw(master)
    path = os.ttyname(slave)
    yield master, path
    os.close(slave)
    os.close(master)


def ask(link: serial.Serial, line: str) -> str:
    link.write(line.encode("ascii") + b"\n")
    reply = link.readline()
    assert reply.endswith(b"\r\n"), f"no complete reply to {line!r}: {reply!r}"
    return reply[:-2].decode("ascii")


def only_state(state: dict[str, str]) -> dict[str, str]:
    return {k: v for k, v in state.items() if k not in ("boot", "uptime_ms", "changes", "deadman")}


def test_identity_and_tagged_ping(port: serial.Serial) -> None:
    assert ask(port, "#a1 ping") == "OK 00 #a1 pong"
    assert ask(port, "id") == "OK 00 REACH front-end teensy35"
    assert ask(port, "version") == "OK 00 firmware=2.0.0 protocol=2"
    commands = "help id version ping state select rail temps tec safe deadman"
    assert ask(port, "#zz help") == f"OK 00 #zz {commands}"


def test_framing_errors_over_the_wire(port: serial.Serial) -> None:
    assert ask(port, "#t1 " + "x" * 300) == "ERR 01 #t1 line too long"
    port.write(b"ping\x00\n")
    assert port.readline() == b"ERR 02 byte outside printable ascii\r\n"
    assert ask(port, "#bad-tag ping") == "ERR 07 bad tag"
    port.write(b"ping\r\n")
    assert port.readline() == b"OK 00 pong\r\n"


def test_pins_lines_follow_every_change(sim: FirmwareTeensy, port: serial.Serial) -> None:
    assert only_state(sim.state) == POWER_ON
    assert sim.state["boot"] == "por"
    seen: list[dict[str, str]] = []
    sim.on_change(seen.append)
    assert ask(port, "rail 12v on") == "OK 00 12v=1"
    assert ask(port, "select ms1 3") == "OK 00 ms1=3"
    state = sim.wait_for_state(lambda s: s.get("ms1") == "3", REPLY_TIMEOUT_S)
    assert only_state(state) == {**POWER_ON, "12v": "1", "ms1": "3"}
    assert [s["ms1"] for s in seen] == ["0", "3"]
    assert [s["12v"] for s in seen] == ["1", "1"]
    # The state reply and the PINS line agree.
    reply = ask(port, "state")
    assert only_state(parse_pins(reply.removeprefix("OK 00 "))) == only_state(state)


def test_refused_command_moves_nothing(sim: FirmwareTeensy, port: serial.Serial) -> None:
    seen: list[dict[str, str]] = []
    sim.on_change(seen.append)
    assert ask(port, "select ms2 1") == "ERR 20 ms2 needs rail 24v"
    assert ask(port, "rail 3v3 off") == "ERR 21 rail 3v3 is not switchable"
    assert ask(port, "rail fan on") == "ERR 20 fan needs rail 24v"
    # PINS lines come in order: any from the refused lines would precede this change's.
    assert ask(port, "rail 6v on") == "OK 00 6v=1"
    state = sim.wait_for_state(lambda s: s.get("6v") == "1", REPLY_TIMEOUT_S)
    assert only_state(state) == {**POWER_ON, "6v": "1"}
    assert len(seen) == 1


def test_safe_keeps_fan_and_24v(sim: FirmwareTeensy, port: serial.Serial) -> None:
    for line in ("rail 24v on", "rail fan on", "rail 12v on", "rail ns on", "select ms2 5",
                 "select mts vna", "select ms4 2"):  # fmt: skip
        assert ask(port, line).startswith("OK 00")
    reply = ask(port, "#s safe")
    assert reply.startswith("OK 00 #s ms1=0 ms2=0 ms3=0 ms4=0 mts=lna 6v=0 12v=0 24v=1 ns=0 fan=1")
    # PINS lines lag the replies: wait for the one that counts the safe's own changes, since
    # an earlier line (after "rail fan on") already looked like the safe state.
    changes = parse_pins(reply.removeprefix("OK 00 #s "))["changes"]
    state = sim.wait_for_state(lambda s: s.get("changes") == changes, REPLY_TIMEOUT_S)
    assert only_state(state) == {**POWER_ON, "24v": "1", "fan": "1"}


def test_i2c_sensor_injection(sim: FirmwareTeensy, port: serial.Serial) -> None:
    assert ask(port, "temps") == "OK 00"
    sim.set_sensor(0x18, 24.94)
    sim.set_sensor(0x1B, -5.0)
    assert ask(port, "#t temps") == "OK 00 #t 0x18=24.94 0x1b=-5.00"
    sim.set_sensor(0x1B, None)
    assert ask(port, "temps") == "OK 00 0x18=24.94"
    sim.fail_sensor(0x19)
    assert ask(port, "temps") == "ERR 40 i2c bus error at 0x19"


def test_hang_is_recovered_by_the_watchdog(sim: FirmwareTeensy, port: serial.Serial) -> None:
    assert ask(port, "rail 24v on") == "OK 00 24v=1"
    assert ask(port, "select mts vna") == "OK 00 mts=vna"
    sim.wait_for_state(lambda s: s.get("mts") == "vna", REPLY_TIMEOUT_S)
    sim.hang()
    port.write(b"#h1 ping\n")
    port.timeout = WATCHDOG_MS / 1000 / 3
    assert port.readline() == b""  # a hung board answers nothing
    state = sim.wait_for_state(lambda s: s.get("boot") == "wdog", 10 * WATCHDOG_MS / 1000)
    assert only_state(state) == POWER_ON
    port.timeout = REPLY_TIMEOUT_S
    assert port.read(port.in_waiting) == b""  # the request sent while hung was lost
    assert ask(port, "#h2 ping") == "OK 00 #h2 pong"
    assert "boot=wdog" in ask(port, "state")


def test_deadman_trips_in_real_time_and_reports_once(
    sim: FirmwareTeensy, port: serial.Serial
) -> None:
    for line in ("rail 24v on", "rail fan on", "rail 12v on", "select ms1 4"):
        assert ask(port, line).startswith("OK 00")
    assert ask(port, "#d deadman 200") == "OK 00 #d deadman=200"
    assert parse_pins(ask(port, "state").removeprefix("OK 00 "))["changes"] == "4"
    # The simulator goes safe on its own (a PINS line), with nobody asking. The trip's line is
    # the first past the host's four changes: an earlier line, still unread when the replies
    # came back, also has 12v=0.
    state = sim.wait_for_state(lambda s: int(s.get("changes", "0")) > 4, 10 * 0.2)
    assert only_state(state) == {**POWER_ON, "24v": "1", "fan": "1"}
    assert (state["changes"], state["deadman"]) == ("6", "0")
    expected = "dead-man tripped after 200 ms without the host; front-end safe"
    assert ask(port, "#x1 rail 6v on") == f"ERR 50 #x1 {expected}"
    assert ask(port, "#x2 rail 6v on") == "OK 00 #x2 6v=1"


def test_port_can_be_reopened(sim: FirmwareTeensy) -> None:
    for round_ in range(3):
        with serial.Serial(sim.port, timeout=REPLY_TIMEOUT_S) as link:
            assert ask(link, f"#r{round_} ping") == f"OK 00 #r{round_} pong"


def test_tec_query_without_uart_times_out(port: serial.Serial) -> None:
    assert ask(port, "tec query 0161") == "ERR 30 tec rail is off"
    assert ask(port, "rail tec on") == "OK 00 tec=1"
    assert ask(port, "tec query 0161") == "ERR 31 tec no reply within 300 ms"


def test_tec_pass_through(built: None, tec_pty: tuple[int, str]) -> None:
    master, path = tec_pty
    frame = b"\x01j00" + b"%02X" % ((sum(b"j00") + 1) & 0xFF)
    answer = b"\x01j02OK" + b"%02X" % ((sum(b"j02OK") + 1) & 0xFF) + b"\r\n"
    with (
        FirmwareTeensy(uart1=path, build=False) as sim,
        serial.Serial(sim.port, timeout=REPLY_TIMEOUT_S) as link,
    ):
        assert ask(link, "rail tec on") == "OK 00 tec=1"
        assert ask(link, f"tec send {frame.hex()}") == f"OK 00 sent={len(frame)}"
        assert _read_exactly(master, len(frame)) == frame

        link.write(f"#q tec query {frame.hex()}\n".encode())
        assert _read_exactly(master, len(frame)) == frame
        os.write(master, answer)
        reply = link.readline().decode("ascii").rstrip("\r\n")
        assert reply == f"OK 00 #q {answer.hex().upper()}"
        assert bytes.fromhex(reply.split()[-1]) == answer


def test_launcher_reports_a_program_that_dies(built: None, tmp_path: Path) -> None:
    teensy = FirmwareTeensy(uart1=str(tmp_path / "no-such-tty"), build=False)
    with pytest.raises(ReceiverError, match="exited with code 1"):
        teensy.start()
    teensy.close()
    with pytest.raises(ReceiverError, match="not started"):
        teensy.hang()


def _read_exactly(fd: int, size: int) -> bytes:
    data = b""
    while len(data) < size:
        ready, _, _ = select.select([fd], [], [], REPLY_TIMEOUT_S)
        assert ready, f"only {data!r} arrived"
        data += os.read(fd, size - len(data))
    return data


def test_a_restart_while_instruments_sync_sees_its_terminal(sim: FirmwareTeensy) -> None:
    """The simulated instruments call ``sync()`` from their own threads, all the time. One
    that caught a restarted program before its output was non-blocking read its first
    lines and then blocked, holding the read lock: ``start()`` saw no PTY line for 10 s
    (CI, the monitor's unplug test). Each restart here has a thread syncing throughout."""
    stop = threading.Event()

    def syncing() -> None:
        while not stop.is_set():
            sim.sync()

    sim.start_timeout_s = 3.0
    for _ in range(20):
        sim.close()
        worker = threading.Thread(target=syncing)
        worker.start()
        try:
            sim.start()
            with serial.Serial(sim.port, timeout=REPLY_TIMEOUT_S) as link:
                assert ask(link, "#r ping") == "OK 00 #r pong"
        finally:
            stop.set()
            worker.join()
            stop.clear()
