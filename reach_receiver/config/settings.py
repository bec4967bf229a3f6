"""Typed settings of each instrument: the one place for their defaults, units and ranges.

Each class is the schema of one ``devices.<name>`` section of the site file
(:mod:`.site`): a frozen dataclass whose field names carry their units (``timeout_s``,
``period_s``, ``channel_width_hz``), whose defaults are the only defaults the drivers
get, and whose ``metadata`` gives the range a value must lie in. :func:`read_settings`
reads a section against its schema, reporting every mistake as ``file:line: key:
message``; a field without a default must be written.

The spectrometer's accumulation ``period_s`` has no default on purpose: it converts the
seconds a schedule asks for into a count of spectra, and the dry run's timing depends
on it, so a site must say what its spectrometer does (REACH's iTPM: 1 s; the simulated
receiver: longer, to keep the packet rate of a compressed clock manageable).
"""

from __future__ import annotations

import dataclasses
import ipaddress
import typing
from dataclasses import dataclass, field
from typing import Any, Literal, TypeVar

from calibration.core.constants import ITPM_CHANNEL_WIDTH_HZ

from .fields import REQUIRED, Fields

T = TypeVar("T")


def _range(
    low: float | None = None,
    high: float | None = None,
    *,
    open_low: bool = False,
    choices: tuple[object, ...] = (),
) -> dict[str, Any]:
    """Field metadata: the closed (or left-open) range, or the choices, of a value."""
    return {"low": low, "high": high, "open_low": open_low, "choices": choices}


_POSITIVE = _range(0.0, open_low=True)
#: Field metadata: the text must be an IPv4 address written as four numbers.
_IPV4 = {"ipv4": True}
_TIMEOUT = _range(0.0, 600.0, open_low=True)


@dataclass(frozen=True)
class TeensySettings:
    """The front-end microcontroller: its USB serial port, and its dead-man switch.

    ``deadman_s``: after this long without the host, the firmware puts the front-end in
    its safe state on its own (0 = off; otherwise at least 0.1 s); the driver renews it
    every third of it while connected.
    """

    port: str
    timeout_s: float = field(default=1.0, metadata=_TIMEOUT)
    deadman_s: float = field(default=60.0, metadata=_range(0.0, 3600.0))


@dataclass(frozen=True)
class VnaSettings:
    """The VNA: a VISA resource (``TCPIP0::<host>::5025::SOCKET``)."""

    resource: str
    timeout_s: float = field(default=10.0, metadata=_TIMEOUT)


@dataclass(frozen=True)
class TecSettings:
    """The TEC controller: through the Teensy's UART (``via: teensy``) or its own port."""

    via: Literal["teensy", "serial"] = field(
        default="teensy", metadata=_range(choices=("teensy", "serial"))
    )
    port: str | None = None
    timeout_s: float = field(default=1.0, metadata=_TIMEOUT)


@dataclass(frozen=True)
class Tc08Settings:
    """The TC-08: Pico's ``libusbtc08`` (found on the library path by default)."""

    library: str | None = None
    mains_hz: int = field(default=50, metadata=_range(choices=(50, 60)))


@dataclass(frozen=True)
class SpectrometerSettings:
    """The iTPM's spectra: where they arrive, who sends them, how long each integrates.

    ``host`` is the local address bound (the interface on the iTPM's network; 0.0.0.0:
    every interface). ``source`` is the iTPM's own IPv4 address: datagrams from any other
    sender are counted and dropped, never assembled into a spectrum, and ``source_port``
    (0: any) narrows that to the iTPM's sending port. Without a source every sender is
    taken; the driver then logs a warning at each connection unless it listens on
    loopback only (where only this computer's processes can send).
    """

    period_s: float = field(metadata=_range(0.0, 3600.0, open_low=True))
    host: str = field(default="0.0.0.0", metadata=_IPV4)
    port: int = field(default=4660, metadata=_range(1, 65535))
    source: str | None = field(default=None, metadata=_IPV4)
    source_port: int = field(default=0, metadata=_range(0, 65535))
    timeout_s: float = field(default=5.0, metadata=_TIMEOUT)
    channel_width_hz: float = field(default=ITPM_CHANNEL_WIDTH_HZ, metadata=_POSITIVE)


@dataclass(frozen=True)
class DeviceSettings:
    """Every instrument of a site."""

    teensy: TeensySettings
    vna: VnaSettings
    tec: TecSettings
    tc08: Tc08Settings
    spectrometer: SpectrometerSettings


#: The ``devices`` section's keys and their schemas, in the order a site file lists them.
DEVICE_SCHEMAS: dict[str, type] = {
    f.name: typing.get_type_hints(DeviceSettings)[f.name]
    for f in dataclasses.fields(DeviceSettings)
}


def keys_of(schema: type) -> tuple[str, ...]:
    """The keys a section of this schema may hold."""
    return tuple(f.name for f in dataclasses.fields(schema))


def read_settings(schema: type[T], section: Fields) -> T | None:
    """Read one section against its schema; ``None`` when anything was wrong (reported).

    Types come from the annotations (``str``, ``str | None``, ``float``, ``int``, a
    ``Literal`` of strings) and ranges from the fields' metadata.
    """
    hints = typing.get_type_hints(schema)
    values: dict[str, Any] = {}
    for spec in dataclasses.fields(schema):  # type: ignore[arg-type]
        name, kind, meta = spec.name, hints[spec.name], spec.metadata
        default = REQUIRED if spec.default is dataclasses.MISSING else spec.default
        choices = meta.get("choices", ())
        if kind is float:
            values[name] = section.number(
                name,
                default,
                low=meta.get("low"),
                high=meta.get("high"),
                open_low=meta.get("open_low", False),
            )
        elif kind is int:
            value = section.count(name, default, minimum=int(meta.get("low") or 0))
            high = meta.get("high")
            if choices and value not in choices:
                section.report(name, f"must be one of {', '.join(map(str, choices))}, not {value}")
            elif high is not None and value > high:
                section.report(name, f"must be at most {high:g}, not {value}")
            values[name] = value
        elif choices:
            values[name] = section.choice(name, [str(c) for c in choices], default)
        else:  # str or str | None
            values[name] = section.text(name, default)
            if meta.get("ipv4") and values[name] is not None:
                _check_ipv4(section, name, values[name])
    if section.failed:
        return None
    return schema(**values)


def _check_ipv4(section: Fields, name: str, value: str) -> None:
    """Report ``value`` unless it is an IPv4 address (a host name would need a lookup)."""
    try:
        ipaddress.IPv4Address(value)
    except ValueError:
        section.report(name, f"must be an IPv4 address such as 192.168.10.30, not {value!r}")
