"""A serial driver never takes over a terminal that a simulator's old pty number now names.

A simulated instrument's pseudo-terminal that goes away leaves its number to the next
terminal the kernel opens; a daemon retrying the old path used to open an operator's tmux
pane, put it in raw mode and write its ``#tag ping`` into it (seen when a test's
simulator died under a live ``reachd --sim``). The transport now refuses any port that is
some process's controlling terminal, and still opens an instrument's line.
"""

from __future__ import annotations

import os
import pty
import termios
import time

import pytest

from reach_receiver.devices.teensy import Teensy
from reach_receiver.errors import ConnectionLost
from reach_receiver.transports.serial_port import SerialTransport, terminal_owner


def _modes(path: str) -> list:
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    try:
        return termios.tcgetattr(fd)
    finally:
        os.close(fd)


def _stdin(pid: int) -> str:
    try:
        return os.readlink(f"/proc/{pid}/fd/0")
    except OSError:
        return ""


@pytest.fixture
def terminal():
    """A pty that is a child session's controlling terminal (as a login's or tmux's is)."""
    pid, master = pty.fork()
    if pid == 0:  # the child: a session leader whose terminal is the pty's slave
        time.sleep(30)
        os._exit(0)
    try:
        deadline = time.monotonic() + 10
        while not _stdin(pid).startswith("/dev/pts/"):  # until the child has its terminal
            assert time.monotonic() < deadline
            time.sleep(0.01)
        yield _stdin(pid), pid, master
    finally:
        os.kill(pid, 9)
        os.waitpid(pid, 0)
        os.close(master)


def test_a_session_s_terminal_is_refused_and_left_as_it_was(terminal):
    path, pid, _ = terminal
    assert terminal_owner(path) == pid
    before = _modes(path)
    with pytest.raises(ConnectionLost, match=f"will not open {path}: it is the terminal of "
                                             f"process {pid}"):
        Teensy(path, timeout_s=0.5).connect()
    after = _modes(path)
    assert after == before  # not put in raw mode


def test_an_instrument_s_pty_is_nobody_s_terminal_and_opens():
    master, slave = os.openpty()
    try:
        path = os.ttyname(slave)
        assert terminal_owner(path) is None
        link = SerialTransport(path, "teensy")
        link.open()
        assert link.is_open
        link.close()
    finally:
        os.close(master)
        os.close(slave)


def test_a_missing_port_has_no_owner_and_fails_as_before(tmp_path):
    assert terminal_owner(str(tmp_path / "gone")) is None
    with pytest.raises(ConnectionLost, match="cannot open serial port"):
        SerialTransport(str(tmp_path / "gone"), "teensy").open()
