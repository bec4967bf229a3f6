"""Copper Mountain TR1300/1 vector network analyser: S11 sweeps and one-port SOL calibration.

The VNA measures the reflection coefficients of the calibration sources, the LNA and the
antenna (thesis sec. 2.1.1). It is calibrated with short, open and load standards on
switch MS2 positions 3-5, then checked against a 50 ohm test load (MS2 position 6,
thesis table A.2); a deviation above 5 % triggers a re-calibration (thesis sec. 2.1.1,
2.1.3). The scheduler owns the switches: :meth:`Vna.calibrate_sol` calls back between
standards so that it can move MS2.

SCPI used (Copper Mountain TRVNA software, socket server on port 5025; design.md):

* sweep: ``SENS1:FREQ:STAR/STOP``, ``SENS1:SWE:POIN``, ``SENS1:BWID``, ``SOUR1:POW``,
  ``SENS1:AVER``, ``SENS1:AVER:COUN``, ``TRIG:SEQ:AVER`` (one trigger runs all averages),
  ``CALC1:PAR1:DEF S11``; each is read back after writing;
* measurement: ``TRIG:SOUR BUS``, ``TRIG:SEQ:SING``, ``*OPC?``, then ``SENS1:FREQ:DATA?``
  and ``CALC1:TRAC1:DATA:SDAT?`` (corrected data, re/im interleaved);
* calibration: ``SENS1:CORR:COLL:METH:SOLT1 1``, ``SENS1:CORR:COLL:{SHOR,OPEN,LOAD} 1``,
  ``SENS1:CORR:COLL:SAVE`` (each followed by ``*OPC?``), ``SENS1:CORR:STAT?``, and
  ``SENS1:CORR:STAT 0|1`` for raw sweeps (the host-side path, :mod:`.vna_host_cal`);
* state files: ``MMEM:STOR:STYP CST``, ``MMEM:STOR "<name>"``, ``MMEM:LOAD "<name>"``;
* errors: ``SYST:ERR?`` answering ``<code>,"<message>"`` until ``0,"No error"`` when the
  software supports it (unconfirmed for TRVNA, so a silent instrument is coped with).

Retry policy: a query that only reads is repeated once after a reconnect when the link
drops, times out or returns garbage; a sweep is re-triggered from the start (never
returned half-read); ``SENS1:CORR:COLL:SAVE`` is never repeated. The link's rules
(``*OPC?``, the error queue, the retry) are :mod:`reach_receiver.devices.vna_link`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TypeVar

import numpy as np

from reach_receiver.clock import Clock, SystemClock
from reach_receiver.devices.vna_link import MessageTransport, ScpiLink
from reach_receiver.devices.vna_settings import (
    AVERAGES_RANGE,
    F_MAX_HZ,
    F_MIN_HZ,
    IFBW_STEPS_HZ,
    POINTS_RANGE,
    POWER_RANGE_DBM,
    POWER_STEP_DB,
    ComplexArray,
    FloatArray,
    S11Measurement,
    ScpiErrorEntry,
    SweepSettings,
)
from reach_receiver.errors import (
    ConfigError,
    DeviceError,
    ProtocolError,
)
from reach_receiver.transports.scpi import ScpiTransport

__all__ = [
    "AVERAGES_RANGE",
    "F_MAX_HZ",
    "F_MIN_HZ",
    "IFBW_STEPS_HZ",
    "POINTS_RANGE",
    "POWER_RANGE_DBM",
    "POWER_STEP_DB",
    "STANDARDS",
    "ComplexArray",
    "FloatArray",
    "S11Measurement",
    "ScpiErrorEntry",
    "SweepSettings",
    "Vna",
]

log = logging.getLogger(__name__)

T = TypeVar("T")

STANDARDS = ("short", "open", "load")

_STANDARD_NODE = {"short": "SHOR", "open": "OPEN", "load": "LOAD"}


class Vna(ScpiLink):
    """Driver of the Copper Mountain TR1300/1 over SCPI.

    Parameters
    ----------
    transport
        A :class:`MessageTransport`, or a VISA address (``TCPIP0::<host>::5025::SOCKET``)
        from which a :class:`ScpiTransport` is built. No I/O happens here.
    timeout_s
        Deadline of ordinary replies.
    clock
        Stamps measurements; the wall clock by default.
    opc_margin_s
        Added to the scaled sweep time when waiting for ``*OPC?``.
    sweep_time_factor
        Sweep timeout = ``factor * points * averages / IFBW + opc_margin_s``; covers the
        per-point overheads the nominal time leaves out.
    error_query_timeout_s
        Deadline of ``SYST:ERR?``; a silence this long marks the queue unsupported.
    cal_kit
        Calibration kit number of the TRVNA software, selected with
        ``SENS1:CORR:COLL:CKIT`` before a calibration (REACH's first code used 23); None
        leaves the software's selection alone.
    name
        Device name in messages.
    """

    def __init__(
        self,
        transport: MessageTransport | str,
        timeout_s: float = 5.0,
        *,
        clock: Clock | None = None,
        opc_margin_s: float = 10.0,
        sweep_time_factor: float = 1.5,
        error_query_timeout_s: float = 1.0,
        cal_kit: int | None = None,
        name: str = "vna",
    ) -> None:
        if isinstance(transport, str):
            transport = ScpiTransport(transport, device=name, timeout_s=timeout_s)
        self._transport = transport
        self.timeout_s = timeout_s
        self._clock: Clock = clock if clock is not None else SystemClock()
        self.opc_margin_s = opc_margin_s
        self.sweep_time_factor = sweep_time_factor
        self.error_query_timeout_s = error_query_timeout_s
        self.cal_kit = cal_kit
        self.name = name
        self.idn = ""
        self.settings: SweepSettings | None = None
        self._error_queue: bool | None = None
        self._collected: set[str] = set()

    # --- life cycle ---------------------------------------------------------------------
    def connect(self) -> str:
        """Open the link, read ``*IDN?`` and check it is a Copper Mountain VNA.

        Stale entries of the error queue are read and logged. Returns the IDN reply.
        """
        self._transport.open()
        idn = self._retry("read *IDN?", lambda: self._transport.query("*IDN?"))
        fields = [f.strip() for f in idn.split(",")]
        maker = fields[0].upper() if fields else ""
        if len(fields) < 2 or not (maker == "CMT" or "COPPER MOUNTAIN" in maker):
            raise DeviceError(self.name, f"not a Copper Mountain VNA: {idn!r}", "*IDN?")
        if not fields[1].upper().startswith("TR1300"):
            log.warning("%s: expected a TR1300/1, found %s; carrying on", self.name, fields[1])
        self.idn = idn
        for entry in self.errors():
            log.warning("%s: stale error on connect: %s", self.name, entry)
        return idn

    def close(self) -> None:
        """Close the link."""
        self._transport.close()

    def __enter__(self) -> Vna:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- settings -----------------------------------------------------------------------
    def configure(self, settings: SweepSettings) -> None:
        """Write every setting, read each back, and raise if the instrument disagrees.

        Raises
        ------
        DeviceError
            Naming each setting that reads back differently, with the error queue.
        """

        def write_all() -> None:
            averaging = int(settings.averages > 1)
            for command in (
                "CALC1:PAR:COUN 1",
                "CALC1:PAR1:DEF S11",
                f"SENS1:FREQ:STAR {settings.f_start_hz:.12g}",
                f"SENS1:FREQ:STOP {settings.f_stop_hz:.12g}",
                f"SENS1:SWE:POIN {settings.points}",
                f"SENS1:BWID {settings.ifbw_hz:.12g}",
                f"SOUR1:POW {settings.power_dbm:.12g}",
                f"SENS1:AVER:COUN {settings.averages}",
                f"SENS1:AVER {averaging}",
                f"TRIG:SEQ:AVER {averaging}",
                "TRIG:SOUR BUS",
            ):
                self._transport.write(command)
            self._wait_opc(self.timeout_s)

        self._retry("configure", write_all)
        actual = self.read_settings()
        mismatches = _compare(settings, actual)
        trigger = self._retry("read TRIG:SOUR?", lambda: self._transport.query("TRIG:SOUR?"))
        if not trigger.strip().upper().startswith("BUS"):
            mismatches.append(("TRIG:SOUR", f"set BUS, reads back {trigger!r}"))
        if mismatches:
            errors = self.errors()
            detail = "; ".join(f"{cmd} {what}" for cmd, what in mismatches)
            queue = f"; error queue: {', '.join(map(str, errors))}" if errors else ""
            message = f"instrument disagrees with the settings: {detail}{queue}"
            raise DeviceError(self.name, message, mismatches[0][0])
        self.settings = settings

    def read_settings(self) -> SweepSettings:
        """The sweep settings the instrument holds now.

        Raises
        ------
        ProtocolError
            If a reply is not a number, or the values are not valid settings.
        """

        def read() -> SweepSettings:
            values = {
                cmd: self._query_number(cmd)
                for cmd in (
                    "SENS1:FREQ:STAR?",
                    "SENS1:FREQ:STOP?",
                    "SENS1:SWE:POIN?",
                    "SENS1:BWID?",
                    "SOUR1:POW?",
                    "SENS1:AVER?",
                    "SENS1:AVER:COUN?",
                )
            }
            try:
                return SweepSettings(
                    f_start_hz=values["SENS1:FREQ:STAR?"],
                    f_stop_hz=values["SENS1:FREQ:STOP?"],
                    points=round(values["SENS1:SWE:POIN?"]),
                    ifbw_hz=values["SENS1:BWID?"],
                    power_dbm=values["SOUR1:POW?"],
                    averages=round(values["SENS1:AVER:COUN?"]) if values["SENS1:AVER?"] else 1,
                )
            except ConfigError as err:
                raise ProtocolError(self.name, f"instrument holds {err}") from err

        return self._retry("read settings", read)

    # --- measurement --------------------------------------------------------------------
    def measure_s11(self) -> S11Measurement:
        """Trigger one (averaged) sweep and return validated, complete S11 data.

        Raises
        ------
        ProtocolError
            Wrong number of frequencies or values, non-finite data, or a grid that is not
            the configured one, on the retry as well.
        DeviceTimeout, ConnectionLost
            When the retry fails the same way.
        """
        settings = self.settings if self.settings is not None else self.read_settings()
        self.settings = settings
        calibrated = self.calibration_active()

        def sweep() -> S11Measurement:
            timestamp = self._clock.now()
            self._transport.write("TRIG:SEQ:SING")
            self._wait_opc(self._sweep_timeout_s(settings))
            freq = self._transport.query_floats("SENS1:FREQ:DATA?")
            data = self._transport.query_floats("CALC1:TRAC1:DATA:SDAT?")
            s11 = self._validate(settings, freq, data)
            return S11Measurement(freq, s11, settings, timestamp, self.idn, calibrated)

        return self._retry("S11 sweep", sweep)

    def calibration_active(self) -> bool:
        """Whether the instrument applies error correction (``SENS1:CORR:STAT?``)."""
        return bool(self._retry("read correction", lambda: self._query_number("SENS1:CORR:STAT?")))

    def set_correction(self, on: bool) -> None:
        """Switch the instrument's error correction (``SENS1:CORR:STAT``) and check it took.

        Switching it on without a calibration leaves it off; that raises.
        """
        self._retry("set correction", lambda: self._command(f"SENS1:CORR:STAT {int(on)}"))
        if self.calibration_active() != on:
            raise DeviceError(self.name, f"correction did not turn {'on' if on else 'off'}")

    # --- calibration --------------------------------------------------------------------
    def start_sol(self) -> None:
        """Begin a one-port short-open-load calibration of port 1."""
        self._collected.clear()

        def start() -> None:
            if self.cal_kit is not None:
                self._transport.write(f"SENS1:CORR:COLL:CKIT {self.cal_kit}")
            self._command("SENS1:CORR:COLL:METH:SOLT1 1")

        self._retry("start SOL", start)

    def measure_standard(self, standard: str) -> None:
        """Measure the standard now connected: ``"short"``, ``"open"`` or ``"load"``.

        Repeated once after a dropped link: the scheduler has not moved the switch yet,
        so measuring again measures the same standard.
        """
        if standard not in _STANDARD_NODE:
            raise ValueError(f"{self.name}: unknown standard {standard!r}; use {STANDARDS}")
        settings = self.settings if self.settings is not None else self.read_settings()
        command = f"SENS1:CORR:COLL:{_STANDARD_NODE[standard]} 1"
        timeout = self._sweep_timeout_s(settings)
        self._retry(f"measure {standard}", lambda: self._command(command, timeout))
        self._collected.add(standard)

    def save_calibration(self) -> None:
        """Compute and apply the calibration (``SENS1:CORR:COLL:SAVE``); never repeated.

        Raises
        ------
        DeviceError
            If a standard is missing, or correction is not on afterwards.
        """
        missing = [s for s in STANDARDS if s not in self._collected]
        if missing:
            message = f"calibration incomplete, not measured: {', '.join(missing)}"
            raise DeviceError(self.name, message, "SENS1:CORR:COLL:SAVE")
        self._command("SENS1:CORR:COLL:SAVE")
        self._collected.clear()
        if not self.calibration_active():
            errors = ", ".join(map(str, self.errors()))
            message = f"correction is off after saving the calibration; errors: {errors or '-'}"
            raise DeviceError(self.name, message, "SENS1:CORR:COLL:SAVE")

    def calibrate_sol(self, connect_standard: Callable[[str], None]) -> None:
        """Full SOL calibration; ``connect_standard(name)`` switches MS2 before each standard."""
        self.start_sol()
        for standard in STANDARDS:
            connect_standard(standard)
            self.measure_standard(standard)
        self.save_calibration()

    # --- state files --------------------------------------------------------------------
    def save_state(self, filename: str, with_calibration: bool = True) -> None:
        """Save settings (and calibration tables) to a state file on the instrument PC."""
        stype = "CST" if with_calibration else "STAT"
        name = _quoted(filename)

        def save() -> None:
            self._transport.write(f"MMEM:STOR:STYP {stype}")
            self._command(f"MMEM:STOR {name}")

        self._retry("save state", save)
        self._raise_on_errors(f"MMEM:STOR {name}")

    def recall_state(self, filename: str) -> SweepSettings:
        """Load a state file and return the settings it holds.

        Raises
        ------
        DeviceError
            If the instrument reports an error (a missing file, for example).
        """
        command = f"MMEM:LOAD {_quoted(filename)}"
        self._retry("recall state", lambda: self._command(command))
        self._raise_on_errors(command)
        self.settings = self.read_settings()
        return self.settings

    # --- sweeps ------------------------------------------------------------------------
    def _sweep_timeout_s(self, settings: SweepSettings) -> float:
        return self.sweep_time_factor * settings.nominal_duration_s() + self.opc_margin_s

    def _validate(
        self, settings: SweepSettings, freq: FloatArray, data: FloatArray
    ) -> ComplexArray:
        n = settings.points
        where = "CALC1:TRAC1:DATA:SDAT?"
        if freq.size != n:
            message = f"{freq.size} frequencies for {n} points"
            raise ProtocolError(self.name, message, "SENS1:FREQ:DATA?")
        if data.size != 2 * n:
            raise ProtocolError(self.name, f"{data.size} values for {n} complex points", where)
        if not (np.all(np.isfinite(freq)) and np.all(np.isfinite(data))):
            raise ProtocolError(self.name, "non-finite values in the sweep", where)
        expected = settings.frequencies()
        if np.max(np.abs(freq - expected)) > 10.0:
            message = "frequency grid is not the configured one (settings changed?)"
            raise ProtocolError(self.name, message, "SENS1:FREQ:DATA?")
        return data[0::2] + 1j * data[1::2]


def _compare(wanted: SweepSettings, actual: SweepSettings) -> list[tuple[str, str]]:
    checks = (
        ("SENS1:FREQ:STAR", wanted.f_start_hz, actual.f_start_hz, 1.0),
        ("SENS1:FREQ:STOP", wanted.f_stop_hz, actual.f_stop_hz, 1.0),
        ("SENS1:SWE:POIN", wanted.points, actual.points, 0.0),
        ("SENS1:BWID", wanted.ifbw_hz, actual.ifbw_hz, 1e-6 * wanted.ifbw_hz),
        ("SOUR1:POW", wanted.power_dbm, actual.power_dbm, POWER_STEP_DB / 2),
        ("SENS1:AVER:COUN", wanted.averages, actual.averages, 0.0),
    )
    return [
        (cmd, f"set {want:g}, reads back {got:g}")
        for cmd, want, got, tolerance in checks
        if abs(want - got) > tolerance
    ]


def _quoted(filename: str) -> str:
    if not filename or any(c in filename for c in '"\n\r'):
        raise ValueError(f"unusable state file name {filename!r}")
    return f'"{filename}"'
