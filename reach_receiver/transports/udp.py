"""UDP receive socket: where the iTPM's spectra datagrams arrive.

The iTPM streams its integrated spectra as UDP datagrams to one port of the control
computer (REACH used 4660, ``lessju/reach_control`` ``spectrometer/spectra.py``). The
receiver never answers, so this transport only binds, receives and closes. Two habits
matter for a fast stream read from Python:

* a large kernel receive buffer (``SO_RCVBUF``), so that a burst of 256 packets (one
  spectrum, 280 kB on the wire) queues while the reader is busy. Linux caps the request
  at ``net.core.rmem_max`` unless the process may use ``SO_RCVBUFFORCE``; both are tried
  and what the kernel granted is reported in :attr:`UdpReceiver.rcvbuf_granted`;
* ``recv_into`` a preallocated buffer, so no bytes object is made per datagram.

A bound UDP port takes datagrams from anyone who can reach it, and a datagram's sender
is all that tells the iTPM's spectra from anybody else's. Given the iTPM's ``source``
address (and optionally its port), the receiver reads each datagram's sender
(``recvfrom_into``) and drops every other one: counted in :attr:`UdpReceiver.foreign`,
logged once as a warning and then at most once a minute, never returned. The kernel
could filter on its own (a connected UDP socket), but it would drop them unseen.
"""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import socket
import sys
import time

from reach_receiver.errors import ConnectionLost, DeviceTimeout, ReceiverError

logger = logging.getLogger(__name__)

# Linux's SO_RCVBUFFORCE (asm-generic/socket.h); the socket module does not export it.
_SO_RCVBUFFORCE = 33
#: After the first warning about a foreign sender, at most one warning this often.
FOREIGN_WARNING_INTERVAL_S = 60.0
#: Foreign datagrams one :meth:`UdpReceiver.recv_into_nowait` reads past at most, so a
#: flood cannot keep a caller draining the queue.
_NOWAIT_FOREIGN_LIMIT = 4096


