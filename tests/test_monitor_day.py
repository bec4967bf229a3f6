"""A simulated day of monitoring: rows and cadence, down-sampled means, the run's readings.

``reachd`` runs against the simulated receiver at 3000x (a day in 29 s) with the
default one-minute cadence (5-minute spectra keep the packet rate low). A short run
early in the day (a Dicke cycle, then a wait) lends the run's drivers to the monitor.
Afterwards the metrics database must hold one row per series per sample, at 60 s
spacing, with a missed slot only where the monitor counted one as skipped; no alarm
may have been raised (the run's start included); the
15-minute means must equal the means of their minute rows; and the run file must hold
the health readings taken while it ran.
"""

import dataclasses
import math
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from reach_receiver.config.daemon import DaemonSettings
from reach_receiver.config.monitoring import MonitoringSettings
from reach_receiver.daemon.service import Daemon, Directories
from reach_receiver.monitor.database import QUARTER_S, MetricsDatabase
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings
from reach_receiver.store import read_run_file
from tests.test_daemon_link import until

DAY_S = 86400.0
CADENCE_S = 60.0
SCHEDULE = """\
schedule: monitored
steps:
  - initialise: {rails: [12v, 24v, 6v]}
  - temperatures: {period_s: 30}
  - dicke: {sources: [cold], seconds: 600}
  - wait: {seconds: 1800}
  - safe
"""


def _newest_sample(monitor) -> float:
    """Clock time of the monitor's newest sample (its daemon-state reading's stamp)."""
    stamps = [r.timestamp for r in monitor.latest() if r.metric == "reach_daemon_state"]
    return max(stamps, default=-math.inf)


@pytest.fixture(scope="module")
def day(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("day")
    settings = SimulationSettings(compression=3000.0, spectrum_period_s=300.0)
    with SimulatedReceiver(settings) as sim:
        directories = Directories(tmp / "run", tmp / "state")
        site = dataclasses.replace(
            sim.site(), monitoring=MonitoringSettings(cadence_s=CADENCE_S),
            daemon=DaemonSettings(runtime_dir=directories.runtime, state_dir=directories.state),
        )
        reachd = Daemon(site, sim.clock, directories, tick_s=0.05)
        reachd.start()
        start = sim.clock.now()
        serving = threading.Thread(target=reachd.serve)
        serving.start()
        job = reachd.submit("monitored.yaml", {"monitored.yaml": SCHEDULE}, "test")
        done = until(lambda: reachd.queue.get(job.id).state not in ("queued", "running"))
        assert done
        time.sleep(max(sim.clock.real_seconds(start + DAY_S - sim.clock.now()), 0.0))
        # Halt once the day's last slot is sampled: a cadence is 20 ms real here, and a
        # halt right at the day's end stopped the monitor before a slot it was late for.
        until(lambda: _newest_sample(reachd.monitor) >= start + DAY_S - CADENCE_S)
        end = sim.clock.now()
        reachd.halt("day over")
        serving.join(timeout=60)
        monitor = reachd.monitor
        reachd.close()
        database = MetricsDatabase(monitor.database_path)
        database.maintain(end)
        yield database, monitor, reachd.queue.get(job.id), start, end
        database.close()


def test_the_database_holds_one_row_per_series_every_cadence(day):
    database, monitor, _, start, _ = day
    # From the beginning, not from ``start``: the monitor may sample before the test reads
    # ``start`` after the daemon's start() (one cadence is 20 ms real at 3000x; once in CI).
    points = database.series("reach_disk_free_bytes", 0.0)
    assert len(points) == monitor.samples  # one row of this series per sample
    first, last = points[0].t, points[-1].t
    # The first sample's delay is real time at 3000x (0.1 s real is 5 minutes here), which
    # a loaded machine stretches (17 minutes once in CI): held to "before the run ends".
    # The span is therefore not held to a day less two cadences (86,227 s once in CI, the
    # first sample late and the last slot cut by the halt): the last sample is held to
    # the day's last slot, which the fixture waits for before it halts.
    assert first - start <= 2400.0
    assert last >= start + DAY_S - CADENCE_S
    slots = round((last - first) / CADENCE_S) + 1
    gaps = np.diff([p.t for p in points])
    assert np.median(gaps) == pytest.approx(CADENCE_S, abs=2.0)
    assert (gaps > 0).all()
    missing = slots - len(points)
    assert 0 <= missing <= monitor.skipped  # every missing slot one the monitor counted
    # One cadence is 20 ms real at 3000x, so a loaded machine falls behind and skips
    # slots (16 % once in CI, beside the other worker's solves); the bound only says the
    # monitor kept sampling through the day rather than stalling.
    assert missing <= 0.5 * slots, (missing, slots)
    rows_per_sample = {len(database.series(k, first, last)) for k in (
        "reach_daemon_state", "reach_disk_free_ratio", "reach_device_up{device=teensy}")}
    assert rows_per_sample == {len(points)}
    idle = database.series("reach_teensy_temperature_celsius{sensor=0x18}", start)
    assert len(idle) >= 0.9 * len(points)  # by the monitor while idle, at the run's safe points
    print(f"\nsimulated day: {len(points)} samples in {slots} slots of {CADENCE_S:g} s "
          f"({missing} missed), {database.count()} rows in the database")


def test_a_healthy_day_with_a_run_raises_no_alarm(day):
    # The run takes the hardware and brings it up: its devices are unknown until then,
    # and the TC-08 answers through the run's temperature log meanwhile.
    _, monitor, job, _, _ = day
    assert job.state == "completed", job.reason
    assert monitor.board.history == [], [a.message for _, a, _ in monitor.board.history]


def test_fifteen_minute_means_equal_the_means_of_their_minute_rows(day):
    database, _, _, start, _ = day
    for key in ("reach_tc08_temperature_celsius{channel=2,component=heated load thermistor}",
                "reach_teensy_temperature_celsius{sensor=0x1a}"):
        minute = database.series(key, start)
        buckets = database.quarter_means(key)
        assert len(buckets) >= 90
        by_bucket: dict[int, list[float]] = {}
        for p in minute:
            by_bucket.setdefault(int(p.t) - int(p.t) % QUARTER_S, []).append(p.value)
        for t, mean, n in buckets:
            values = by_bucket[t]
            assert n == len(values)
            assert mean == pytest.approx(np.mean(values), abs=1e-3)
        whole = sum(m * n for _, m, n in buckets) / sum(n for _, _, n in buckets)
        covered = [v for t, _, _ in buckets for v in by_bucket[t]]
        assert whole == pytest.approx(np.mean(covered), abs=1e-3)


def test_the_run_file_holds_the_readings_taken_during_the_run(day):
    database, _, job, _, _ = day
    assert job.state == "completed", job.reason
    contents = read_run_file(Path(job.run) / "run.h5")
    (health,) = contents.of_kind("monitoring")
    arrays = contents.read(health)
    keys = list(health.attrs["keys"])
    times, series = arrays["timestamps"], arrays["series"]
    present = {keys[i] for i in set(series.tolist())}
    assert "reach_spectrometer_packets_received_total" in present  # the run's counters
    assert any(k.startswith("reach_tc08_temperature_celsius") for k in present)  # its log
    assert any(k.startswith("reach_rail_on") for k in present)  # read at safe points
    assert any(k.startswith("reach_teensy_temperature_celsius") for k in present)
    stored = database.series("reach_disk_free_bytes", times.min(), times.max())
    in_file = times[np.array([keys[i] == "reach_disk_free_bytes" for i in series])]
    assert len(in_file) == len(stored) > 0
