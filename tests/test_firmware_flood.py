"""The firmware's host build under a flood: replies are slow, never lost to a reading client.

Real pseudo-terminal, real program (``firmware/sim``); the flood is the one of
``benchmarks.firmware_flood``.
"""

import os
import select
import time
import tty

import pytest

from benchmarks.firmware_flood import flood
from reach_receiver.sim.teensy_firmware import FirmwareTeensy


@pytest.fixture
def teensy():
    with FirmwareTeensy() as board:
        yield board


def test_a_flood_read_concurrently_gets_every_reply_whole(teensy):
    result = flood(teensy.port, 10000, command="mix", grace_s=3.0)
    assert (result.received, result.missing, result.garbled) == (10000, 0, 0), result.summary()
    assert (result.unknown, result.repeated, result.errors) == (0, 0, 0)
    assert teensy.replies_dropped == 0


def _read_until_quiet(fd, quiet_s=0.5):
    data = b""
    until = time.monotonic() + quiet_s
    while time.monotonic() < until:
        if select.select([fd], [], [], 0.05)[0]:
            data += os.read(fd, 65536)
            until = time.monotonic() + quiet_s
    return data


def test_a_client_that_stops_reading_loses_whole_replies_each_counted(teensy):
    fd = os.open(teensy.port, os.O_RDWR | os.O_NOCTTY)
    try:
        tty.setraw(fd)
        for i in range(3000):  # 360 kB of replies, nothing read
            os.write(fd, f"#{i} state\n".encode())
        time.sleep(0.5)
        lines = _read_until_quiet(fd).split(b"\r\n")[:-1]
        teensy.sync()
        assert all(line.startswith(b"OK 00 #") and line.count(b"OK") == 1 for line in lines)
        tags = [int(line.split()[2][1:]) for line in lines]
        assert tags == sorted(tags)
        assert 500 < len(lines) < 3000  # what the buffering held (86 kB), in order
        assert teensy.replies_dropped == 3000 - len(lines)
        os.write(fd, b"\n#fresh ping\n")  # resynchronising, as PROTOCOL.md says
        assert _read_until_quiet(fd, 0.3).endswith(b"OK 00 #fresh pong\r\n")
    finally:
        os.close(fd)
