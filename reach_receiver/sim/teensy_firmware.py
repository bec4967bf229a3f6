"""The real front-end firmware, run on the host as a simulated Teensy 3.5.

``firmware/`` builds the C++ core of the Teensy firmware against a host hardware layer
into ``firmware/build/teensy-sim`` (``make -C firmware sim``). That program serves the
Teensy protocol (``firmware/PROTOCOL.md``, version 2) on a pseudo-terminal, so a driver
opens :attr:`FirmwareTeensy.port` with pyserial exactly as it opens ``/dev/ttyACM0``, and
the bytes it exchanges are answered by the code that runs on the board.

The program's side channel (PROTOCOL.md, "Host build as simulator"):

* standard output: ``PTY <path>`` once, then ``PINS <state payload>`` at start and after
  every change of an output, e.g.
  ``PINS ms1=3 ms2=0 ... 12v=1 ... boot=por uptime_ms=52 changes=2 deadman=0``;
* standard output also: ``TXDROP <n>`` when a reply was dropped because nobody read the
  terminal for 70 ms (the board's USB transmit timeout; counted in
  :attr:`FirmwareTeensy.replies_dropped` and logged as a warning);
* standard input: ``I2C <addr> <celsius>`` / ``I2C <addr> fail`` / ``I2C <addr> absent``
  set what a simulated MCP9808 reads, ``HANG`` stops the firmware's main loop so that its
  simulated watchdog resets it (power-on state, ``boot=wdog``);
* ``--uart1 <path>``: the TEC controller's serial device behind ``tec send/query``.

The firmware's dead-man switch runs on the host's real clock, so it trips (and shows as a
``PINS`` line) after its timeout of real time without a request, as on the board.

:class:`FirmwareTeensy` builds the program when it is missing or older than its sources,
starts it, follows its ``PINS`` lines on a reader thread and offers them as :attr:`state`
and through :meth:`on_change` callbacks, so a simulated receiver knows where the switches
point.
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import os
import select
import subprocess
import threading
from collections.abc import Callable
from pathlib import Path
from types import TracebackType

from reach_receiver.errors import ConnectionLost, DeviceTimeout, ReceiverError

logger = logging.getLogger(__name__)

DEVICE = "teensy-sim"
FIRMWARE_DIR = Path(__file__).resolve().parents[2] / "firmware"
"""The firmware tree of a source checkout (the simulator is built from it)."""

_SOURCE_GLOBS = ("core/*.cpp", "core/*.h", "host/*.cpp", "host/*.h", "sim/*.cpp", "Makefile")
_build_lock = threading.Lock()

StateCallback = Callable[[dict[str, str]], None]


def simulator_binary(firmware_dir: Path = FIRMWARE_DIR) -> Path:
    """Path of the simulator program inside ``firmware_dir``."""
    return firmware_dir / "build" / "teensy-sim"


def _is_stale(binary: Path, firmware_dir: Path) -> bool:
    if not binary.exists():
        return True
    built = binary.stat().st_mtime
    sources = (p for pattern in _SOURCE_GLOBS for p in firmware_dir.glob(pattern))
    return any(p.stat().st_mtime > built for p in sources)


def ensure_built(firmware_dir: Path = FIRMWARE_DIR, timeout_s: float = 300.0) -> Path:
    """Build ``teensy-sim`` with ``make -C <firmware_dir> sim`` if missing or out of date.

    Parameters
    ----------
    firmware_dir
        The ``firmware/`` directory of the checkout.
    timeout_s
        Longest time the build may take.

    Returns
    -------
    Path
        The up-to-date simulator program.

    Raises
    ------
    ReceiverError
        The tree is missing or the build failed (the compiler's last lines are quoted).
    """
    binary = simulator_binary(firmware_dir)
    if not (firmware_dir / "Makefile").exists():
        raise ReceiverError(
            f"{DEVICE}: no firmware sources at {firmware_dir}: the simulated Teensy is the "
            "firmware's host build, so the simulator runs from a source checkout installed "
            "with 'pip install -e .'"
        )
    binary.parent.mkdir(parents=True, exist_ok=True)
    # A thread lock within this process, a file lock between processes (parallel tests).
    with _build_lock, open(binary.parent / ".teensy-sim.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not _is_stale(binary, firmware_dir):
            return binary
        logger.info("%s: building %s", DEVICE, binary)
        try:
            done = subprocess.run(
                ["make", "-C", str(firmware_dir), "sim"],
                capture_output=True,
                text=True,
                timeout=timeout_s,
                check=False,
            )
        except (OSError, subprocess.TimeoutExpired) as err:
            raise ReceiverError(f"{DEVICE}: cannot run make: {err}") from err
        if done.returncode != 0:
            tail = "\n".join((done.stdout + done.stderr).splitlines()[-15:])
            raise ReceiverError(f"{DEVICE}: build failed (make sim):\n{tail}")
    return binary


def parse_pins(payload: str) -> dict[str, str]:
    """Split a ``state`` payload (``ms1=3 ... deadman=0``) into a name -> value dict."""
    return dict(field.split("=", 1) for field in payload.split() if "=" in field)


class FirmwareTeensy:
    """The firmware simulator as a child process, with its pins followed live.

    Parameters
    ----------
    uart1
        Serial device of the (simulated) TEC controller for ``tec send/query``; ``None``
        leaves UART1 unconnected, so ``tec query`` times out (``ERR 31``).
    watchdog_ms
        Timeout of the simulated watchdog (the board's is 1000 ms).
    start_timeout_s
        Longest wait for the program to announce its pseudo-terminal.
    firmware_dir
        The ``firmware/`` tree to build from.
    build
        Build (``make``) the program first when missing or older than its sources.

    Notes
    -----
    Nothing happens in the constructor; :meth:`start` (or ``with``) launches the program.
    Callbacks registered with :meth:`on_change` run on the reader thread.
    """

    def __init__(
        self,
        uart1: str | None = None,
        *,
        watchdog_ms: int = 1000,
        start_timeout_s: float = 10.0,
        firmware_dir: Path = FIRMWARE_DIR,
        build: bool = True,
    ) -> None:
        self.uart1 = uart1
        self.watchdog_ms = watchdog_ms
        self.start_timeout_s = start_timeout_s
        self.firmware_dir = firmware_dir
        self.build = build
        self._proc: subprocess.Popen[bytes] | None = None
        self._read_lock = threading.Lock()
        self._pending = b""
        self._eof = False
        self._reader: threading.Thread | None = None
        self._port: str | None = None
        self._started = threading.Event()
        self._changed = threading.Condition()
        self._state: dict[str, str] = {}
        self._callbacks: list[StateCallback] = []
        self._stdin_lock = threading.Lock()
        self.replies_dropped = 0
        """Replies the program dropped since start: its terminal stayed full for 70 ms."""

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        """Build if needed, launch the program and wait for its terminal and first state.

        Raises
        ------
        ReceiverError
            The build failed, or the program could not be started or exited at once
            (for example an unusable ``uart1`` path).
        DeviceTimeout
            The program did not announce its terminal within ``start_timeout_s``.
        """
        if self._proc is not None:
            return
        with self._changed:
            self._state = {}
        self._pending, self._eof = b"", False
        self.replies_dropped = 0
        binary = (
            ensure_built(self.firmware_dir) if self.build else simulator_binary(self.firmware_dir)
        )
        args = [str(binary), "--watchdog-ms", str(self.watchdog_ms)]
        if self.uart1 is not None:
            args += ["--uart1", self.uart1]
        try:
            proc = subprocess.Popen(
                args,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                bufsize=0,
                # Its own session: a hang-up or a signal to its owner's process group (a
                # closed terminal, `timeout`) must not end the board before the owner has
                # put the front-end in its safe state; only close() ends it.
                start_new_session=True,
            )
        except OSError as err:
            raise ReceiverError(f"{DEVICE}: cannot start {binary}: {err}") from err
        # Non-blocking before any thread can see the program: sync() from a simulated
        # instrument's thread may read it first, and a blocking read after the first lines
        # held the read lock until the program's end (a restart then saw no PTY line).
        assert proc.stdout is not None
        os.set_blocking(proc.stdout.fileno(), False)
        self._proc = proc
        self._reader = threading.Thread(target=self._read_output, name=DEVICE, daemon=True)
        self._reader.start()
        ready = self._started.wait(self.start_timeout_s) and self._port is not None
        if not ready:
            code = self._exit_code()
            self.close()
            if code is not None:
                raise ReceiverError(f"{DEVICE}: exited with code {code} before its PTY line")
            raise DeviceTimeout(DEVICE, f"no PTY line within {self.start_timeout_s} s", "start")

    def close(self, timeout_s: float = 5.0) -> None:
        """End the program (end of input, then SIGTERM, then SIGKILL) and join the reader."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        with self._stdin_lock:
            if proc.stdin is not None:
                with contextlib.suppress(OSError):  # the program is already gone
                    proc.stdin.close()
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            proc.terminate()
            try:
                proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        if self._reader is not None:
            self._reader.join(timeout_s)
            self._reader = None
        if proc.stdout is not None:
            proc.stdout.close()
        self._port = None
        self._started.clear()

    def __enter__(self) -> FirmwareTeensy:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # ------------------------------------------------------------------ pins
    @property
    def port(self) -> str:
        """Path of the pseudo-terminal to open with pyserial (``/dev/pts/N``)."""
        if self._port is None:
            raise ReceiverError(f"{DEVICE}: not started")
        return self._port

    @property
    def state(self) -> dict[str, str]:
        """The latest ``PINS`` state (a copy): ``{"ms1": "3", "mts": "lna", "12v": "1", ...}``."""
        with self._changed:
            return dict(self._state)

    def on_change(self, callback: StateCallback) -> None:
        """Call ``callback(new_state)`` on every ``PINS`` line (on the reader thread)."""
        with self._changed:
            self._callbacks.append(callback)

    def wait_for_state(
        self, predicate: Callable[[dict[str, str]], bool], timeout_s: float
    ) -> dict[str, str]:
        """Block until ``predicate(state)`` holds and return that state.

        Raises
        ------
        DeviceTimeout
            The predicate did not hold within ``timeout_s``.
        """
        with self._changed:
            if not self._changed.wait_for(lambda: predicate(self._state), timeout_s):
                raise DeviceTimeout(DEVICE, f"state not reached in {timeout_s} s", "PINS")
            return dict(self._state)

    # ------------------------------------------------------------------ faults
    def set_sensor(self, addr: int, celsius: float | None) -> None:
        """Make the MCP9808 at I2C ``addr`` read ``celsius`` (``None``: no sensor there)."""
        value = "absent" if celsius is None else repr(float(celsius))
        self._send(f"I2C {addr:#04x} {value}")

    def fail_sensor(self, addr: int) -> None:
        """Make the MCP9808 at I2C ``addr`` answer with a bus error."""
        self._send(f"I2C {addr:#04x} fail")

    def hang(self) -> None:
        """Stop the firmware's main loop; its watchdog resets it after ``watchdog_ms``."""
        self._send("HANG")

    # ------------------------------------------------------------------ internals
    def _exit_code(self) -> int | None:
        """The program's exit code if its output ended (it died), else ``None``."""
        proc = self._proc
        if proc is None or not self._started.is_set():
            return None  # still silent: a real time-out
        try:  # the reader saw the end of the output: the exit status follows at once
            return proc.wait(1.0)
        except subprocess.TimeoutExpired:
            return None

    def _send(self, line: str) -> None:
        proc = self._proc
        if proc is None or proc.stdin is None:
            raise ReceiverError(f"{DEVICE}: not started")
        with self._stdin_lock:
            try:
                proc.stdin.write((line + "\n").encode())
                proc.stdin.flush()
            except (OSError, ValueError) as err:
                raise ConnectionLost(DEVICE, f"simulator input closed: {err}", line) from err

    def sync(self) -> None:
        """Take in every line the program has written so far, before returning.

        The program reports pin changes before it sends the reply that caused them, so
        after a driver has read a reply, ``sync()`` makes :attr:`state` include its
        effect. The simulated instruments call it before they measure, which removes the
        race between the reader thread and a measurement right after a switch.
        """
        proc = self._proc
        if proc is not None:
            self._drain(proc)

    def _read_output(self) -> None:
        proc = self._proc
        if proc is None or proc.stdout is None:
            return
        fd = proc.stdout.fileno()  # non-blocking since start()
        # Only while this is the current program: a reader that outlives close() (its join
        # timed out on a busy machine) must not touch the next program's state: its end of
        # file or its wake-up would end the next start() before that program's PTY line.
        while not self._eof and proc is self._proc:
            try:
                select.select([fd], [], [], 0.05)
            except (OSError, ValueError):
                break
            self._drain(proc)
        if proc is self._proc:
            self._started.set()  # wake start() if the program died before its PTY line

    def _drain(self, proc: subprocess.Popen[bytes]) -> None:
        if proc.stdout is None:
            return
        with self._read_lock:
            if proc is not self._proc:
                return
            while not self._eof:
                try:
                    chunk = os.read(proc.stdout.fileno(), 65536)
                except BlockingIOError:
                    break
                except (OSError, ValueError):
                    chunk = b""
                if not chunk:
                    self._eof = True
                    break
                self._pending += chunk
            *lines, self._pending = self._pending.split(b"\n")
            for raw in lines:
                self._line(raw.decode("ascii", errors="replace"))

    def _line(self, line: str) -> None:
        if line.startswith("PTY "):
            self._port = line[4:].strip()
        elif line.startswith("TXDROP "):
            count = line[7:].strip()
            self.replies_dropped = int(count) if count.isdigit() else self.replies_dropped + 1
            if self.replies_dropped == 1 or self.replies_dropped % 1000 == 0:  # not one a reply
                logger.warning(
                    "%s: reply dropped: nobody read the terminal for 70 ms (%d so far)",
                    DEVICE, self.replies_dropped,
                )
        elif line.startswith("PINS "):
            self._publish(parse_pins(line[5:]))
            self._started.set()  # started: terminal open and first state known
        elif line:
            logger.info("%s: %s", DEVICE, line)

    def _publish(self, state: dict[str, str]) -> None:
        with self._changed:
            self._state = state
            callbacks = list(self._callbacks)
            self._changed.notify_all()
        for callback in callbacks:
            try:
                callback(dict(state))
            except Exception:  # a faulty observer must not stop the reader
                logger.exception("%s: on_change callback failed", DEVICE)
