"""The TEC controller reached through the Teensy's second UART (fig. 2.42: RX1/TX1, TEC_EN).

On the deployed front-end the Electron Dynamics controller hangs off the Teensy, not off
its own USB port. This :class:`~reach_receiver.devices.tec.TecLink` carries the TEC's
frames inside the Teensy protocol's ``tec send <hex>`` and ``tec query <hex>``
(``firmware/PROTOCOL.md``); the Teensy does not look inside them, so checksums are still
checked end to end by :class:`~reach_receiver.devices.tec.Tec`.
"""

from __future__ import annotations

from reach_receiver.devices.teensy import Teensy, TeensyError
from reach_receiver.errors import DeviceTimeout, ProtocolError

#: Teensy error codes of the passthrough (PROTOCOL.md): no reply, reply too long.
_TEC_TIMEOUT = 31
_TEC_OVERLONG = 32


class TeensyTecLink:
    """A TEC link that borrows an already connected :class:`Teensy`.

    ``open`` and ``close`` do nothing: the Teensy's life cycle belongs to its owner.
    """

    def __init__(self, teensy: Teensy) -> None:
        self.teensy = teensy

    def open(self) -> None:
        """Nothing to open: the Teensy is connected by its owner."""

    def close(self) -> None:
        """Nothing to close."""

    def exchange(self, frame: bytes, expect_reply: bool, timeout_s: float) -> bytes:
        """Pass ``frame`` through the Teensy; return the reply without ``CR LF`` (or ``b""``).

        The board's "no reply" and "reply too long" become the same errors a direct
        serial link raises, so the TEC driver's retries treat both links alike.
        """
        try:
            if not expect_reply:
                self.teensy.tec_send(frame)
                return b""
            return self.teensy.tec_query(frame, timeout_s=timeout_s)
        except TeensyError as err:
            if err.code == _TEC_TIMEOUT:
                raise DeviceTimeout("tec", "no reply through the Teensy", err.command) from err
            if err.code == _TEC_OVERLONG:
                raise ProtocolError("tec", "reply too long for the Teensy", err.command) from err
            raise
