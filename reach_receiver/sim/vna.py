"""Simulated Copper Mountain TR1300/1 behind a real TCP socket, speaking its SCPI subset.

Physics. The port sees a true reflection ``G(f)`` (the ``reflection`` callable: the
front-end decides what is connected). The raw measurement passes it through the one-port
error model (Pozar, *Microwave Engineering*, 4th ed., sec. 4.6; scikit-rf's ``OnePort``)::

    m = e00 + e10e01 G / (1 - e11 G) + n

with directivity ``e00``, source match ``e11`` and reflection tracking ``e10e01`` smooth,
seeded complex functions of frequency. ``n`` is circular complex Gaussian noise of rms
``sigma = noise_ref * sqrt(IFBW / 1 kHz) * 10^((-5 dBm - P) / 20) / sqrt(averages)``.
The error terms drift linearly with the clock's time (``drift_rate_per_s``) and on demand
(:meth:`VnaSimulator.drift_now`), so a calibration ages.

Calibration. ``SENS1:CORR:COLL:{SHOR,OPEN,LOAD} 1`` each measure whatever ``reflection``
returns at that moment (a wrong switch position gives a wrong calibration, as on the
real instrument); ``SENS1:CORR:COLL:SAVE`` solves for the error terms with the engine's
:func:`calibration.rf.one_port.solve_one_port` (the linear system
``m_i = e00 + G_i m_i e11 + G_i D``, ``D = e10e01 - e00 e11``, every frequency at once)
for the ideal standards of :data:`calibration.rf.cal_kit.IDEAL_KIT` (``G = -1, +1, 0``), and
corrected data are ``G = (m - e00) / (e10e01 + e11 (m - e00))``
(:func:`calibration.rf.one_port.correct_reflection`).

Faults on demand (:meth:`VnaSimulator.inject`): no reply, garbled reply, truncated data,
connection drop before or in the middle of a reply, a queued SCPI error; and a mode in
which ``SYST:ERR?`` is an unknown command (unknown queries get no reply, as on SCPI
instruments, and queue ``-113,"Undefined header"``). The SCPI's forms, ranges and reply
formats, and the state ``MMEM:STOR`` saves, are :mod:`reach_receiver.sim.vna_scpi`.
"""

from __future__ import annotations

import contextlib
import copy
import enum
import logging
import socket
import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from calibration.core.errors import CalibrationError
from calibration.rf.cal_kit import IDEAL_KIT
from calibration.rf.one_port import solve_one_port
from reach_receiver.clock import Clock
from reach_receiver.sim.vna_model import ComplexArray, ErrorModel, sweep_duration_s
from reach_receiver.sim.vna_scpi import (
    IFBW_STEPS_HZ,
    ChannelState,
    ascii_values,
    clip,
    flag,
    interleave,
    nearest,
    normalise_header,
    power_level,
)
from reach_receiver.transports.scpi import socket_address

__all__ = [
    "ComplexArray",
    "ErrorModel",
    "Fault",
    "Reflection",
    "VnaSimulator",
    "solve_one_port",
    "sweep_duration_s",
]

log = logging.getLogger(__name__)

Reflection = Callable[[NDArray[np.float64]], NDArray[np.complex128]]
_STANDARDS = ("SHOR", "OPEN", "LOAD")  # the order of calibration.rf.cal_kit.STANDARD_NAMES


class Fault(enum.Enum):
    """Misbehaviours the simulator can be told to show."""

    NO_REPLY = "no reply"
    GARBLED = "garbled reply"
    TRUNCATED = "truncated data"
    DROP_BEFORE_REPLY = "connection dropped before the reply"
    DROP_MID_REPLY = "connection dropped in the middle of the reply"
    SCPI_ERROR = "command rejected with a queued SCPI error"


@dataclass
class _Armed:
    fault: Fault
    header: str | None
    remaining: int


