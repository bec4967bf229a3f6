"""Duration estimates, the dry-run timeline, sidereal time and impossible-timing checks."""

import random
from datetime import datetime, timedelta, timezone
from textwrap import dedent

import numpy as np
import pytest
from sites import planning_site

from calibration.core.sidereal import apparent_lst_h
from reach_receiver.devices.vna_settings import SweepSettings
from reach_receiver.run import compile_text
from reach_receiver.run import steps as s
from reach_receiver.schedule.compile import ScheduleError
from reach_receiver.schedule.lst import SIDEREAL_RATE, local_sidereal_time_h, next_utc_at_lst
from reach_receiver.schedule.timing import (
    estimated_duration_s,
    format_timeline,
    hms,
    sweep_duration_s,
    timeline,
)

START = datetime(2026, 11, 22, 12, 0, tzinfo=timezone.utc)
DEFAULT_SWEEP_S = 1401 * 20 / 1e3 * 1.2 + 2  # SweepSettings' defaults (REACH's)


#: The spectrometer's accumulation period of these tests' site (s).
PERIOD_S = 30.0
SITE = planning_site(PERIOD_S, longitude_deg=0.0)


def compiled(text: str, start: datetime = START) -> s.Schedule:
    return compile_text(dedent(text), "t.yaml", start_utc=start, site=SITE)


def durations(schedule: s.Schedule, **kwargs) -> list[tuple[float, float, int]]:
    kwargs.setdefault("spectrum_period_s", PERIOD_S)
    entries = timeline(schedule, start_utc=START, longitude_deg=21.52, **kwargs)
    return [(e.start_s, e.duration_s, e.depth) for e in entries]


# --------------------------------------------------------------------------- estimates
def test_sweep_estimate_uses_points_averages_and_bandwidth():
    assert sweep_duration_s(SweepSettings()) == pytest.approx(DEFAULT_SWEEP_S, abs=1e-9)
    fast = SweepSettings(points=201, averages=1, ifbw_hz=1e4)
    assert sweep_duration_s(fast) == pytest.approx(201 / 1e4 * 1.2 + 2, abs=1e-12)


def test_timeline_of_a_small_schedule():
    schedule = compiled(
        """\
        schedule: small
        steps:
          - initialise
          - connect: {source: hot}
          - spectrum: {source: hot, seconds: 100}
          - dicke: {sources: [hot, cold], seconds: 60}
          - temperatures
          - tec: {setpoint_c: 25}
          - tec: {setpoint_c: 25, wait: {hold_s: 300}}
          - calibrate
          - safe
        """
    )
    spectrum = 100 + 2 * 30
    dicke = 2 * 3 * (60 + 2 * 30)
    expected = [5, 1, spectrum, dicke, 0, 1, 300, 10, 1]
    got = durations(schedule)
    assert [d for _, d, _ in got] == pytest.approx(expected, abs=1e-9)
    starts = [sum(expected[:i]) for i in range(len(expected))]
    assert [t for t, _, _ in got] == pytest.approx(starts, abs=1e-9)
    total = estimated_duration_s(
        schedule, start_utc=START, longitude_deg=0.0, spectrum_period_s=PERIOD_S
    )
    assert total == pytest.approx(sum(expected), abs=1e-9)
    faster = estimated_duration_s(
        schedule, start_utc=START, longitude_deg=0.0, spectrum_period_s=1.0
    )
    assert faster == pytest.approx(sum(expected) - 7 * 2 * 29, abs=1e-9)


def test_latest_vna_calibration_sets_the_sweep_of_later_measurements():
    schedule = compiled(
        """\
        schedule: vna
        steps:
          - initialise
          - s11: {targets: [hot, cold]}
          - vna_calibrate: {sweep: {points: 201, averages: 1, ifbw_hz: 1000}}
          - test_load_check
          - s11: {targets: [hot, cold, lna]}
        """
    )
    small = 201 / 1e3 * 1.2 + 2
    got = [d for _, d, _ in durations(schedule)]
    assert got == pytest.approx([5, 2 * DEFAULT_SWEEP_S, 3 * small, small, 3 * small], abs=1e-9)


def test_observe_counts_spectra_and_interleaved_test_load_sweeps():
    schedule = compiled(
        """\
        schedule: obs
        steps:
          - initialise
          - observe: {cycles: 13, seconds: 60, test_load_every: 6}
        """
    )
    expected = 13 * 3 * (60 + 2 * 30) + 2 * DEFAULT_SWEEP_S
    assert durations(schedule)[1][1] == pytest.approx(expected, abs=1e-9)


