r"""SCPI transport: newline-terminated messages over a raw TCP socket, through pyvisa-py.

The Copper Mountain VNA software serves SCPI on a plain TCP socket (port 5025), which
VISA names ``TCPIP0::<host>::<port>::SOCKET``. Every message ends in ``\n``; ASCII data
blocks are comma-separated numbers on one line. This class opens the resource with the
pure-Python backend (``'@py'``), applies a finite timeout to every read, and maps pyvisa's
failures onto :mod:`reach_receiver.errors` with the command that was being served.

pyvisa-py (0.8) reports a peer that closed its socket as a read *timeout*: its socket
reader takes an empty ``recv`` for "no data yet". So after every timeout the transport
peeks at the socket (``MSG_PEEK | MSG_DONTWAIT``): an orderly end of stream means the
link dropped (:class:`ConnectionLost`), anything else is a genuine
:class:`DeviceTimeout`. Long operations (``*OPC?`` after a sweep) are waited for in short
slices with that check in between, so a drop during a sweep is seen at once rather than
after the whole sweep timeout.
"""

from __future__ import annotations

import logging
import socket
import time
from typing import Any

import numpy as np
import pyvisa
import pyvisa.constants
import pyvisa.errors
from numpy.typing import NDArray

from reach_receiver.errors import ConnectionLost, DeviceTimeout, ProtocolError, ReceiverError

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]


def socket_address(host: str, port: int) -> str:
    """The VISA resource name of a raw SCPI socket: ``TCPIP0::<host>::<port>::SOCKET``."""
    return f"TCPIP0::{host}::{port}::SOCKET"


def parse_floats(text: str) -> FloatArray:
    """Parse an ASCII data block of comma-separated numbers.

    Raises
    ------
    ValueError
        If any field is not a number (an empty reply parses as an empty array).
    """
    stripped = text.strip()
    if not stripped:
        return np.zeros(0)
    return np.array([float(field) for field in stripped.split(",")], dtype=float)


