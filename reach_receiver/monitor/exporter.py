"""The current readings in Prometheus' text format, on the loopback interface only.

``prometheus_client`` serves a registry of our own (not its global one, which would add
the process's own metrics under names we do not choose) holding one collector that
turns the latest reading of each series into a gauge sample: metric and label names as
the readings carry them (``reach_tc08_temperature_celsius{channel="1",...}``), one HELP
line per metric. Readings older than two cadences are left out rather than shown as if
current; each raised alarm is a ``reach_alarm_active{alarm="<rule>: <series key>"}``
sample of 1.

The server binds ``127.0.0.1``: the site's network is not ours to expose; a Prometheus
on another host reaches it through an SSH tunnel or a local agent.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterator, Sequence
from wsgiref.simple_server import WSGIServer

from prometheus_client.core import GaugeMetricFamily
from prometheus_client.exposition import start_http_server
from prometheus_client.registry import Collector, CollectorRegistry

from .readings import Reading

LOOPBACK = "127.0.0.1"

#: HELP text per metric; a metric not listed gets its unit.
HELP = {
    "reach_tc08_temperature_celsius": "TC-08 thermocouple temperature (channel 0: cold junction)",
    "reach_tc08_fault": "1 when the TC-08 channel's reading is flagged (open, overflow, stuck)",
    "reach_teensy_temperature_celsius": "front-end MCP9808 sensor on the Teensy's I2C bus",
    "reach_tec_temperature_celsius": "TEC plate (enclosure) temperature",
    "reach_tec_setpoint_celsius": "TEC setpoint",
    "reach_tec_output_percent": "TEC output drive",
    "reach_tec_fault_bits": "TEC status fault word (0 = no fault)",
    "reach_switch_position": "RF switch position (0 = released; mts: 0 LNA, 1 VNA)",
    "reach_rail_on": "1 when the power rail is on",
    "reach_device_up": "1 when the device answered the monitor's last read",
    "reach_disk_free_bytes": "free space of the data directory's file system",
    "reach_daemon_state": "reachd state: 0 starting, 1 idle, 2 running, 3 observing, "
    "4 faulted, 5 stopping, 6 stopped",
    "reach_calibration_drift_sigma": "the latest calibration against the previous solution on "
    "the antenna, in Gaussian sigma of its false-alarm probability (one a calibration)",
}


class ReadingsCollector(Collector):
    """Gauges of the latest readings (module docstring)."""

    def __init__(
        self,
        latest: Callable[[], Sequence[Reading]],
        alarms: Callable[[], Sequence[str]],
        max_age_s: Callable[[], float],
        now: Callable[[], float],
    ) -> None:
        self.latest = latest
        self.alarms = alarms
        self.max_age_s = max_age_s
        self.now = now

    def collect(self) -> Iterator[GaugeMetricFamily]:
        """One gauge family per metric; stale and NaN readings left out."""
        families: dict[str, GaugeMetricFamily] = {}
        label_names: dict[str, list[str]] = {}
        oldest = self.now() - self.max_age_s()
        for reading in self.latest():
            if reading.timestamp < oldest or math.isnan(reading.value):
                continue
            names = sorted(reading.labels)
            family = families.get(reading.metric)
            if family is None:
                text = HELP.get(reading.metric, f"unit {reading.unit}")
                family = families[reading.metric] = GaugeMetricFamily(
                    reading.metric, text, labels=names
                )
                label_names[reading.metric] = names
            if names == label_names[reading.metric]:
                family.add_metric([reading.labels[n] for n in names], reading.value)
        alarm = GaugeMetricFamily("reach_alarm_active", "1 for each raised alarm",
                                  labels=["alarm"])
        for detail in self.alarms():
            alarm.add_metric([detail], 1.0)
        yield from families.values()
        yield alarm


class Exporter:
    """The HTTP server of one :class:`ReadingsCollector` on ``127.0.0.1:port``."""

    def __init__(self, collector: ReadingsCollector, port: int) -> None:
        self.registry = CollectorRegistry(auto_describe=False)
        self.registry.register(collector)
        self._server: WSGIServer | None
        self._thread: threading.Thread | None
        self._server, self._thread = start_http_server(port, addr=LOOPBACK,
                                                       registry=self.registry)

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port)."""
        if self._server is None:
            raise RuntimeError("the exporter is closed")
        host, port = self._server.server_address[:2]
        return str(host), int(port)

    def close(self) -> None:
        """Stop serving."""
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
        if self._thread is not None:
            self._thread.join(timeout=5)
        self._server = self._thread = None
