"""The monitor: samples the receiver's health every cadence, keeps it, raises alarms.

One :class:`Monitor` lives in ``reachd``. Its thread wakes on each multiple of the
cadence (``monitoring.cadence_s`` of the site file, one minute by default, in the
daemon's clock) and records a sample:

* always: the daemon's state, the data directory's free space, the link statistics;
* while idle: the devices through the monitor's own links
  (:class:`~.access.IdleDevices`), under the device lock the daemon takes before it
  commands the hardware itself (:meth:`Monitor.hardware`, :meth:`Monitor.hand_over`);
* during a run (:meth:`Monitor.watch_run`): what the run reads anyway, shared: the
  spectrometer's counters and the newest reading of the run's temperature log (which
  also tells whether the TC-08 answers: a new reading, or a failed read). The
  board and the TEC are read by the run's own thread at its safe points
  (:meth:`RunWatch.safe_point`: between steps, between Dicke positions, during waits),
  at most once a cadence, never inside an integration or a VNA sweep.

Every batch goes through the alarms (:class:`~.alarms.AlarmBoard`), into the metrics
database (:class:`~.database.MetricsDatabase`, down-sampled every 15 minutes of clock
time), into the latest values that ``reach-run --status`` and Prometheus show, and,
during a run, into the run's own list, which the run layer stores in its run file.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from reach_receiver.clock import Clock
from reach_receiver.config.site import SiteConfig
from reach_receiver.devices.spectra import SpectrometerStatistics
from reach_receiver.devices.spectrometer import Spectrometer
from reach_receiver.devices.tc08 import DEFAULT_PORTS, Tc08Reading
from reach_receiver.errors import ReceiverError

from .access import DeviceSet, IdleDevices, Links, read_devices
from .alarms import AlarmBoard, Hook
from .arrivals import Arrivals
from .database import QUARTER_S, MetricsDatabase
from .exporter import Exporter, ReadingsCollector
from .readings import Reading, disk_readings, spectrometer_readings, tc08_readings

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TemperatureLogState:
    """A run's temperature log: whether it runs, its newest reading, its failed reads."""

    logging: bool = False
    latest: Tc08Reading | None = None
    failures: int = 0


class RunWatch:
    """What a run holds of the monitor: safe points, and the readings taken meanwhile.

    Parameters
    ----------
    monitor
        The daemon's monitor.
    devices
        The run's drivers (the TC-08 only when no temperature log runs).
    spectrometer
        The run's spectrometer, whose counters are read from the monitor's thread.
    temperature_log
        ``() -> TemperatureLogState`` of the run's temperature log.
    """

    def __init__(
        self,
        monitor: Monitor,
        devices: DeviceSet,
        spectrometer: Spectrometer | None,
        temperature_log: Callable[[], TemperatureLogState],
    ) -> None:
        self.monitor = monitor
        self.devices = devices
        self.spectrometer = spectrometer
        self.temperature_log = temperature_log
        self.taken: list[Reading] = []
        self.safe_points = 0
        self.safe_point_s = 0.0  # real seconds spent sampling at safe points
        self.safe_point_max_s = 0.0  # the longest of them (real s)
        self._last_active = -math.inf
        self._last_point = time.monotonic()
        self._last_stats: SpectrometerStatistics | None = None
        self._last_tc08 = -math.inf
        self._log_failures = 0
        self._tc08 = devices.tc08
        self.arrivals = Arrivals(monitor.links)

    @property
    def cadence_s(self) -> float:
        """Clock seconds between samples."""
        return self.monitor.cadence_s

    def safe_point(self) -> None:
        """The run is between measurements: read the board and the TEC if one is due."""
        now = self.monitor.clock.now()
        if now - self._last_active < self.cadence_s:
            return
        started = time.monotonic()
        since = self._last_point
        teensy = self.devices.teensy

        def state_read_since() -> object:
            remembered = teensy.last_state if teensy is not None else None
            return remembered[1] if remembered and remembered[0] >= since else None

        logging_temperatures = self.temperature_log().logging
        devices = DeviceSet(
            teensy, self.devices.tec, None if logging_temperatures else self._tc08,
            self.devices.ports, state_read_since,  # type: ignore[arg-type]
            self.devices.tec_usable, self.devices.connected,
        )
        self._last_active = now
        readings = read_devices(devices, self.monitor.links, self.monitor.clock.now)
        self.monitor.record(readings, self)
        self._last_point = time.monotonic()
        self.safe_points += 1
        self.safe_point_s += self._last_point - started
        self.safe_point_max_s = max(self.safe_point_max_s, self._last_point - started)

    def passive(self, now: float) -> list[Reading]:
        """What the run read anyway: the spectrometer's counters, the temperature log.

        A new reading of the log is the TC-08 answering; a failed read of the log since
        the last sample, with no reading after it, is the TC-08 not answering.
        """
        out: list[Reading] = []
        spectrometer = self.spectrometer
        if spectrometer is not None:
            stats = spectrometer.statistics
            out += spectrometer_readings(stats, self._last_stats, now)
            self._last_stats = stats
            period = spectrometer.period or self.monitor.site.devices.spectrometer.period_s
            self.arrivals.observe(stats, self._spectrometer_port(), period, self.cadence_s, now)
        log_state = self.temperature_log()
        latest = log_state.latest
        links = self.monitor.links
        if log_state.logging and latest is not None and latest.timestamp > self._last_tc08:
            self._last_tc08 = latest.timestamp
            out += tc08_readings(latest, self.devices.ports)
            links.good("tc08", latest.timestamp)
        elif log_state.logging and log_state.failures > self._log_failures:
            failed = log_state.failures - self._log_failures
            links.failed("tc08", f"tc08: {failed} read(s) of the temperature log failed")
        self._log_failures = log_state.failures
        return out

    def _spectrometer_port(self) -> int | None:
        """The UDP port the run's spectrometer listens on; ``None`` while it does not."""
        if self.spectrometer is None or not self.devices.connected():
            return None
        try:
            return int(self.spectrometer.address[1])
        except (ReceiverError, OSError):
            return None

    def close(self) -> None:
        """The run is over: the monitor takes its own links again."""
        self.monitor.run_ended(self)


