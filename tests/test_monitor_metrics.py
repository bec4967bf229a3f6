"""The metrics database's queries and ``reach-run metrics``: since, boundaries, CSV, names.

Forty days of one-minute readings of a ramp (value = 10 + 0.001 x minute number, so a
15-minute mean is the value at its bucket's eighth minute, and a bucket cut in the wrong
place has the wrong mean) go into a real database file, which is then down-sampled with
the default retention (30 days of minutes). ``reach-run metrics`` reads it through a
site file, as an operator would.
"""

import csv
import io
import time

import numpy as np
import pytest
import yaml
from sites import DEVICES

from reach_receiver.cli import run_main
from reach_receiver.cli.health import format_health, parse_time
from reach_receiver.monitor.database import QUARTER_S, MetricsDatabase
from reach_receiver.monitor.readings import Reading

DAY_S = 86400
KEY = "reach_tec_temperature_celsius"


def ramp(t: float, start: float) -> float:
    return 10.0 + 0.001 * round((t - start) / 60)


@pytest.fixture(scope="module")
def database(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("metrics")
    now = float(int(time.time()) // QUARTER_S * QUARTER_S)
    start = now - 40 * DAY_S
    times = np.arange(start, now, 60.0)
    path = tmp / "metrics.sqlite"
    db = MetricsDatabase(path)
    db.write(Reading(KEY, ramp(t, start), "degC", t) for t in times)
    db.write(Reading("reach_device_up", 1.0, "1", t, labels={"device": d})
             for t in times[-10:] for d in ("tec", "teensy"))
    assert db.maintain(now) > 0
    db.close()
    site = tmp / "site.yaml"
    site.write_text(yaml.safe_dump({"devices": DEVICES, "monitoring": {"database": str(path)}}))
    return MetricsDatabase(path), now, start, site


def test_a_series_across_the_retention_boundary_is_means_then_minutes(database):
    db, now, start, _ = database
    points = db.series(KEY, now - 40 * DAY_S)
    quarters = [p for p in points if p.resolution_s == QUARTER_S]
    minutes = [p for p in points if p.resolution_s == 60]
    assert points == quarters + minutes  # the means first, then the minute rows
    assert minutes[0].t == now - 30 * DAY_S  # the retention cut
    assert quarters[-1].t + QUARTER_S == minutes[0].t  # no gap, no overlap
    assert quarters[0].t == start
    assert len(quarters) == 10 * DAY_S // QUARTER_S
    assert len(minutes) == 30 * DAY_S // 60
    assert np.all(np.diff([p.t for p in points]) > 0)
    expected = [ramp(q.t + 7 * 60, start) for q in quarters]
    np.testing.assert_allclose([q.value for q in quarters], expected, atol=1e-3)
    np.testing.assert_allclose([m.value for m in minutes], [ramp(m.t, start) for m in minutes],
                               atol=1e-9)


def test_a_recent_window_is_minute_data_only(database):
    db, now, _, _ = database
    points = db.series(KEY, now - DAY_S)
    assert len(points) == DAY_S // 60
    assert {p.resolution_s for p in points} == {60}
    assert points[0].t == now - DAY_S
    bounded = db.series(KEY, now - DAY_S, now - DAY_S + 600)
    assert [p.t for p in bounded] == [now - DAY_S + 60 * i for i in range(11)]


@pytest.mark.parametrize(("text", "back_s"), [("90s", 90), ("15m", 900), ("24h", DAY_S),
                                              ("30d", 30 * DAY_S), ("2w", 14 * DAY_S),
                                              ("1.5h", 5400)])
def test_since_takes_durations_back_from_now(text, back_s):
    assert parse_time(text, 1.7e9) == 1.7e9 - back_s


def test_since_takes_iso_times_in_utc_and_unix_seconds():
    assert parse_time("2026-03-01T18:00Z", 0) == 1772388000.0
    assert parse_time("2026-03-01T18:00", 0) == 1772388000.0  # no offset: UTC
    assert parse_time("2026-03-01T20:00+02:00", 0) == 1772388000.0
    assert parse_time("1700000000", 0) == 1.7e9
    with pytest.raises(ValueError, match="24h, 30d"):
        parse_time("yesterday", 0)


def test_metrics_exports_a_day_as_csv(database, tmp_path, capsys):
    _, now, start, site = database
    out = tmp_path / "tec.csv"
    asked = time.time()
    assert run_main(["metrics", KEY, "--since", "24h", "--site", str(site),
                     "--csv", str(out)]) == 0
    assert f"written to {out}" in capsys.readouterr().out
    rows = list(csv.reader(io.StringIO(out.read_text())))
    assert rows[0] == ["time_utc", "unix_s", f"{KEY} (degC)", "status"]
    body = rows[1:]
    first = float(body[0][1])
    assert asked - DAY_S <= first <= time.time() - DAY_S + 60  # 24 h back from the real now
    assert len(body) == (now - 60 - first) / 60 + 1  # every minute up to the newest row
    for stamp, unix, value, status in (body[0], body[-1]):
        assert stamp.endswith("Z")
        assert float(value) == pytest.approx(ramp(float(unix), start), abs=1e-9)
        assert status == "nominal"
    assert float(body[-1][1]) == now - 60


def test_metrics_prints_every_series_of_a_metric(database, capsys):
    site = database[3]
    assert run_main(["metrics", "reach_device_up", "--since", "1h", "--site", str(site)]) == 0
    text = capsys.readouterr().out
    assert "reach_device_up{device=tec} (1): 10 points" in text
    assert "reach_device_up{device=teensy} (1): 10 points" in text


@pytest.mark.parametrize(("name", "close"), [
    ("reach_tec_temprature_celsius", KEY),
    ("reach_device_up{device=vna}", "reach_device_up{device=tec}, reach_device_up{device=teensy}"),
])
def test_an_unknown_name_is_refused_with_close_names(database, capsys, name, close):
    assert run_main(["metrics", name, "--site", str(database[3])]) == 2
    err = capsys.readouterr().err
    assert f"no series {name!r}" in err
    assert f"close names: {close}" in err


def test_csv_of_several_series_and_a_missing_database_are_refused(database, tmp_path, capsys):
    site = database[3]
    assert run_main(["metrics", "reach_device_up", "--site", str(site), "--csv", "-"]) == 2
    assert "is 2 series" in capsys.readouterr().err
    assert run_main(["metrics", KEY, "--database", str(tmp_path / "none.sqlite")]) == 1
    assert "no metrics database" in capsys.readouterr().err
    assert run_main(["metrics", KEY, "--site", str(site), "--since", "soon"]) == 2


def test_health_is_readable_at_a_glance():
    now = 1.7e9
    health = {
        "alarms": ["tec fault: reach_tec_fault_bits = 8, above 0.5"],
        "cadence_s": 60.0,
        "readings": [
            {"key": "reach_disk_free_bytes", "value": 4.2e9, "unit": "B", "status": "error",
             "t": now - 10},
            {"key": "reach_tc08_temperature_celsius{channel=1,component=MS1 switch}",
             "value": 25.3125, "unit": "degC", "status": "nominal", "t": now - 10},
            {"key": "reach_tc08_temperature_celsius{channel=3,component=MS3 switch}",
             "value": None, "unit": "degC", "status": "error", "t": now - 300},
        ],
    }
    lines = format_health(health, now)
    assert lines[0] == "alarms: 1 raised"
    assert lines[1] == "  ! tec fault: reach_tec_fault_bits = 8, above 0.5"
    assert "10 s ago" in lines[2]
    disk, tc1, tc3 = lines[3:]
    assert disk.split() == ["disk_free_bytes", "4.20", "GB", "[error]"]
    assert tc1.split()[:4] == ["tc08_temperature_celsius", "1,", "MS1", "switch"]
    assert tc1.rstrip().endswith("25.31 degC")
    assert tc3.split()[:3] == ["3,", "MS3", "switch"]  # the metric named once
    assert "[error]" in tc3
    assert "(300 s old)" in tc3
    assert format_health({}, now) == ["health: no readings (the daemon has no monitor)"]


def test_readings_within_one_second_are_two_rows(tmp_path):
    """A late sample beside the next punctual one (0.3 s apart): neither replaces the other."""
    db = MetricsDatabase(tmp_path / "m.sqlite")
    t0 = 1.7e9 + 59.6
    db.write([Reading(KEY, 1.0, "degC", t0)])
    db.write([Reading(KEY, 2.0, "degC", t0 + 0.3)])
    points = db.series(KEY, t0 - 1)
    assert [(p.t, p.value) for p in points] == [(pytest.approx(t0), 1.0),
                                                (pytest.approx(t0 + 0.3), 2.0)]
    assert db.series(KEY, t0 + 0.1) == points[1:]  # bounds to the millisecond
    db.close()


def test_a_file_with_whole_second_times_is_converted_when_opened(tmp_path):
    import sqlite3

    path = tmp_path / "old.sqlite"
    db = MetricsDatabase(path)
    db.write([Reading(KEY, 3.5, "degC", 1.7e9)])
    db.close()
    with sqlite3.connect(path) as old:  # as the first layout wrote it
        old.execute("UPDATE minute SET t = t / 1000")
        old.execute("PRAGMA user_version = 0")
    db = MetricsDatabase(path)
    assert [(p.t, p.value) for p in db.series(KEY, 0)] == [(1.7e9, 3.5)]
    db.close()