def test_repeat_counts_periods_and_only_the_last_repetition_s_own_duration():
    schedule = compiled(
        """\
        schedule: rep
        steps:
          - initialise
          - repeat:
              count: 3
              period_s: 3600
              steps:
                - spectrum: {source: ant, seconds: 100}
                - repeat:
                    count: 2
                    steps: [{wait: {seconds: 50}}]
          - safe
        """
    )
    one = 160 + 2 * 50
    got = durations(schedule)
    assert got == [
        (0.0, 5.0, 0),
        (5.0, pytest.approx(2 * 3600 + one), 0),
        (5.0, 160.0, 1),
        (165.0, 100.0, 1),
        (165.0, 50.0, 2),
        (pytest.approx(5.0 + 2 * 3600 + one), 1.0, 0),
    ]


def test_waits_until_a_utc_time_and_a_sidereal_time():
    until = START + timedelta(hours=1)
    schedule = compiled(
        f"""\
        schedule: waits
        steps:
          - initialise
          - wait: {{until_utc: "{until.isoformat()}"}}
          - wait: {{until_lst_h: 4.5}}
        """
    )
    got = durations(schedule)
    assert got[1][1] == pytest.approx(3600 - 5, abs=1e-6)
    reached = START + timedelta(seconds=got[2][0] + got[2][1])
    assert local_sidereal_time_h(reached, 21.52) == pytest.approx(4.5, abs=1e-6)
    assert 0 <= got[2][1] < 86_164.1


def test_format_timeline_is_a_table_with_places_and_a_total():
    schedule = compiled(
        """\
        schedule: fmt
        steps:
          - initialise
          - repeat:
              count: 2
              steps: [{dicke: {sources: [hot], seconds: 600}}]
        """
    )
    entries = timeline(schedule, start_utc=START, longitude_deg=0.0, spectrum_period_s=PERIOD_S)
    text = format_timeline(entries)
    lines = text.splitlines()
    assert lines[0].split() == ["start", "duration", "step", "where"]
    assert "t.yaml:3" in lines[1]
    assert "0:00:05" in lines[1]
    assert "    Dicke cycles of hot" in lines[3]  # one level deeper than the repeat
    assert "t.yaml:6" in lines[3]
    total = 5 + 2 * 3 * (600 + 60)
    assert lines[-1].split() == ["total", hms(total)]
    assert hms(total) == "1:06:05"


def test_hms():
    assert hms(0) == "0:00:00"
    assert hms(3725.4) == "1:02:05"
    assert hms(90_000) == "25:00:00"


# --------------------------------------------------------------------------- impossible timing
def test_repeat_period_shorter_than_a_repetition_is_a_problem():
    text = """\
        schedule: rep
        steps:
          - initialise
          - repeat:
              count: 4
              period_s: 600
              steps:
                - dicke: {sources: [hot, cold], seconds: 60}
        """
    with pytest.raises(ScheduleError) as caught:
        compiled(text)
    (problem,) = caught.value.problems
    assert (problem.line, problem.key) == (4, "repeat.period_s")
    assert "0:12:00 estimated" in problem.message
    compiled(text.replace("600", "720"))  # exactly one repetition long is fine


def test_wait_until_a_time_the_schedule_cannot_reach_yet_is_a_problem():
    text = """\
        schedule: late
        steps:
          - initialise
          - dicke: {sources: [hot], seconds: 3600}
          - wait: {until_utc: "2026-11-22T13:00:00Z"}
        """
    with pytest.raises(ScheduleError) as caught:
        compiled(text)  # starts 12:00, reaches the wait after 3 h
    (problem,) = caught.value.problems
    assert (problem.line, problem.key) == (5, "wait.until_utc")
    assert "2026-11-22T15:03:05Z" in problem.message
    early = compiled(text, start=START - timedelta(hours=4))
    assert isinstance(early.steps[2], s.Wait)


def test_wait_in_the_past_fails_by_default_start_now():
    with pytest.raises(ScheduleError, match=r"t.yaml:2: wait.until_utc: 2001"):
        compile_text(
            "schedule: x\nsteps: [initialise, {wait: {until_utc: 2001-01-01T00:00:00Z}}]\n",
            "t.yaml",
        )