class Monitor:
    """The daemon's monitor (module docstring).

    Parameters
    ----------
    site
        The site: devices, the ``monitoring`` section, thermocouple ports.
    clock
        The daemon's clock.
    state_dir
        Where the metrics database goes (unless the site names it).
    data_dir
        The directory whose file system's free space is watched (the runs).
    daemon_state
        ``() -> index`` of the daemon's state (``reach_daemon_state``; see its HELP).
    """

    def __init__(
        self,
        site: SiteConfig,
        clock: Clock,
        state_dir: Path,
        data_dir: Path,
        daemon_state: Callable[[], int] = lambda: 1,
    ) -> None:
        self.site = site
        self.settings = site.monitoring
        self.clock = clock
        self.data_dir = data_dir
        self.daemon_state = daemon_state
        self.links = Links()
        self.database_path = self.settings.database_path(state_dir)
        self.database: MetricsDatabase | None = None
        self.hook: Hook | None = None
        self.board = AlarmBoard(self.settings.alarms)
        self.exporter: Exporter | None = None
        self.ports = {**DEFAULT_PORTS}
        self._latest: dict[str, Reading] = {}
        self._idle = IdleDevices(site.devices, clock)
        self._devices = threading.RLock()  # held while the monitor talks to devices
        self._record_lock = threading.Lock()
        self._run: RunWatch | None = None
        self.last_watch: RunWatch | None = None  # the latest run's (its safe-point times)
        self._run_mode = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._next_maintenance = -math.inf
        self.samples = 0
        self.skipped = 0

    @property
    def cadence_s(self) -> float:
        """Clock seconds between samples."""
        return self.settings.cadence_s

    # ----------------------------------------------------------------- life cycle
    def start(self) -> None:
        """Open the database, the hook and the Prometheus port; start sampling."""
        settings = self.settings
        self.database = MetricsDatabase(
            self.database_path, minute_days=settings.minute_days,
            quarter_days=settings.quarter_days,
        )
        if settings.hook:
            self.hook = Hook(settings.hook, settings.hook_timeout_s)
            self.board.hook = self.hook
        if settings.prometheus_port is not None:
            collector = ReadingsCollector(
                self.latest, self.alarm_ids, lambda: 2 * self.cadence_s, self.clock.now
            )
            self.exporter = Exporter(collector, settings.prometheus_port)
            log.info("monitor: Prometheus metrics on http://%s:%d/", *self.exporter.address)
        self._stop.clear()
        self._thread = threading.Thread(target=self._loop, name="monitor", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop sampling; close the links, the port, the hook and the database."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=30)
            self._thread = None
        with self._devices:
            self._idle.close()
        if self.exporter is not None:
            self.exporter.close()
        if self.hook is not None:
            self.hook.close()
        if self.database is not None:
            self.database.close()
            self.database = None

    # ----------------------------------------------------------------- the hardware
    @contextlib.contextmanager
    def hardware(self) -> Iterator[None]:
        """The daemon commands the hardware itself: the monitor lets go meanwhile."""
        with self._devices:
            self._idle.close()
            yield

    def hand_over(self) -> None:
        """A run is about to take the hardware: no idle sampling until it ends."""
        with self._devices:
            self._run_mode = True
            self._idle.close()

    def watch_run(
        self,
        devices: DeviceSet,
        spectrometer: Spectrometer | None,
        temperature_log: Callable[[], TemperatureLogState],
    ) -> RunWatch:
        """The run's side of the monitor (:class:`RunWatch`)."""
        self.hand_over()
        devices.ports = {**self.ports, **devices.ports}
        watch = RunWatch(self, devices, spectrometer, temperature_log)
        self._run = self.last_watch = watch
        return watch

    def run_ended(self, watch: RunWatch | None = None) -> None:
        """The run is over (idempotent): idle sampling resumes."""
        with self._devices:
            ended = self._run if watch is None else watch
            if watch is None or self._run is watch:
                self._run = None
            self._run_mode = self._run is not None
        if ended is not None:
            ended.arrivals.reset()

    # ----------------------------------------------------------------- sampling
    def _loop(self) -> None:
        cadence = self.cadence_s
        due = math.floor(self.clock.now() / cadence) * cadence + cadence
        while not self._stop.is_set():
            if self.clock.wait(self._stop, due - self.clock.now()):
                return
            try:
                self.sample()
            except Exception:  # the monitor must outlive any one bad sample
                log.exception("monitor: sample failed")
            now = self.clock.now()
            due += cadence
            if now >= due:
                missed = math.floor((now - due) / cadence) + 1
                self.skipped += missed
                due += missed * cadence

    def sample(self) -> list[Reading]:
        """One sample (module docstring); returns what was recorded."""
        now = self.clock.now()
        readings: list[Reading] = []
        run = self._run
        if run is not None:
            readings += run.passive(now)
        elif not self._run_mode:
            with self._devices:
                if not self._run_mode:
                    readings += self._idle.sample(self.links, self.ports)
        # The daemon's own readings carry the sample's time, not the end of the device
        # reads above (they stamp their own): the series then keep the cadence exactly.
        index = self.daemon_state()
        readings.append(Reading("reach_daemon_state", float(index), "1", now))
        readings += disk_readings(self.data_dir, now)
        readings += self.links.readings(now)
        recorded = self.record(readings, run)
        self.samples += 1
        if now >= self._next_maintenance and self.database is not None:
            self.database.maintain(now)
            self._next_maintenance = now - now % QUARTER_S + QUARTER_S + 1
        return recorded

    def record(self, readings: Sequence[Reading], run: RunWatch | None = None) -> list[Reading]:
        """Alarms, database, latest values, and the run's list."""
        with self._record_lock:
            checked = self.board.update(readings)
            if self.database is not None:
                self.database.write(checked)
            for reading in checked:
                self._latest[reading.key] = reading
            if run is not None:
                run.taken.extend(checked)
        return checked

    # ----------------------------------------------------------------- views
    def latest(self) -> list[Reading]:
        """The newest reading of every series."""
        with self._record_lock:
            return list(self._latest.values())

    def alarms(self) -> list[str]:
        """The raised alarms in words, one line each, their durations as of now."""
        now = self.clock.now()
        with self._record_lock:
            return self.board.messages(now)

    def alarm_ids(self) -> list[str]:
        """The raised alarms' details (``rule: series key``), one each."""
        with self._record_lock:
            return self.board.ids()

    def status(self) -> dict[str, object]:
        """For the daemon's ``status`` reply: alarms and the latest readings.

        ``alarms`` holds each raised alarm in words; ``alarm_details`` the same alarms
        with their detail (``id``: rule and series key) and numbers
        (:meth:`~.alarms.Alarm.as_dict`).
        """
        readings = sorted(self.latest(), key=lambda r: r.key)
        now = self.clock.now()
        with self._record_lock:
            details = self.board.details(now)
        return {
            "alarms": [str(d["text"]) for d in details],
            "alarm_details": details,
            "readings": [
                {"key": r.key, "value": None if math.isnan(r.value) else r.value,
                 "unit": r.unit, "status": r.status, "t": r.timestamp}
                for r in readings
            ],
            "cadence_s": self.cadence_s,
        }