class ScpiTransport:
    """A message channel to one SCPI instrument on a TCP socket.

    Parameters
    ----------
    address
        VISA resource name, ``TCPIP0::<host>::<port>::SOCKET``.
    device
        The instrument's name, used in error messages.
    timeout_s
        Default deadline of one read (finite).
    backend
        pyvisa backend; ``'@py'`` (pyvisa-py) everywhere in this project.
    """

    def __init__(
        self, address: str, device: str = "scpi", timeout_s: float = 5.0, backend: str = "@py"
    ) -> None:
        if not timeout_s > 0:
            raise ValueError(f"{device}: timeout must be positive, got {timeout_s}")
        self.address = address
        self.device = device
        self.timeout_s = float(timeout_s)
        self.backend = backend
        self._manager: pyvisa.ResourceManager | None = None
        self._resource: Any = None

    @property
    def is_open(self) -> bool:
        """Whether a session is open."""
        return self._resource is not None

    def open(self) -> None:
        """Connect the socket (no message is exchanged)."""
        if self.is_open:
            return
        manager = pyvisa.ResourceManager(self.backend)
        try:
            resource = manager.open_resource(
                self.address,
                read_termination="\n",
                write_termination="\n",
                timeout=self._ms(self.timeout_s),
                open_timeout=self._ms(self.timeout_s),
            )
        # pyvisa-py raises a bare Exception("could not connect: ...") for a refused socket.
        except Exception as err:
            manager.close()
            message = f"cannot connect to {self.address}: {err}"
            raise ConnectionLost(self.device, message) from err
        self._manager = manager
        self._resource = resource
        sock = self._socket()
        if sock is not None:
            # A command and the *OPC? after it are two small writes: without this, Nagle's
            # algorithm holds the second back for the peer's delayed ACK (~40 ms).
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def close(self) -> None:
        """Close the session; closing a closed transport does nothing."""
        resource, manager = self._resource, self._manager
        self._resource = None
        self._manager = None
        try:
            if resource is not None:
                resource.close()
        except (pyvisa.errors.Error, OSError) as err:
            log.debug("%s: error while closing %s: %s", self.device, self.address, err)
        finally:
            if manager is not None:
                manager.close()

    def reconnect(self) -> None:
        """Drop the session and open a fresh one; stale replies are left behind with it."""
        log.info("%s: reconnecting to %s", self.device, self.address)
        self.close()
        self.open()

    def write(self, command: str) -> None:
        """Send one command."""
        resource = self._session(command)
        try:
            resource.write(command)
        except (pyvisa.errors.Error, OSError) as err:
            raise ConnectionLost(self.device, f"write failed: {err}", command) from err

    def query(self, command: str, timeout_s: float | None = None) -> str:
        """Send ``command`` and return its one-line reply, without the terminator.

        Raises
        ------
        DeviceTimeout
            No complete reply within ``timeout_s`` (the default timeout if None).
        ConnectionLost
            The socket failed or the instrument closed it.
        ProtocolError
            The reply is not ASCII text.
        """
        self.write(command)
        return self._read(command, self.timeout_s if timeout_s is None else timeout_s)

    def query_floats(self, command: str, timeout_s: float | None = None) -> FloatArray:
        """Query an ASCII data block and parse it as comma-separated numbers.

        Raises
        ------
        ProtocolError
            If a field is not a number.
        """
        reply = self.query(command, timeout_s)
        try:
            return parse_floats(reply)
        except ValueError as err:
            message = f"reply is not a list of numbers: {reply[:80]!r}"
            raise ProtocolError(self.device, message, command) from err

    def query_long(self, command: str, timeout_s: float, poll_s: float = 0.1) -> str:
        """Query whose short reply comes only after a long operation (``*OPC?``).

        The wait is cut into ``poll_s`` slices with a check of the socket in between, so a
        dropped link raises :class:`ConnectionLost` within a slice. Bytes of a reply that
        straddles a slice boundary would be lost by pyvisa-py, so use this only for replies
        of a few bytes, which arrive in one segment.
        """
        self.write(command)
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            try:
                return self._read(command, max(min(poll_s, remaining), 0.001))
            except DeviceTimeout:
                if time.monotonic() >= deadline:
                    message = f"no reply within {timeout_s:.3g} s"
                    raise DeviceTimeout(self.device, message, command) from None

    def _read(self, command: str, timeout_s: float) -> str:
        resource = self._session(command)
        resource.timeout = self._ms(timeout_s)
        try:
            reply: str = resource.read()
        except pyvisa.errors.VisaIOError as err:
            if err.error_code == pyvisa.constants.StatusCode.error_timeout:
                if self._peer_closed():
                    message = "instrument closed the link"
                    raise ConnectionLost(self.device, message, command) from err
                message = f"no reply within {timeout_s:.3g} s"
                raise DeviceTimeout(self.device, message, command) from err
            raise ConnectionLost(self.device, f"read failed: {err}", command) from err
        except UnicodeDecodeError as err:
            raise ProtocolError(self.device, f"reply is not ASCII: {err}", command) from err
        except (pyvisa.errors.Error, OSError) as err:
            raise ConnectionLost(self.device, f"read failed: {err}", command) from err
        finally:
            if self._resource is not None:
                self._resource.timeout = self._ms(self.timeout_s)
        return reply

    def _socket(self) -> socket.socket | None:
        """The session's socket: a pyvisa-py internal, None where it is not reachable."""
        resource = self._resource
        try:
            sock = resource.visalib.sessions[resource.session].interface
        except (AttributeError, KeyError, TypeError):
            return None
        return sock if isinstance(sock, socket.socket) else None

    def _peer_closed(self) -> bool:
        """Whether the instrument has closed its end of the socket."""
        sock = self._socket()
        if sock is None:
            return False
        try:
            peeked = sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT)
        except BlockingIOError:
            return False
        except OSError:
            return True
        return peeked == b""

    def _session(self, command: str) -> Any:
        if self._resource is None:
            raise ReceiverError(f"{self.device}: not connected to {self.address} ({command!r})")
        return self._resource

    @staticmethod
    def _ms(seconds: float) -> int:
        return max(1, round(seconds * 1000))