# --------------------------------------------------------------------------- sidereal time
def _hms_h(hours: int, minutes: int, seconds: float) -> float:
    return hours + minutes / 60 + seconds / 3600


def _meeus_gmst_h(utc: datetime) -> float:
    """Meeus eq. 12.4, the IAU 1982 mean sidereal time, with UTC for UT1: good to ~2 s."""
    days = (utc.timestamp() - 946_728_000.0) / 86_400.0
    centuries = days / 36_525.0
    degrees = 280.46061837 + 360.98564736629 * days + 0.000387933 * centuries**2
    return (degrees % 360.0) / 15.0


def test_apparent_sidereal_time_matches_meeus_example_12a():
    # 1987-04-10 0h UT (UT1): apparent GST 13h10m46.1351s. UT1 - UTC was -0.2911 s that
    # day (IERS); the newer IAU 2006/2000A models and polar motion move it by a few ms.
    utc = datetime(1987, 4, 10, 0, 0, tzinfo=timezone.utc)
    expected_s = _hms_h(13, 10, 46.1351) * 3600 - 0.2911 * SIDEREAL_RATE
    assert local_sidereal_time_h(utc, 0.0) * 3600 == pytest.approx(expected_s, abs=0.01)


def test_sidereal_time_agrees_with_the_closed_form_over_times_and_longitudes():
    rng = random.Random(38)
    stamps = [rng.uniform(0, 2.2e9) for _ in range(300)]  # 1970 to 2039
    for longitude in (-150.0, 0.0, 21.52, 179.9):
        got = apparent_lst_h(stamps, longitude)
        expected = [
            (_meeus_gmst_h(datetime.fromtimestamp(t, tz=timezone.utc)) + longitude / 15) % 24
            for t in stamps
        ]
        # UT1 - UTC (< 0.9 s) and the equation of the equinoxes (< 1.2 s)
        difference_s = ((got - np.array(expected) + 12) % 24 - 12) * 3600
        assert np.max(np.abs(difference_s)) < 2.2
        assert np.all((got >= 0) & (got < 24))


def test_naive_times_are_utc_and_one_call_stamps_many():
    naive = datetime(1987, 4, 10, 19, 21)
    aware = naive.replace(tzinfo=timezone.utc)
    assert local_sidereal_time_h(naive, 21.52) == local_sidereal_time_h(aware, 21.52)
    stamps = [aware.timestamp() + 3600 * k for k in range(5)]
    singly = [local_sidereal_time_h(datetime.fromtimestamp(t, tz=timezone.utc), 21.52)
              for t in stamps]
    np.testing.assert_allclose(apparent_lst_h(stamps, 21.52), singly, rtol=0, atol=1e-12)
    assert apparent_lst_h([], 21.52).shape == (0,)


def test_sidereal_day_is_shorter_than_a_solar_day():
    rng = random.Random(3856)
    day = timedelta(hours=24 / SIDEREAL_RATE)
    for _ in range(20):
        t = datetime(2000, 1, 1, tzinfo=timezone.utc) + timedelta(days=rng.uniform(0, 10_000))
        lon = rng.uniform(-180, 180)
        # a mean sidereal day: the apparent one differs by the day's change of nutation
        # (ms) and of UT1 - UTC (ms)
        change_h = (local_sidereal_time_h(t + day, lon) - local_sidereal_time_h(t, lon) + 12) % 24
        assert abs(change_h - 12) * 3600 < 0.02


def test_next_utc_at_lst_lands_on_the_lst_within_one_sidereal_day():
    rng = random.Random(20261122)
    for _ in range(200):
        after = datetime(2020, 1, 1, tzinfo=timezone.utc) + timedelta(
            seconds=rng.uniform(0, 20 * 365.25 * 86400)
        )
        lst = rng.uniform(0, 24)
        lon = rng.uniform(-180, 180)
        found = next_utc_at_lst(after, lst, lon)
        assert after <= found < after + timedelta(hours=24 / SIDEREAL_RATE)
        error_h = (local_sidereal_time_h(found, lon) - lst + 12) % 24 - 12
        assert abs(error_h) < 1e-8


def test_next_utc_at_lst_now_is_now():
    now = datetime(2026, 11, 22, 18, 0, tzinfo=timezone.utc)
    lst = local_sidereal_time_h(now, 21.52)
    found = next_utc_at_lst(now, lst, 21.52)
    assert abs((found - now).total_seconds()) < 1e-3
