"""The site file: where each instrument is reached, and what the front-end holds.

A YAML mapping, safe-loaded, unknown keys rejected with the file and key named::

    site: {name: REACH Karoo, longitude_deg: 21.52, latitude_deg: -30.97}
    devices:
      teensy: {port: /dev/serial/by-id/usb-Teensyduino_USB_Serial_12345-if00}
      vna: {resource: "TCPIP0::192.168.10.20::5025::SOCKET", timeout_s: 20}
      tec: {via: teensy}              # or {port: /dev/ttyUSB0}
      tc08: {library: /opt/picotech/lib/libusbtc08.so}
      spectrometer: {host: 0.0.0.0, port: 4660}
    references: {test_load: /etc/reach/test_load_pnax.s1p}   # lab (PNA-X) S11 of MS2-6
    sources: {hot: {ms1: 6}, r100: {ms1: 2}, c2r27: null}   # changes to table A.2
    thermocouples: {hot: 2}                 # source -> TC-08 port, changes to table 2.2

``reach-sim`` prints one of these with the simulated instruments' addresses and a
``simulation`` section (its compressed clock), which ``reach-run`` then shares.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from reach_receiver.errors import ConfigError
from reach_receiver.frontend.layout import (
    REACH_SOURCES,
    SOURCE_THERMOCOUPLE,
    SWITCH_POSITIONS,
    SourcePosition,
)

_SECTIONS = {"site", "devices", "references", "simulation", "sources", "thermocouples"}
_SIMULATION_KEYS = {"compression", "start", "monotonic_origin"}
_DEVICE_KEYS: Mapping[str, set[str]] = {
    "teensy": {"port", "timeout_s"},
    "vna": {"resource", "timeout_s"},
    "tec": {"via", "port", "timeout_s"},
    "tc08": {"library", "simulated", "mains_hz"},
    "spectrometer": {"host", "port", "timeout_s", "period_s"},
}


@dataclass(frozen=True)
class SiteConfig:
    """A parsed site file: the site's name and position, and one settings map per device."""

    name: str = "unnamed site"
    longitude_deg: float = 0.0
    latitude_deg: float = 0.0
    devices: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    references: Mapping[str, str] = field(default_factory=dict)
    simulation: Mapping[str, float] = field(default_factory=dict)
    sources: Mapping[str, SourcePosition] = field(default_factory=lambda: dict(REACH_SOURCES))
    thermocouples: Mapping[str, int] = field(default_factory=lambda: dict(SOURCE_THERMOCOUPLE))
    source: str = "<memory>"

    def device(self, name: str) -> Mapping[str, Any]:
        """The settings of one device; a missing device is a :class:`ConfigError`."""
        if name not in self.devices:
            raise ConfigError(f"{self.source}: no 'devices.{name}' entry in the site file")
        return self.devices[name]

    def to_yaml(self) -> str:
        """The site file text that reproduces this configuration."""
        document: dict[str, Any] = {
            "site": {
                "name": self.name,
                "longitude_deg": self.longitude_deg,
                "latitude_deg": self.latitude_deg,
            },
            "devices": {k: dict(v) for k, v in self.devices.items()},
        }
        if self.references:
            document["references"] = dict(self.references)
        if self.simulation:
            document["simulation"] = dict(self.simulation)
        changed: dict[str, dict[str, int] | None] = {
            k: _position_yaml(v) for k, v in self.sources.items() if REACH_SOURCES.get(k) != v
        }
        changed.update({k: None for k in REACH_SOURCES if k not in self.sources})
        if changed:
            document["sources"] = changed
        ports = {k: v for k, v in self.thermocouples.items() if SOURCE_THERMOCOUPLE.get(k) != v}
        if ports:
            document["thermocouples"] = ports
        return yaml.safe_dump(document, sort_keys=False)


