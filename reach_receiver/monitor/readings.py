"""Typed health readings: a value, its unit, a status and when it was taken.

The aiokatcp ``Sensor``/``Reading`` idea, flattened for a metrics database and
Prometheus: each :class:`Reading` names its metric in Prometheus' conventions
(``reach_`` namespace, the unit as a suffix: ``_celsius``, ``_bytes``, ``_seconds``,
``_ratio``, ``_total`` for counters) with a few labels (``channel``, ``device``,
``rail``...). Its *series key*, ``metric{label=value,...}``, is what the database stores
and ``reach-run metrics`` names.

The builders here turn what the drivers already return (a TC-08 reading, the board's
``state`` reply, the TEC's status, the spectrometer's counters) into readings; they do
no I/O of their own, so a read the run made is turned into readings without touching
the device again.
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from reach_receiver.devices.board import FrontEndState
from reach_receiver.devices.spectra import SpectrometerStatistics
from reach_receiver.devices.tc08 import Tc08Reading
from reach_receiver.devices.tec_frames import TecStatus

#: Statuses, in order of concern; stored as their index.
STATUSES = ("nominal", "warn", "error", "unknown")
NOMINAL, WARN, ERROR, UNKNOWN = STATUSES


@dataclass(frozen=True)
class Reading:
    """One reading of one series.

    ``value`` is NaN when the device answered but the value cannot be used (a
    thermocouple flagged open or overflowing): its status then says why not. ``note`` is
    what the number alone does not say, for an alarm's text (a calibration drift's size
    and band); it is not part of the series and is not stored.
    """

    metric: str
    value: float
    unit: str
    timestamp: float
    status: str = NOMINAL
    labels: Mapping[str, str] = field(default_factory=dict)
    note: str = ""

    @property
    def key(self) -> str:
        """The series key, ``metric{a=1,b=x}`` (labels sorted), or the metric alone."""
        return series_key(self.metric, self.labels)


def series_key(metric: str, labels: Mapping[str, str]) -> str:
    """The key of a series: ``metric`` with its labels in sorted order."""
    if not labels:
        return metric
    inner = ",".join(f"{k}={v}" for k, v in sorted(labels.items()))
    return f"{metric}{{{inner}}}"


def parse_key(key: str) -> tuple[str, dict[str, str]]:
    """The metric and labels of a series key (:func:`series_key` inverted)."""
    metric, _, rest = key.partition("{")
    labels = dict(item.split("=", 1) for item in rest.rstrip("}").split(",") if "=" in item)
    return metric, labels


def tc08_readings(reading: Tc08Reading, ports: Mapping[int, str]) -> list[Reading]:
    """Each channel's temperature (0 is the cold junction) and whether it is flagged.

    A flagged channel (open circuit or overflow read as NaN, stuck) reads NaN with
    status ``error``, and ``reach_tc08_fault`` is 1 for it.
    """
    out = []
    for channel in sorted(reading.raw_c):
        labels = {"channel": str(channel), "component": ports.get(channel, "cold junction")}
        if channel == 0:
            labels["component"] = "cold junction"
        flagged = channel in reading.flags
        value = math.nan if flagged else reading.temperatures_c[channel]
        status = ERROR if flagged else NOMINAL
        t = reading.timestamp
        out.append(Reading("reach_tc08_temperature_celsius", value, "degC", t, status, labels))
        out.append(Reading("reach_tc08_fault", float(flagged), "1", t, status, labels))
    return out


def board_readings(state: FrontEndState, t: float) -> list[Reading]:
    """Switch positions (MTS: 0 = LNA, 1 = VNA), rails on/off, safe state, uptime."""
    out = []
    for switch, position in state.switches.items():
        value = float(position == "vna") if switch == "mts" else float(position)
        out.append(Reading("reach_switch_position", value, "1", t, labels={"switch": switch}))
    for rail, on in state.rails.items():
        out.append(Reading("reach_rail_on", float(on), "1", t, labels={"rail": rail}))
    out.append(Reading("reach_frontend_safe", float(state.is_safe), "1", t))
    out.append(Reading("reach_frontend_uptime_seconds", state.uptime_ms / 1000.0, "s", t))
    return out


def i2c_readings(temperatures: Mapping[int, float], t: float) -> list[Reading]:
    """The front-end's MCP9808 sensors on the Teensy's I2C bus."""
    return [
        Reading("reach_teensy_temperature_celsius", value, "degC", t,
                labels={"sensor": f"0x{address:02x}"})
        for address, value in sorted(temperatures.items())
    ]


def tec_readings(status: TecStatus, t: float) -> list[Reading]:
    """The TEC's plate temperature, setpoint, output, regulation, supply and fault bits."""
    faulty = ERROR if status.faults.raw else NOMINAL
    return [
        Reading("reach_tec_temperature_celsius", status.temperature, "degC", t),
        Reading("reach_tec_setpoint_celsius", status.setpoint, "degC", t),
        Reading("reach_tec_output_percent", status.output_percent, "%", t),
        Reading("reach_tec_regulating", float(status.controlled), "1", t),
        Reading("reach_tec_supply_volts", status.supply_v, "V", t),
        Reading("reach_tec_fault_bits", float(status.faults.raw), "1", t, faulty),
    ]


def spectrometer_readings(
    stats: SpectrometerStatistics, previous: SpectrometerStatistics | None, t: float
) -> list[Reading]:
    """Packet counters since the run connected, and the loss ratio since ``previous``."""
    out = [
        Reading("reach_spectrometer_packets_received_total", stats.packets_received, "1", t),
        Reading("reach_spectrometer_packets_lost_total", stats.packets_lost, "1", t),
        Reading("reach_spectrometer_packets_duplicated_total", stats.packets_duplicated, "1", t),
        # Datagrams of senders other than the site's iTPM, dropped unread.
        Reading("reach_spectrometer_packets_foreign_total", stats.packets_foreign, "1", t),
        Reading("reach_spectrometer_spectra_total", stats.spectra_completed, "1", t),
    ]
    if previous is not None:
        got = stats.packets_received - previous.packets_received
        lost = stats.packets_lost - previous.packets_lost
        ratio = lost / (got + lost) if got + lost > 0 else 0.0
        out.append(Reading("reach_spectrometer_loss_ratio", ratio, "1", t))
    return out


def disk_readings(path: Path, t: float) -> list[Reading]:
    """Free space of the file system holding ``path`` (the data directory)."""
    try:
        usage = shutil.disk_usage(path)
    except OSError:
        return [Reading("reach_disk_free_bytes", math.nan, "B", t, UNKNOWN)]
    return [
        Reading("reach_disk_free_bytes", float(usage.free), "B", t),
        Reading("reach_disk_free_ratio", usage.free / usage.total, "1", t),
    ]
