"""The site file: where each instrument is reached, and what the front-end holds.

A YAML mapping, safe-loaded with line numbers; every mistake is reported at once as
``file:line: key: message`` (:class:`SiteError`) and unknown keys are refused::

    site: {name: REACH Karoo, longitude_deg: 21.52, latitude_deg: -30.97}
    devices:                          # schemas and defaults: reach_receiver.config.settings
      teensy: {port: /dev/serial/by-id/usb-Teensyduino_USB_Serial_12345-if00}
      vna: {resource: "TCPIP0::192.168.10.20::5025::SOCKET", timeout_s: 20}
      tec: {via: teensy}              # or {via: serial, port: /dev/ttyUSB0}
      tc08: {library: /opt/picotech/lib/libusbtc08.so}
      spectrometer: {host: 192.168.10.1, port: 4660, source: 192.168.10.30, period_s: 1.0}
                                      # period_s required; source: the iTPM's address
    calibration: {band_hz: [50.0e+6, 130.0e+6], solver: radiometric}   # the engine's band
                                  # and solver (the defaults; calibration.solve.solvers.METHODS);
                                  # band_of_interest_hz: [lo, hi] within it, where the
                                  # calibrate_adaptive step weighs the antenna's error
                                  # (default: the whole band);
                                  # corrections: reach_receiver.config.corrections
    references: {test_load: /etc/reach/test_load_pnax.s1p}   # lab (PNA-X) S11 of MS2-6
    sources: {hot: {ms1: 6}, r100: {ms1: 2}, c2r27: null}   # changes to table A.2
    thermocouples: {hot: 2}                 # source -> TC-08 port, changes to table 2.2
    daemon: {resume: true, timers: [...]}   # reachd: reach_receiver.config.daemon
    monitoring: {cadence_s: 60, alarms: [...]}   # reachd: reach_receiver.config.monitoring

``reach-sim`` prints one of these with the simulated instruments' addresses and a
``simulation`` section (its compressed clock), which ``reach-run`` then shares.

Where the file is: ``--site``, else ``$REACH_SITE``, else ``/etc/reach/site.yaml``
(:func:`find_site`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from calibration.core.constants import METHODS
from reach_receiver.clock import Clock, CompressedClock, SystemClock
from reach_receiver.frontend.layout import (
    REACH_SOURCES,
    SOURCE_THERMOCOUPLE,
    SWITCH_POSITIONS,
    SourcePosition,
)

from .corrections import (
    CALIBRATION_KEYS,
    CorrectionSettings,
    corrections_yaml,
    read_corrections,
    site_path,
    touchstone_problem,
)
from .daemon import DAEMON_KEYS, DaemonSettings, daemon_yaml, read_daemon
from .fields import REQUIRED, Fields, type_name
from .monitoring import MONITORING_KEYS, MonitoringSettings, monitoring_yaml, read_monitoring
from .settings import DEVICE_SCHEMAS, DeviceSettings, keys_of, read_settings
from .site_file import (
    SECTIONS,
    SectionReader,
    SiteError,
    find_site,
    read_document,
)
from .yaml_lines import LineDict, Problem, with_lines

#: The calibration band when the site does not set one (thesis 4.1: REACH's 50-130 MHz).
DEFAULT_BAND_HZ = (50e6, 130e6)
#: The calibrate step's solver when neither the step nor the site names one.
DEFAULT_SOLVER = METHODS[0]
_PLACE_KEYS = ("name", "longitude_deg", "latitude_deg")
_REFERENCE_KEYS = ("test_load",)
_SIMULATION_KEYS = ("compression", "start", "monotonic_origin")
#: Simulated seconds per real second a shared clock may run at (reach-sim's default: 3000).
MAX_COMPRESSION = 1e6


@dataclass(frozen=True)
class SiteConfig:
    """A checked site file: the place, the instruments, and the front-end's tables.

    ``sources`` is table A.2 with the site's changes, ``thermocouples`` table 2.2 with
    its changes; ``simulation`` holds a ``reach-sim``'s shared clock (empty on site);
    ``solver`` the ``calibrate`` step's default solver (:data:`calibration.solve.solvers.METHODS`).
    """

    devices: DeviceSettings
    name: str = "unnamed site"
    longitude_deg: float = 0.0
    latitude_deg: float = 0.0
    band_hz: tuple[float, float] = DEFAULT_BAND_HZ
    band_of_interest_hz: tuple[float, float] | None = None
    references: Mapping[str, str] = field(default_factory=dict)
    simulation: Mapping[str, float] = field(default_factory=dict)
    sources: Mapping[str, SourcePosition] = field(default_factory=lambda: dict(REACH_SOURCES))
    thermocouples: Mapping[str, int] = field(default_factory=lambda: dict(SOURCE_THERMOCOUPLE))
    daemon: DaemonSettings = field(default_factory=DaemonSettings)
    monitoring: MonitoringSettings = field(default_factory=MonitoringSettings)
    source: str = "<memory>"
    corrections: CorrectionSettings = field(default_factory=CorrectionSettings)
    solver: str = DEFAULT_SOLVER

    def clock(self) -> Clock:
        """The clock the site runs on: a ``reach-sim``'s shared compressed clock, or the wall's."""
        if self.simulation:
            return CompressedClock(
                self.simulation["compression"],
                self.simulation["start"],
                self.simulation["monotonic_origin"],
            )
        return SystemClock()

    def to_yaml(self) -> str:
        """The site file text that reproduces this configuration."""
        document: dict[str, Any] = {
            "site": {
                "name": self.name,
                "longitude_deg": self.longitude_deg,
                "latitude_deg": self.latitude_deg,
            },
            "devices": {
                name: {k: v for k, v in dataclasses.asdict(settings).items() if v is not None}
                for name, settings in vars(self.devices).items()
            },
        }
        calibration: dict[str, Any] = (
            {"band_hz": list(self.band_hz)} if self.band_hz != DEFAULT_BAND_HZ else {}
        )
        if self.band_of_interest_hz is not None:
            calibration["band_of_interest_hz"] = list(self.band_of_interest_hz)
        if self.solver != DEFAULT_SOLVER:
            calibration["solver"] = self.solver
        if calibration or corrections_yaml(self.corrections):
            document["calibration"] = {**calibration, **corrections_yaml(self.corrections)}
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
        if self.daemon != DaemonSettings():
            document["daemon"] = daemon_yaml(self.daemon)
        if monitoring_yaml(self.monitoring):
            document["monitoring"] = monitoring_yaml(self.monitoring)
        return yaml.safe_dump(document, sort_keys=False)


def parse_site(document: object, source: str = "<memory>") -> SiteConfig:
    """Check and convert a loaded site document; every mistake is reported at once.

    Raises
    ------
    SiteError
        With one ``file:line: key: message`` per mistake.
    """
    document = with_lines(document)
    if not isinstance(document, LineDict):
        message = f"a site file is a mapping of {', '.join(SECTIONS)}, not {type_name(document)}"
        raise SiteError([Problem(source, 1, "<document>", message)])
    reader = SectionReader(document, source)
    place = reader.section("site", _PLACE_KEYS)
    longitude = place.number("longitude_deg", 0.0, low=-180.0, high=360.0)
    latitude = place.number("latitude_deg", 0.0, low=-90.0, high=90.0)
    name = place.text("name", "unnamed site") or "unnamed site"
    devices = _devices(reader)
    band = _band(reader)
    interest = _band_of_interest(reader, band)
    solver = reader.section("calibration", CALIBRATION_KEYS).choice(
        "solver", METHODS, DEFAULT_SOLVER
    )
    corrections = read_corrections(reader.section("calibration", CALIBRATION_KEYS))
    written_references = _references(reader.section("references", _REFERENCE_KEYS))
    clock = _clock(reader.section("simulation", _SIMULATION_KEYS))
    sources = _sources(reader)
    thermocouples = _thermocouples(reader)
    daemon = read_daemon(reader.section("daemon", DAEMON_KEYS), source, reader.problems)
    monitoring = read_monitoring(reader.section("monitoring", MONITORING_KEYS), reader.problems)
    if reader.problems or devices is None or band is None or solver is None:
        raise SiteError(sorted(dict.fromkeys(reader.problems), key=lambda p: p.line))
    return SiteConfig(
        devices=devices,
        name=name,
        longitude_deg=longitude,
        latitude_deg=latitude,
        band_hz=band,
        band_of_interest_hz=interest,
        references={k: v for k, v in written_references.items() if v is not None},
        simulation=clock,
        sources=sources,
        thermocouples=thermocouples,
        daemon=daemon,
        monitoring=monitoring,
        source=source,
        corrections=corrections,
        solver=solver,
    )


def _references(references: Fields) -> dict[str, str | None]:
    """The reference files (taken from the site's directory), each a one-port Touchstone."""
    written: dict[str, str | None] = {}
    for key in (k for k in _REFERENCE_KEYS if references.has(k)):
        value = references.text(key)
        if value is None:
            continue
        path = site_path(value, references.file)
        problem = touchstone_problem(path, ports=1)
        if problem is not None:
            references.report(key, problem)
        written[key] = str(path)
    return written


def _clock(simulation: Fields) -> dict[str, float]:
    """A ``reach-sim``'s shared clock: all three numbers, or none (the wall clock)."""
    clock = {}
    if simulation.has("compression"):
        clock["compression"] = simulation.number(
            "compression", REQUIRED, low=0.0, high=MAX_COMPRESSION, open_low=True
        )
    if simulation.has("start"):
        clock["start"] = simulation.number("start", REQUIRED, low=0.0)
    if simulation.has("monotonic_origin"):
        clock["monotonic_origin"] = simulation.number("monotonic_origin", REQUIRED, low=0.0)
    if clock and set(clock) != set(_SIMULATION_KEYS):
        missing = sorted(set(_SIMULATION_KEYS) - set(clock))
        simulation.report("<clock>", f"needs all of {', '.join(_SIMULATION_KEYS)}: {missing}")
    return clock


def _devices(reader: SectionReader) -> DeviceSettings | None:
    devices = reader.section("devices", tuple(DEVICE_SCHEMAS))
    read: dict[str, Any] = {}
    for name, schema in DEVICE_SCHEMAS.items():
        if not devices.has(name):
            devices.report(name, "missing required section", devices.args.line)
            continue
        section = devices.mapping(name, keys_of(schema))
        if section is None:
            section = Fields(
                LineDict(line=devices.line(name)),
                file=reader.file,
                key=f"devices.{name}",
                allowed=keys_of(schema),
                problems=reader.problems,
            )
        read[name] = read_settings(schema, section)
        if name == "tec" and read[name] is not None:
            tec = read[name]
            if (tec.via == "serial") != (tec.port is not None):
                section.report("port", "give a port with 'via: serial', and only then")
                read[name] = None
    if any(v is None for v in read.values()) or len(read) != len(DEVICE_SCHEMAS):
        return None
    return DeviceSettings(**read)


def _band(reader: SectionReader) -> tuple[float, float] | None:
    calibration = reader.section("calibration", CALIBRATION_KEYS)
    if not calibration.has("band_hz"):
        return DEFAULT_BAND_HZ
    written = calibration.raw("band_hz")
    line = calibration.line("band_hz")
    if not isinstance(written, list) or len(written) != 2:
        calibration.report("band_hz", f"must be [low, high] in Hz, not {type_name(written)}")
        return None
    low, high = written
    numbers = all(isinstance(v, int | float) and not isinstance(v, bool) for v in written)
    if not numbers or not 0 <= low < high:
        message = f"must be [low, high] with 0 <= low < high, not {written}"
        reader.report(line, "calibration.band_hz", message)
        return None
    return float(low), float(high)


def _band_of_interest(
    reader: SectionReader, band: tuple[float, float] | None
) -> tuple[float, float] | None:
    """``calibration.band_of_interest_hz``: ``[low, high]`` inside ``band_hz``, or None."""
    calibration = reader.section("calibration", CALIBRATION_KEYS)
    if not calibration.has("band_of_interest_hz"):
        return None
    written = calibration.raw("band_of_interest_hz")
    numbers = (
        isinstance(written, list) and len(written) == 2
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in written)
    )
    if not numbers or not 0 <= written[0] < written[1]:
        calibration.report(
            "band_of_interest_hz", f"must be [low, high] in Hz with 0 <= low < high, not {written}"
        )
        return None
    low, high = float(written[0]), float(written[1])
    if band is not None and (low < band[0] or high > band[1]):
        calibration.report(
            "band_of_interest_hz",
            f"[{low:g}, {high:g}] must lie inside the calibration band "
            f"[{band[0]:g}, {band[1]:g}] (band_hz)",
        )
        return None
    return low, high


