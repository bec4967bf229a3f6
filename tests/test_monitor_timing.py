"""Monitoring never interrupts a Dicke position and delays the next one by a stated bound.

The same schedule (Dicke cycles of three sources) runs twice against one simulated
receiver (real transports; the compressed clock at 100x, 6 s spectra): once as a plain
run with no monitor (monitoring off), once with the daemon's :class:`Monitor` sampling
every 30 clock seconds, so that each safe point between positions reads the board, its
I2C sensors and the TEC (the TC-08 is the run's own temperature log's, shared: its
readings fall inside integrations, as the log's always do, and are not device reads of
the monitor).
From the run files:

* **never interrupted**: each position holds its ``n`` spectra back to back (starts one
  period apart) and the same integration time, on and off; and no reading the monitor
  took from a device at a safe point is stamped inside any position's integration
  ``[first start, last start + period]``.
* **delayed at most by the bound**: the gap between one position's last spectrum and the
  next position's first is, with monitoring on, at most the largest such gap with it off
  plus the longest safe point (:attr:`RunWatch.safe_point_max_s`, real seconds, times the
  compression) plus one spectrum period. Gaps within a cycle are compared; those between
  cycles are not, because there the cycle is stored, whose real time on a shared, loaded
  machine varies by tens of milliseconds from one run to the next, and at 300x that was
  several spectra either way (42 s against 24 s once, with no monitoring in it). The clock
  runs at 100x, not faster: a position change's own real-time jitter on a loaded machine
  (tens of ms, the other test worker beside it) is then below one spectrum, where at 300x
  it reached three. On site (no compression, 1 s spectra) the bound is one spectrum and a
  few tens of milliseconds per position change. Why: a safe point only runs between
  positions; the spectrometer keeps integrating meanwhile, so the run waits for the spectrum in
  progress when it is done (at most one period, the first is discarded anyway) and the
  rest of the cycle shifts by no more than that. The safe point itself must stay short:
  under :data:`SAFE_POINT_LIMIT_S` real seconds (a fraction of REACH's 1 s spectrum on
  site, where the clock is not compressed).
"""

import dataclasses
import itertools

import numpy as np
import pytest

from reach_receiver.config.monitoring import MonitoringSettings
from reach_receiver.monitor import Monitor
from reach_receiver.run import compile_text
from reach_receiver.run.measure import DICKE_POSITIONS
from reach_receiver.run.session import RunSession
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings
from reach_receiver.store import read_run_file

COMPRESSION = 100.0
PERIOD_S = 6.0
CADENCE_S = 30.0
#: The longest a safe point may take (real seconds): the board, I2C and TEC over serial.
SAFE_POINT_LIMIT_S = 0.25
#: Readings the monitor takes from the devices themselves at the run's safe points.
ACTIVE = ("reach_switch_", "reach_rail_", "reach_frontend_", "reach_teensy_", "reach_tec_")
SCHEDULE = """\
schedule: timed
steps:
  - initialise: {rails: [12v, 24v, 6v, tec]}
  - dicke: {sources: [cold, hot, r25], seconds: 60}
  - safe
"""


def _positions(run_file):
    """Each Dicke position's spectrum starts, in order, and the run file's contents."""
    contents = read_run_file(run_file)
    out = []
    for cycle in contents.of_kind("dicke"):
        arrays = contents.read(cycle)
        out += [np.asarray(arrays[f"{p}/timestamps"], dtype=float) for p in DICKE_POSITIONS]
    return out, contents


def _gaps(positions):
    """Clock seconds from the end of each position's last spectrum to the next's first."""
    return np.array([b[0] - (a[-1] + PERIOD_S) for a, b in itertools.pairwise(positions)])


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("timing")
    settings = SimulationSettings(compression=COMPRESSION, spectrum_period_s=PERIOD_S)
    with SimulatedReceiver(settings) as sim:
        site = sim.site()
        schedule = compile_text(SCHEDULE, "timed.yaml", site=site)
        off = RunSession(schedule, site, sim.clock, tmp / "off").run()
        monitored = dataclasses.replace(site, monitoring=MonitoringSettings(cadence_s=CADENCE_S))
        monitor = Monitor(monitored, sim.clock, tmp / "state", tmp / "on")
        monitor.start()
        try:
            on = RunSession(schedule, monitored, sim.clock, tmp / "on", monitor=monitor).run()
        finally:
            monitor.close()
    return off.run_file, on.run_file, monitor.last_watch


def test_positions_are_never_interrupted_by_monitoring(runs):
    off, on = (_positions(f)[0] for f in runs[:2])
    assert len(off) == len(on) == 3 * len(DICKE_POSITIONS)
    for starts_off, starts_on in zip(off, on, strict=True):
        assert len(starts_on) == len(starts_off) == 10
        np.testing.assert_allclose(np.diff(starts_on), PERIOD_S, atol=1e-3)
        np.testing.assert_allclose(np.diff(starts_off), PERIOD_S, atol=1e-3)
    positions, contents = _positions(runs[1])
    (health,) = contents.of_kind("monitoring")
    arrays = contents.read(health)
    keys = list(health.attrs["keys"])
    active = np.array([keys[i].startswith(ACTIVE) for i in arrays["series"]])
    times = np.asarray(arrays["timestamps"])[active]
    assert len(times) > 0
    spans = [(starts[0], starts[-1] + PERIOD_S) for starts in positions]
    inside = [t for t in times for lo, hi in spans if lo < t < hi]
    assert not inside, f"device reads inside an integration at {inside[:5]}"
    between = sum(1 for a, b in itertools.pairwise(spans) if any(a[1] <= t <= b[0] for t in times))
    assert between >= len(spans) // 2  # the safe points between positions did sample


def test_the_next_position_is_delayed_at_most_by_the_bound(runs):
    off, on, watch = runs
    assert watch is not None
    assert watch.safe_points >= len(DICKE_POSITIONS)
    assert watch.safe_point_max_s < SAFE_POINT_LIMIT_S, watch.safe_point_max_s
    gaps_off, gaps_on = _gaps(_positions(off)[0]), _gaps(_positions(on)[0])
    step = len(DICKE_POSITIONS)
    within = np.arange(len(gaps_off)) % step != step - 1  # else: the cycle is stored between
    delay_s = watch.safe_point_max_s * COMPRESSION + PERIOD_S
    bound = gaps_off[within].max() + delay_s
    print(f"\ngaps within a cycle (clock s): off {np.round(gaps_off[within], 1).tolist()}, "
          f"on {np.round(gaps_on[within], 1).tolist()}; bound {bound:.1f}; between cycles "
          f"off {np.round(gaps_off[~within], 1).tolist()}, on {np.round(gaps_on[~within], 1)}")
    assert gaps_on[within].max() <= bound
    print(f"{watch.safe_points} safe points, longest {1e3 * watch.safe_point_max_s:.1f} ms "
          f"real, mean {1e3 * watch.safe_point_s / watch.safe_points:.1f} ms")