class VnaSimulator:
    """A TR1300/1 on a loopback TCP port, for the :class:`~reach_receiver.devices.vna.Vna` driver.

    Parameters
    ----------
    reflection
        ``reflection(freq_hz) -> complex array``: the true reflection at the VNA port now.
    clock
        Time source: sweeps take their simulated duration on it and drift follows it.
    host, port
        Where to listen (port 0: any free port; see :attr:`address`).
    seed
        Seeds the error-term shapes and the measurement noise.
    drift_rate_per_s
        Fractional change of the error terms per second of clock time (default 1 %/hour).
    noise_ref
        Complex rms noise of one sweep at 1 kHz IFBW and -5 dBm (linear reflection units).
    error_queue_supported
        When False, ``SYST:ERR?`` is an unknown command (never answered).
    idn
        The ``*IDN?`` reply.
    """

    def __init__(
        self,
        reflection: Reflection,
        clock: Clock,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        seed: int = 0,
        drift_rate_per_s: float = 0.01 / 3600.0,
        noise_ref: float = 1e-3,
        error_queue_supported: bool = True,
        idn: str = "CMT,TR1300/1,SIM00001,22.1.4",
    ) -> None:
        self._reflection = reflection
        self._clock = clock
        self._host, self._port = host, port
        self._rng = np.random.default_rng((seed, 2))
        self.model = ErrorModel(seed=seed, drift_rate_per_s=drift_rate_per_s, t0=clock.now())
        self.noise_ref = noise_ref
        self.error_queue_supported = error_queue_supported
        self.idn = idn
        self.triggers = 0
        self.store_type = "STAT"
        self._state = ChannelState()
        self._saved: dict[str, ChannelState] = {}
        self._errors: list[tuple[int, str]] = []
        self._faults: list[_Armed] = []
        self._busy_until = clock.now()
        self._trace: tuple[NDArray[np.float64], ComplexArray] | None = None
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._listener: socket.socket | None = None
        self._threads: list[threading.Thread] = []
        self._clients: list[socket.socket] = []

    # --- life cycle -------------------------------------------------------------------
    @property
    def address(self) -> str:
        """VISA resource name of the listening socket."""
        if self._listener is None:
            raise RuntimeError("simulator not started")
        return socket_address(self._host, self._listener.getsockname()[1])

    def start(self) -> None:
        """Listen and serve in background threads."""
        listener = socket.create_server((self._host, self._port))
        listener.settimeout(0.05)
        self._listener = listener
        self._spawn(self._accept_loop)

    def close(self) -> None:
        """Stop serving, close every socket and join the threads."""
        self._stop.set()
        with self._lock:
            clients, self._clients = self._clients, []
        for client in clients:
            _shut(client)
        for thread in self._threads:
            thread.join(timeout=5.0)
        if self._listener is not None:
            self._listener.close()

    def __enter__(self) -> VnaSimulator:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- test controls ----------------------------------------------------------------
    def inject(self, fault: Fault, on: str | None = None, count: int = 1) -> None:
        """Arm ``fault`` for the next ``count`` commands whose header is ``on`` (any if None)."""
        header = None if on is None else normalise_header(on)
        with self._lock:
            self._faults.append(_Armed(fault, header, count))

    def drift_now(self, amount: float) -> None:
        """Move every error term by the fractional ``amount`` at once."""
        self.model.drift_now(amount)

    def queue_error(self, code: int, message: str) -> None:
        """Put an entry on the SCPI error queue."""
        with self._lock:
            self._errors.append((code, message))

    def noise_sigma(self, ifbw_hz: float, power_dbm: float, averages: int) -> float:
        """Complex rms noise of one raw measurement point (see the module docstring)."""
        scale = np.sqrt(ifbw_hz / 1e3) * 10 ** ((-5.0 - power_dbm) / 20.0)
        return float(self.noise_ref * scale / np.sqrt(max(averages, 1)))

    # --- server -----------------------------------------------------------------------
    def _spawn(self, target: Callable[..., None], *args: object) -> None:
        thread = threading.Thread(target=target, args=args, daemon=True)
        self._threads.append(thread)
        thread.start()

    def _accept_loop(self) -> None:
        assert self._listener is not None
        while not self._stop.is_set():
            try:
                client, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            client.settimeout(0.05)
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._clients.append(client)
            self._spawn(self._serve, client)

    def _serve(self, client: socket.socket) -> None:
        buffer = b""
        try:
            while not self._stop.is_set():
                try:
                    chunk = client.recv(65536)
                except TimeoutError:
                    continue
                if not chunk:
                    return
                buffer += chunk
                while b"\n" in buffer:
                    line, buffer = buffer.split(b"\n", 1)
                    if not self._handle(client, line.decode("ascii", "replace").strip()):
                        return
        except OSError:
            return
        finally:
            with self._lock:
                if client in self._clients:
                    self._clients.remove(client)
            _shut(client)

    def _take_fault(self, header: str) -> Fault | None:
        with self._lock:
            for armed in self._faults:
                if armed.header in (None, header):
                    armed.remaining -= 1
                    if armed.remaining <= 0:
                        self._faults.remove(armed)
                    return armed.fault
        return None

    def _handle(self, client: socket.socket, line: str) -> bool:
        """Serve one message; False when the connection is to be dropped."""
        if not line:
            return True
        head, _, arg = line.partition(" ")
        header = normalise_header(head)
        fault = self._take_fault(header)
        if fault is Fault.SCPI_ERROR:
            self.queue_error(-222, "Data out of range")
            return True
        if fault is Fault.DROP_BEFORE_REPLY:
            return False
        reply = self._execute(header, arg.strip())
        if reply is None or fault is Fault.NO_REPLY:
            return True
        payload = reply.encode("ascii")
        if fault is Fault.GARBLED:
            middle = len(payload) // 2
            payload = payload[:middle] + b"#?@" + payload[middle + 3 :]
        elif fault is Fault.TRUNCATED:
            payload = b",".join(payload.split(b",")[: max(1, payload.count(b",") // 2)])
        elif fault is Fault.DROP_MID_REPLY:
            client.sendall(payload[: max(1, len(payload) // 2)])
            return False
        client.sendall(payload + b"\n")
        return True

    # --- SCPI -------------------------------------------------------------------------
    def _execute(self, header: str, arg: str) -> str | None:
        """Run one command; the reply of a query, None for a command or an unknown query."""
        if header == "*OPC?":
            self._wait_idle()
            return "1"
        with self._lock:
            try:
                return self._dispatch(header, arg)
            except (ValueError, KeyError, IndexError):
                self._errors.append((-224, "Illegal parameter value"))
                return None

    def _dispatch(self, header: str, arg: str) -> str | None:
        s = self._state
        setters: dict[str, Callable[[], None]] = {
            "SENS1:FREQ:STAR": lambda: self._set_freq(start=float(arg)),
            "SENS1:FREQ:STOP": lambda: self._set_freq(stop=float(arg)),
            "SENS1:SWE:POIN": lambda: self._set_grid(points=int(float(arg))),
            "SENS1:BWID": lambda: setattr(s, "ifbw_hz", nearest(float(arg), IFBW_STEPS_HZ)),
            "SOUR1:POW": lambda: setattr(s, "power_dbm", power_level(float(arg))),
            "SENS1:AVER": lambda: setattr(s, "averaging", flag(arg)),
            "SENS1:AVER:COUN": lambda: setattr(s, "average_count", int(clip(int(arg), 1, 999))),
            "TRIG:SOUR": lambda: setattr(s, "trigger_source", arg.upper()[:3]),
            "TRIG:SEQ:AVER": lambda: setattr(s, "trigger_averaging", flag(arg)),
            "CALC1:PAR:COUN": lambda: None,
            "CALC1:PAR1:DEF": lambda: None,
            "SENS1:CORR:COLL:CKIT": lambda: None,
            "SENS1:CORR:STAT": lambda: setattr(s, "correction", flag(arg) and self._has_cal()),
            "SENS1:CORR:COLL:METH:SOLT1": lambda: s.collected.clear(),
            "SENS1:CORR:COLL:SAVE": self._save_cal,
            "TRIG:SEQ:SING": self._trigger,
            "MMEM:STOR:STYP": lambda: setattr(self, "store_type", arg.upper()),
            "MMEM:STOR": lambda: self._store(arg.strip('"')),
            "MMEM:LOAD": lambda: self._load(arg.strip('"')),
            "*CLS": self._errors.clear,
        }
        node = header.rsplit(":", 1)[-1]
        if header.startswith("SENS1:CORR:COLL:") and node in _STANDARDS:
            setters[header] = lambda: self._collect(node)
        queries: dict[str, Callable[[], str]] = {
            "*IDN?": lambda: self.idn,
            "SENS1:FREQ:STAR?": lambda: f"{s.start_hz:.12g}",
            "SENS1:FREQ:STOP?": lambda: f"{s.stop_hz:.12g}",
            "SENS1:SWE:POIN?": lambda: str(s.points),
            "SENS1:BWID?": lambda: f"{s.ifbw_hz:.12g}",
            "SOUR1:POW?": lambda: f"{s.power_dbm:.12g}",
            "SENS1:AVER?": lambda: str(int(s.averaging)),
            "SENS1:AVER:COUN?": lambda: str(s.average_count),
            "TRIG:SOUR?": lambda: s.trigger_source,
            "TRIG:SEQ:AVER?": lambda: str(int(s.trigger_averaging)),
            "SENS1:CORR:STAT?": lambda: str(int(s.correction)),
            "SENS1:FREQ:DATA?": lambda: ascii_values(self._trace_data()[0]),
            "CALC1:TRAC1:DATA:SDAT?": lambda: ascii_values(interleave(self._trace_data()[1])),
        }
        if self.error_queue_supported:
            queries["SYST:ERR?"] = self._pop_error
        if header in setters:
            setters[header]()
            return None
        if header in queries:
            return queries[header]()
        self._errors.append((-113, "Undefined header"))
        return None

    def _set_freq(self, start: float | None = None, stop: float | None = None) -> None:
        s = self._state
        if start is not None:
            s.start_hz = clip(start, 3e5, 1.3e9 - 1)
            s.stop_hz = max(s.stop_hz, s.start_hz + 1)
        if stop is not None:
            s.stop_hz = clip(stop, 3e5 + 1, 1.3e9)
            s.start_hz = min(s.start_hz, s.stop_hz - 1)
        self._set_grid()

    def _set_grid(self, points: int | None = None) -> None:
        s = self._state
        if points is not None:
            s.points = int(clip(points, 2, 16001))
        grid_changed = s.cal_freq_hz is None or s.cal_freq_hz.shape != (s.points,)
        if not grid_changed and s.cal_freq_hz is not None:
            grid_changed = not np.allclose(s.cal_freq_hz, s.freq_hz(), rtol=0, atol=0.5)
        if grid_changed and s.correction:
            log.info("simulated VNA: frequency grid changed, correction turned off")
            s.correction = False

    def _averages(self) -> int:
        s = self._state
        return s.average_count if s.averaging else 1

    def _raw_sweep(self) -> ComplexArray:
        """One raw (uncorrected) sweep of whatever is connected now; sets the busy time."""
        s = self._state
        freq = s.freq_hz()
        truth = np.asarray(self._reflection(freq), dtype=complex)
        if truth.shape != freq.shape:
            raise ValueError("reflection callable returned the wrong shape")
        now = self._clock.now()
        raw = self.model.measure(freq, truth, now)
        sigma = self.noise_sigma(s.ifbw_hz, s.power_dbm, self._averages())
        noise = self._rng.normal(size=(2, freq.size)) * (sigma / np.sqrt(2.0))
        duration = sweep_duration_s(s.points, self._averages(), s.ifbw_hz)
        self._busy_until = max(self._busy_until, now) + duration
        return raw + noise[0] + 1j * noise[1]

    def _trigger(self) -> None:
        s = self._state
        if s.trigger_source != "BUS":
            self._errors.append((-211, "Trigger ignored"))
            return
        self.triggers += 1
        raw = self._raw_sweep()
        data = raw
        if s.correction and s.cal_terms is not None:
            data = s.cal_terms.correct(raw)
        self._trace = (s.freq_hz(), data)

    def _trace_data(self) -> tuple[NDArray[np.float64], ComplexArray]:
        if self._trace is None:
            s = self._state
            return s.freq_hz(), np.zeros(s.points, dtype=complex)
        return self._trace

    def _collect(self, standard: str) -> None:
        self._state.collected[standard] = self._raw_sweep()

    def _has_cal(self) -> bool:
        return self._state.cal_terms is not None

    def _save_cal(self) -> None:
        s = self._state
        if set(s.collected) != set(_STANDARDS):
            self._errors.append((-200, "Execution error; calibration incomplete"))
            return
        measured = np.stack([s.collected[k] for k in _STANDARDS])
        freq = s.freq_hz()
        try:
            s.cal_terms = solve_one_port(measured, IDEAL_KIT.reflections(freq), freq)
        except CalibrationError as exc:
            log.info("simulated VNA: calibration failed: %s", exc)
            self._errors.append((-200, "Execution error; singular calibration"))
            return
        s.cal_freq_hz = s.freq_hz()
        s.correction = True
        s.collected.clear()

    def _store(self, name: str) -> None:
        state = copy.deepcopy(self._state)
        if self.store_type not in ("CST", "CDST"):
            state.cal_terms, state.cal_freq_hz, state.correction = None, None, False
        self._saved[name] = state

    def _load(self, name: str) -> None:
        if name not in self._saved:
            self._errors.append((-256, "File name not found"))
            return
        self._state = copy.deepcopy(self._saved[name])

    def _pop_error(self) -> str:
        if not self._errors:
            return '0,"No error"'
        code, message = self._errors.pop(0)
        return f'{code},"{message}"'

    def _wait_idle(self) -> None:
        """Block this connection until the running sweep ends, in clock time."""
        while not self._stop.is_set():
            with self._lock:
                remaining = self._busy_until - self._clock.now()
            if remaining <= 0:
                return
            self._clock.sleep(min(remaining, max(remaining / 10.0, 1e-3)))


def _shut(sock: socket.socket) -> None:
    with contextlib.suppress(OSError):
        sock.shutdown(socket.SHUT_RDWR)
    sock.close()


