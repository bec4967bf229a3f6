"""Errors raised by the receiver side: transports, drivers, front-end model and simulators.

One root, :class:`ReceiverError`, so that the scheduler and the command line catch every
deliberate failure in one place and print it without a traceback. Subclasses carry the
device and the command involved, so a report names what failed and where.
"""

from __future__ import annotations


class ReceiverError(Exception):
    """Root of every error the receiver package raises on purpose."""


class DeviceError(ReceiverError):
    """A device answered, but not with what was asked for (an error reply, a bad value).

    Parameters
    ----------
    device
        The instrument's name as the operator knows it (``"teensy"``, ``"vna"``...).
    message
        What went wrong, in the operator's words.
    command
        The command or request that was being served, when there was one.
    """

    def __init__(self, device: str, message: str, command: str | None = None) -> None:
        self.device = device
        self.command = command
        where = f" (command {command!r})" if command else ""
        super().__init__(f"{device}: {message}{where}")


class DeviceTimeout(DeviceError):
    """A device did not answer within its configured timeout."""


class ProtocolError(DeviceError):
    """A reply that is garbled, truncated, or fails its checksum."""


class ConnectionLost(DeviceError):
    """The link to a device dropped (socket closed, serial port gone)."""


class InterlockError(ReceiverError):
    """A request that would break a front-end safety rule (table A.3, fig. 2.42)."""


class ConfigError(ReceiverError, ValueError):
    """A site file or other configuration that cannot be used; the message says where."""