def _sources(reader: SectionReader) -> dict[str, SourcePosition]:
    table = dict(REACH_SOURCES)
    given = reader.document.get("sources")
    if given is None:
        return table
    line = reader.document.line_of("sources")
    if not isinstance(given, LineDict):
        reader.report(line, "sources", "must map source names to switch positions")
        return table
    for name, where in given.items():
        if where is None:  # a source this site does not have
            table.pop(str(name), None)
            continue
        position = _position(reader, str(name), where, given.line_of(name))
        if position is not None:
            table[str(name)] = position
    seen: dict[SourcePosition, str] = {}
    for name, position in table.items():
        if position in seen:
            reader.report(
                given.line_of(name) if name in given else line,
                f"sources.{name}",
                f"sources '{seen[position]}' and '{name}' sit at the same position",
            )
        seen[position] = name
    return table


def _position(reader: SectionReader, name: str, where: object, line: int) -> SourcePosition | None:
    """``{ms1: 7, ms3: 2}``: an MS1 position and at most one termination switch."""
    key = f"sources.{name}"
    if not isinstance(where, dict) or "ms1" not in where or set(where) - {"ms1", "ms3", "ms4"}:
        reader.report(line, key, "must be {ms1: <1-8>} plus at most one of ms3/ms4")
        return None
    terminations = [k for k in ("ms3", "ms4") if k in where]
    values = {k: where[k] for k in ("ms1", *terminations)}
    for switch, value in values.items():
        top = SWITCH_POSITIONS[switch]
        if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= top:
            reader.report(line, f"{key}.{switch}", f"must be an integer 1-{top}, not {value!r}")
            return None
    if len(terminations) > 1:
        reader.report(line, key, "names both ms3 and ms4; a source sits behind one of them")
        return None
    termination = (terminations[0], values[terminations[0]]) if terminations else None
    return SourcePosition(values["ms1"], termination)