def parse_site(document: object, source: str = "<memory>") -> SiteConfig:
    """Check and convert a loaded site document; every mistake is reported at once."""
    problems: list[str] = []
    if not isinstance(document, dict):
        raise ConfigError(f"{source}: a site file is a mapping with 'site' and 'devices'")
    problems += [f"unknown section '{k}'" for k in document if k not in _SECTIONS]
    site = document.get("site") or {}
    devices = document.get("devices") or {}
    if not isinstance(site, dict):
        problems.append("'site' must be a mapping")
        site = {}
    if not isinstance(devices, dict):
        problems.append("'devices' must be a mapping")
        devices = {}
    references = document.get("references") or {}
    if not isinstance(references, dict) or not all(
        isinstance(v, str) for v in references.values()
    ):
        problems.append("'references' must map names to file paths")
        references = {}
    problems += [f"unknown key 'references.{k}'" for k in references if k != "test_load"]
    simulation = document.get("simulation") or {}
    if not isinstance(simulation, dict) or set(simulation) - _SIMULATION_KEYS:
        problems.append(f"'simulation' takes only {sorted(_SIMULATION_KEYS)}")
        simulation = {}
    for key in site:
        if key not in ("name", "longitude_deg", "latitude_deg"):
            problems.append(f"unknown key 'site.{key}'")
    for name, settings in devices.items():
        if name not in _DEVICE_KEYS:
            problems.append(f"unknown device 'devices.{name}'; known: {', '.join(_DEVICE_KEYS)}")
            continue
        if not isinstance(settings, dict):
            problems.append(f"'devices.{name}' must be a mapping")
            continue
        problems += [
            f"unknown key 'devices.{name}.{k}'" for k in settings if k not in _DEVICE_KEYS[name]
        ]
    try:
        longitude = float(site.get("longitude_deg", 0.0))
        latitude = float(site.get("latitude_deg", 0.0))
    except (TypeError, ValueError):
        problems.append("'site.longitude_deg' and 'site.latitude_deg' must be numbers")
        longitude = latitude = 0.0
    table = dict(REACH_SOURCES)
    given = document.get("sources") or {}
    if not isinstance(given, dict):
        problems.append("'sources' must map source names to switch positions")
        given = {}
    for name, where in given.items():
        if where is None:  # a source this site does not have
            table.pop(str(name), None)
            continue
        position = _parse_position(str(name), where, problems)
        if position is not None:
            table[str(name)] = position
    ports = dict(SOURCE_THERMOCOUPLE)
    given_ports = document.get("thermocouples") or {}
    if not isinstance(given_ports, dict):
        problems.append("'thermocouples' must map source names to TC-08 ports 1-8")
        given_ports = {}
    for name, port in given_ports.items():
        if not isinstance(port, int) or isinstance(port, bool) or not 1 <= port <= 8:
            problems.append(f"'thermocouples.{name}' must be a TC-08 port 1-8, not {port!r}")
        else:
            ports[str(name)] = port
    seen: dict[SourcePosition, str] = {}
    for name, position in table.items():
        if position in seen:
            problems.append(f"sources '{seen[position]}' and '{name}' sit at the same position")
        seen[position] = name
    if problems:
        raise ConfigError(f"{source}: " + "; ".join(problems))
    return SiteConfig(
        name=str(site.get("name", "unnamed site")),
        longitude_deg=longitude,
        latitude_deg=latitude,
        devices={k: dict(v) for k, v in devices.items()},
        references=dict(references),
        simulation={k: float(v) for k, v in simulation.items()},
        sources=table,
        thermocouples=ports,
        source=source,
    )


def _parse_position(name: str, where: object, problems: list[str]) -> SourcePosition | None:
    """``{ms1: 7, ms3: 2}``: an MS1 position and at most one termination switch."""
    key = f"sources.{name}"
    if not isinstance(where, dict) or "ms1" not in where or set(where) - {"ms1", "ms3", "ms4"}:
        problems.append(f"'{key}' must be {{ms1: <1-8>}} plus at most one of ms3/ms4")
        return None
    terminations = [k for k in ("ms3", "ms4") if k in where]
    values = {k: where[k] for k in ("ms1", *terminations)}
    for switch, value in values.items():
        top = SWITCH_POSITIONS[switch]
        if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= top:
            problems.append(f"'{key}.{switch}' must be an integer 1-{top}, not {value!r}")
            return None
    if len(terminations) > 1:
        problems.append(f"'{key}' names both ms3 and ms4; a source sits behind one of them")
        return None
    termination = (terminations[0], values[terminations[0]]) if terminations else None
    return SourcePosition(values["ms1"], termination)


def _position_yaml(position: SourcePosition) -> dict[str, int]:
    out = {"ms1": position.ms1}
    if position.termination is not None:
        out[position.termination[0]] = position.termination[1]
    return out


def load_site(path: str | Path) -> SiteConfig:
    """Read a site file."""
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ConfigError(f"{path}: cannot read site file: {err}") from err
    return parse_site(document, str(path))
