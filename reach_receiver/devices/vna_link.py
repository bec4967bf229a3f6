"""How the VNA driver talks SCPI: the message channel, ``*OPC?``, ``SYST:ERR?``, retries.

The link's rules, apart from what is measured: every command that starts an operation
waits for ``*OPC?``; the error queue is read until ``0,"No error"`` where the TRVNA
software has one, and an instrument that never answers ``SYST:ERR?`` is marked as having
none (logged once, never asked again); a query that only reads is repeated once after a
reconnect when the link drops, times out or returns garbage, and a failed retry leaves
no late reply behind for the next command.
"""

from __future__ import annotations

import contextlib
import logging
import re
from collections.abc import Callable
from typing import Protocol, TypeVar

import numpy as np

from reach_receiver.devices.vna_settings import FloatArray, ScpiErrorEntry
from reach_receiver.errors import ConnectionLost, DeviceError, DeviceTimeout, ProtocolError

log = logging.getLogger(__name__)

T = TypeVar("T")

_RECOVERABLE = (ConnectionLost, DeviceTimeout, ProtocolError)
_ERROR_REPLY = re.compile(r'^\s*([+-]?\d+)\s*,\s*"(.*)"\s*$')
_MAX_ERROR_READS = 32


class MessageTransport(Protocol):
    """What the driver needs of a message channel (:class:`ScpiTransport` provides it)."""

    def open(self) -> None:
        """Connect."""
        ...

    def close(self) -> None:
        """Disconnect."""
        ...

    def reconnect(self) -> None:
        """Drop the link and open a fresh one."""
        ...

    def write(self, command: str) -> None:
        """Send one command."""
        ...

    def query(self, command: str, timeout_s: float | None = None) -> str:
        """Send a query and return its reply."""
        ...

    def query_floats(self, command: str, timeout_s: float | None = None) -> FloatArray:
        """Send a query and parse its comma-separated numbers."""
        ...

    def query_long(self, command: str, timeout_s: float, poll_s: float = 0.1) -> str:
        """Query whose reply follows a long operation."""
        ...


class ScpiLink:
    """The driver's side of the SCPI link (a base of :class:`~reach_receiver.devices.vna.Vna`).

    The driver sets ``name``, ``timeout_s``, ``error_query_timeout_s``, ``_transport``
    and ``_error_queue`` (``None``: not yet known) in its constructor.
    """

    name: str
    timeout_s: float
    error_query_timeout_s: float
    _transport: MessageTransport
    _error_queue: bool | None

    # --- error queue --------------------------------------------------------------------
    @property
    def error_queue_supported(self) -> bool | None:
        """True or False once known; None before the first ``SYST:ERR?``."""
        return self._error_queue

    def errors(self) -> list[ScpiErrorEntry]:
        """Read ``SYST:ERR?`` until ``0,"No error"`` (at most 32 entries).

        An instrument that does not answer (or answers something else before ever giving
        a well-formed reply) is marked as having no error queue: this is logged once and
        the query is not sent again.
        """
        if self._error_queue is False:
            return []
        entries: list[ScpiErrorEntry] = []
        for _ in range(_MAX_ERROR_READS):
            try:
                reply = self._transport.query("SYST:ERR?", self.error_query_timeout_s)
            except DeviceTimeout:
                if self._error_queue:
                    raise
                self._mark_queue_unsupported("no reply")
                self._transport.reconnect()
                return entries
            match = _ERROR_REPLY.match(reply)
            if match is None:
                if self._error_queue:
                    raise ProtocolError(self.name, f"bad error entry {reply!r}", "SYST:ERR?")
                self._mark_queue_unsupported(f"reply {reply!r}")
                return entries
            self._error_queue = True
            code = int(match.group(1))
            if code == 0:
                return entries
            entries.append(ScpiErrorEntry(code, match.group(2)))
        log.warning("%s: error queue not empty after %d reads", self.name, _MAX_ERROR_READS)
        return entries

    # --- helpers ------------------------------------------------------------------------
    def _mark_queue_unsupported(self, why: str) -> None:
        self._error_queue = False
        log.warning("%s: error queue unsupported (SYST:ERR? gave %s)", self.name, why)

    def _raise_on_errors(self, command: str) -> None:
        errors = self.errors()
        if errors:
            message = f"instrument reported: {', '.join(map(str, errors))}"
            raise DeviceError(self.name, message, command)

    def _command(self, command: str, timeout_s: float | None = None) -> None:
        self._transport.write(command)
        self._wait_opc(self.timeout_s if timeout_s is None else timeout_s)

    def _wait_opc(self, timeout_s: float) -> None:
        reply = self._transport.query_long("*OPC?", timeout_s)
        if reply.strip().lstrip("+") != "1":
            raise ProtocolError(self.name, f"unexpected reply {reply!r}", "*OPC?")

    def _query_number(self, command: str) -> float:
        reply = self._transport.query(command)
        try:
            value = float(reply)
        except ValueError as err:
            raise ProtocolError(self.name, f"not a number: {reply!r}", command) from err
        if not np.isfinite(value):
            raise ProtocolError(self.name, f"not finite: {reply!r}", command)
        return value

    def _retry(self, what: str, operation: Callable[[], T]) -> T:
        """Run ``operation``; after a drop, timeout or garbled reply reconnect and run it again."""
        try:
            return operation()
        except _RECOVERABLE as err:
            log.warning("%s: %s failed (%s); reconnecting and retrying once", self.name, what, err)
            self._transport.reconnect()
        try:
            return operation()
        except (DeviceTimeout, ProtocolError):
            # Leave no late or partial reply behind for the next command to read.
            with contextlib.suppress(ConnectionLost):
                self._transport.reconnect()
            raise


__all__ = ["MessageTransport", "ScpiLink"]