def _thermocouples(reader: SectionReader) -> dict[str, int]:
    ports = dict(SOURCE_THERMOCOUPLE)
    given = reader.document.get("thermocouples")
    if given is None:
        return ports
    if not isinstance(given, LineDict):
        line = reader.document.line_of("thermocouples")
        reader.report(line, "thermocouples", "must map source names to TC-08 ports 1-8")
        return ports
    for name, port in given.items():
        if not isinstance(port, int) or isinstance(port, bool) or not 1 <= port <= 8:
            reader.report(
                given.line_of(name),
                f"thermocouples.{name}",
                f"must be a TC-08 port 1-8, not {port!r}",
            )
        else:
            ports[str(name)] = port
    return ports


def _position_yaml(position: SourcePosition) -> dict[str, int]:
    out = {"ms1": position.ms1}
    if position.termination is not None:
        out[position.termination[0]] = position.termination[1]
    return out


def load_site(path: str | Path) -> SiteConfig:
    """Read and check a site file.

    Raises
    ------
    SiteError
        Every mistake, ``file:line: key: message``; also an unreadable file.
    """
    path = Path(path)
    return parse_site(read_document(path), str(path))


def replace_devices(site: SiteConfig, **changes: Any) -> SiteConfig:
    """A copy of ``site`` with some devices' settings changed (``spectrometer={...}``)."""
    devices = site.devices
    for name, values in changes.items():
        devices = dataclasses.replace(
            devices, **{name: dataclasses.replace(getattr(devices, name), **values)}
        )
    return dataclasses.replace(site, devices=devices)


__all__ = [
    "DEFAULT_BAND_HZ", "SiteConfig", "SiteError", "find_site", "load_site", "parse_site",
    "replace_devices",
]
