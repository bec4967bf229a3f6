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
"""

from __future__ import annotations

import contextlib
import logging
import socket
import sys

from reach_receiver.errors import ConnectionLost, DeviceTimeout, ReceiverError

logger = logging.getLogger(__name__)

# Linux's SO_RCVBUFFORCE (asm-generic/socket.h); the socket module does not export it.
_SO_RCVBUFFORCE = 33


class UdpReceiver:
    """A bound UDP socket read with ``recv_into`` and a finite timeout.

    Parameters
    ----------
    host
        Local address to bind (``"0.0.0.0"`` for all interfaces, ``"127.0.0.1"`` for tests).
    port
        Local UDP port; 0 lets the kernel choose (read it back from :attr:`address`).
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
        device: str = "itpm",
        rcvbuf_bytes: int = 64 * 1024 * 1024,
        timeout_s: float = 1.0,
    ) -> None:
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be positive, got {timeout_s}")
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

    def recv_into(self, buffer: bytearray | memoryview, timeout_s: float | None = None) -> int:
        """Receive one datagram into ``buffer``; return its length in bytes.

        A datagram longer than ``buffer`` is truncated by the kernel to the buffer's size,
        so pass a buffer one byte longer than the longest valid datagram to detect that.

        Raises
        ------
        DeviceTimeout
            Nothing arrived within ``timeout_s`` (the default one when None).
        ConnectionLost
            The socket failed.
        """
        sock = self._socket("recv")
        wait = self.timeout_s if timeout_s is None else timeout_s
        if wait != self._current_timeout:
            sock.settimeout(wait)
            self._current_timeout = wait
        try:
            return sock.recv_into(buffer)
        except TimeoutError as err:
            raise DeviceTimeout(self.device, f"no datagram within {wait:g} s", "recv") from err
        except OSError as err:
            raise ConnectionLost(self.device, f"UDP receive failed: {err}", "recv") from err

    def recv_into_nowait(self, buffer: bytearray | memoryview) -> int:
        """Receive one queued datagram into ``buffer`` without waiting; 0 when none is queued."""
        sock = self._socket("recv")
        # A socket with a timeout polls before reading even with MSG_DONTWAIT: make it
        # non-blocking (timeout 0) instead; the next recv_into restores its timeout.
        if self._current_timeout != 0.0:
            sock.settimeout(0.0)
            self._current_timeout = 0.0
        try:
            return sock.recv_into(buffer)
        except BlockingIOError:
            return 0
        except OSError as err:
            raise ConnectionLost(self.device, f"UDP receive failed: {err}", "recv") from err