class UdpReceiver:
    """A bound UDP socket read with ``recv_into`` and a finite timeout.

    Parameters
    ----------
    host
        Local address to bind (``"0.0.0.0"`` for all interfaces, ``"127.0.0.1"`` for tests).
    port
        Local UDP port; 0 lets the kernel choose (read it back from :attr:`address`).
    source
        IPv4 address of the only sender whose datagrams are returned; None takes every
        sender's.
    source_port
        With ``source``: the sender's UDP port too (0: any port).
    device
        The instrument's name, used in error messages.
    rcvbuf_bytes
        Receive buffer to request from the kernel.
    timeout_s
        Default deadline of one :meth:`recv_into`, in real seconds.
    """

    def __init__(
        self,
        host: str = "0.0.0.0",
        port: int = 4660,
        *,
        source: str | None = None,
        source_port: int = 0,
        device: str = "itpm",
        rcvbuf_bytes: int = 64 * 1024 * 1024,
        timeout_s: float = 1.0,
    ) -> None:
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be positive, got {timeout_s}")
        if not 0 <= source_port <= 65535:
            raise ValueError(f"source_port must be in [0, 65535], got {source_port}")
        # ValueError for anything but an IPv4 address; written as recvfrom reports it.
        self.source = None if source is None else str(ipaddress.IPv4Address(source))
        self.source_port = source_port
        self.foreign = 0
        """Datagrams from other senders dropped since :meth:`open`."""
        self._warned_at: float | None = None
        self._foreign_at_warning = 0
        self.host = host
        self.port = port
        self.device = device
        self.rcvbuf_bytes = rcvbuf_bytes
        self.timeout_s = timeout_s
        self.rcvbuf_granted = 0
        self._sock: socket.socket | None = None
        self._current_timeout: float | None = None

    @property
    def is_open(self) -> bool:
        """Whether the socket is bound."""
        return self._sock is not None

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port); the kernel's choice when ``port`` was 0."""
        host, port = self._socket("address").getsockname()[:2]
        return str(host), int(port)

    def open(self) -> None:
        """Create and bind the socket and size its receive buffer (nothing is read)."""
        if self._sock is not None:
            return
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, self.rcvbuf_bytes)
            granted = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
            # Linux reports twice the usable size (it counts its bookkeeping too).
            if granted < self.rcvbuf_bytes and sys.platform.startswith("linux"):
                # Without CAP_NET_ADMIN this fails: keep what rmem_max allowed.
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.SOL_SOCKET, _SO_RCVBUFFORCE, self.rcvbuf_bytes)
                granted = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
            sock.bind((self.host, self.port))
            sock.settimeout(self.timeout_s)
        except OSError as err:
            sock.close()
            message = f"cannot bind UDP {self.host}:{self.port}: {err}"
            raise ConnectionLost(self.device, message) from err
        self._sock = sock
        self._current_timeout = self.timeout_s
        self.rcvbuf_granted = int(granted)
        self.foreign = self._foreign_at_warning = 0
        self._warned_at = None
        if granted < self.rcvbuf_bytes:
            logger.warning(
                "%s: asked for a %d-byte UDP receive buffer, the kernel granted %d "
                "(raise net.core.rmem_max)",
                self.device,
                self.rcvbuf_bytes,
                granted,
            )
        else:
            logger.info("%s: UDP receive buffer %d bytes on %s", self.device, granted, self.address)

    def close(self) -> None:
        """Close the socket; closing a closed socket does nothing."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> UdpReceiver:
        self.open()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _socket(self, command: str) -> socket.socket:
        if self._sock is None:
            raise ReceiverError(f"{self.device}: UDP socket is not open (command {command!r})")
        return self._sock

    @property
    def sender(self) -> str:
        """Whose datagrams are returned: ``host:port``, ``host`` (any port) or ``anyone``."""
        if self.source is None:
            return "anyone"
        return f"{self.source}:{self.source_port}" if self.source_port else self.source

    def _accepts(self, sender: tuple[str, int]) -> bool:
        return sender[0] == self.source and (not self.source_port or sender[1] == self.source_port)

    def _drop(self, sender: tuple[str, int]) -> None:
        """Count a foreign datagram; warn at the first, then at most once an interval."""
        self.foreign += 1
        now = time.monotonic()
        if self._warned_at is None:
            logger.warning(
                "%s: dropped a datagram from %s:%d on UDP port %d: only %s sends spectra "
                "(further ones are counted, and reported at most every %g s)",
                self.device, sender[0], sender[1], self.port, self.sender,
                FOREIGN_WARNING_INTERVAL_S,
            )
        elif now - self._warned_at >= FOREIGN_WARNING_INTERVAL_S:
            logger.warning(
                "%s: dropped %d more datagrams from senders other than %s in %.0f s "
                "(the latest from %s:%d)",
                self.device, self.foreign - self._foreign_at_warning, self.sender,
                now - self._warned_at, sender[0], sender[1],
            )
        else:
            return
        self._warned_at = now
        self._foreign_at_warning = self.foreign

    def _set_timeout(self, sock: socket.socket, wait: float) -> None:
        if wait != self._current_timeout:
            sock.settimeout(wait)
            self._current_timeout = wait

    def recv_into(self, buffer: bytearray | memoryview, timeout_s: float | None = None) -> int:
        """Receive one datagram of the source into ``buffer``; return its length in bytes.

        A datagram longer than ``buffer`` is truncated by the kernel to the buffer's size,
        so pass a buffer one byte longer than the longest valid datagram to detect that.
        Datagrams of other senders are dropped (and counted) while waiting.

        Raises
        ------
        DeviceTimeout
            Nothing from the source arrived within ``timeout_s`` (the default one when
            None).
        ConnectionLost
            The socket failed.
        """
        sock = self._socket("recv")
        wait = self.timeout_s if timeout_s is None else timeout_s
        self._set_timeout(sock, wait)
        try:
            if self.source is None:
                return sock.recv_into(buffer)
            deadline = time.monotonic() + wait
            while True:
                nbytes, sender = sock.recvfrom_into(buffer)
                if self._accepts(sender):
                    return nbytes
                self._drop(sender)
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise TimeoutError
                self._set_timeout(sock, remaining)
        except TimeoutError as err:
            message = f"no datagram from {self.sender} within {wait:g} s"
            raise DeviceTimeout(self.device, message, "recv") from err
        except OSError as err:
            raise ConnectionLost(self.device, f"UDP receive failed: {err}", "recv") from err

    def recv_into_nowait(self, buffer: bytearray | memoryview) -> int:
        """Receive one queued datagram of the source without waiting; 0 when none is queued.

        Reads past at most a few thousand foreign datagrams (dropped, counted) and then
        answers 0 as if the queue were empty.
        """
        sock = self._socket("recv")
        # A socket with a timeout polls before reading even with MSG_DONTWAIT: make it
        # non-blocking (timeout 0) instead; the next recv_into restores its timeout.
        self._set_timeout(sock, 0.0)
        try:
            if self.source is None:
                return sock.recv_into(buffer)
            for _ in range(_NOWAIT_FOREIGN_LIMIT):
                nbytes, sender = sock.recvfrom_into(buffer)
                if self._accepts(sender):
                    return nbytes
                self._drop(sender)
            return 0
        except BlockingIOError:
            return 0
        except OSError as err:
            raise ConnectionLost(self.device, f"UDP receive failed: {err}", "recv") from err
