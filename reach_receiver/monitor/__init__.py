"""Monitoring: the receiver's health every cadence, kept for months, with alarms.

================  ==========================================================
module            holds
================  ==========================================================
``readings``      typed readings (value, unit, status, time) and their builders
``access``        the monitor's links while idle, the run's drivers during a run
``alarms``        thresholds held for ``for_s``, hysteresis; the hook
``wording``       alarm text for people (what, since when, which threshold)
``arrivals``      whether the iTPM sends, from a run's counters and socket queue
``database``      SQLite (WAL): minute data, 15-minute means, retention
``exporter``      Prometheus text format on 127.0.0.1
``monitor``       the sampling thread and the run's safe points
================  ==========================================================
"""

from .access import DeviceSet
from .database import MetricsDatabase, Point
from .monitor import Monitor, RunWatch
from .readings import STATUSES, Reading

__all__ = ["STATUSES", "DeviceSet", "MetricsDatabase", "Monitor", "Point", "Reading", "RunWatch"]
