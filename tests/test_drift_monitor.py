"""The calibration drift alarm through the run layer and the daemon's monitor.

The simulated receiver runs at its default 3000x; a short calibrating schedule (four
calibrators and the antenna, a minute per Dicke position, the VNA and the S11s, a solve)
runs three times, each with the daemon's :class:`~reach_receiver.monitor.Monitor` watching
(as ``reachd`` runs a job; its report is not drawn, to keep the test short). The first
run has no previous solution; the second measures no antenna spectrum (as an observing
run calibrates before its first antenna cycle), so it compares with the first on the
antenna as the first run measured it, and must find the receiver stable (a passed check,
no alarm); before the third the simulated LNA
warms by 20 K (:class:`~reach_receiver.sim.drift.NoiseWaveDrift`), and its calibration
must raise the ``calibration drift`` alarm in words, with the drift's size and band, and
store a failed check. How large a drift must be to be seen, and how often a stable
receiver alarms, is measured at the engine level over seeds (``tests/test_drift.py``).
"""

import dataclasses

import pytest

from reach_receiver.config.monitoring import DRIFT_ALARM, DRIFT_METRIC, MonitoringSettings
from reach_receiver.monitor import Monitor
from reach_receiver.run import compile_text
from reach_receiver.run.session import RunSession
from reach_receiver.sim.drift import NoiseWaveDrift
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings
from reach_receiver.store import read_run_file

CALIBRATING = """\
schedule: drift
steps:
  - initialise: {}
  - temperatures: {period_s: 10}
  - vna_calibrate: {}
  - s11: {targets: [cold, hot, c10open, c10short, ant, lna]}
  - dicke: {sources: [cold, hot, c10open, c10short, ant], seconds: 60}
  - calibrate: {}
  - safe: {}
"""
#: The second run's: no antenna spectrum before the solve.
NO_ANTENNA = CALIBRATING.replace("sources: [cold, hot, c10open, c10short, ant]",
                                 "sources: [cold, hot, c10open, c10short]")
#: How much warmer the LNA is at the third calibration (K).
LNA_K = 20.0


def _drift_check(run_file) -> dict | None:
    checks = {m.name: m.attrs for m in read_run_file(run_file).of_kind("check")}
    return checks.get("calibration_drift")


@pytest.fixture(scope="module")
def three(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("drift")
    with SimulatedReceiver(SimulationSettings(spectrum_period_s=60.0)) as sim:
        site = dataclasses.replace(sim.site(), monitoring=MonitoringSettings(cadence_s=600.0))
        monitor = Monitor(site, sim.clock, tmp / "state", tmp)
        schedules = [compile_text(text, "drift.yaml", site=site)
                     for text in (CALIBRATING, NO_ANTENNA, CALIBRATING)]
        checks, alarms = [], []
        for index, schedule in enumerate(schedules):
            if index == 2:  # the LNA warms by LNA_K within minutes, then stays
                elapsed = sim.clock.now() - sim.physics._t0
                drift = NoiseWaveDrift(ramp_k_per_day=1440.0, start_s=elapsed, limit_k=LNA_K)
                sim.physics.config = dataclasses.replace(sim.physics.config, drift=drift)
            summary = RunSession(schedule, site, sim.clock, tmp / "runs", monitor=monitor,
                                 report=False).run()
            checks.append(_drift_check(summary.run_file))
            alarms.append(monitor.alarms())
        yield checks, alarms, monitor


def test_a_stable_receiver_passes_the_drift_check(three):
    checks, alarms, _ = three
    assert checks[0] is None  # nothing to compare with
    assert checks[1]["passed"], checks[1]
    details = checks[1]["details"]
    assert details["previous"].startswith("run ")
    assert details["source"] == "ant"  # not the calibrator the run validates on
    assert details["source_measured_in"] == details["previous"]
    assert alarms[0] == alarms[1] == []


def test_the_warmed_lna_raises_the_alarm_with_size_and_band(three):
    checks, alarms, monitor = three
    (text,) = alarms[2]
    assert text.startswith("calibration drift on 'ant': "), text
    assert " K (" in text, text
    assert " MHz against the solution of " in text, text
    assert "threshold 3.9 sigma" in text, text
    assert not checks[2]["passed"]
    details = checks[2]["details"]
    assert details["sigma"] > details["threshold_sigma"]
    assert details["source_measured_in"] == "this run"
    (raised,) = [a for event, a, _ in monitor.board.history if event == "raised"]
    assert raised.id == f"{DRIFT_ALARM}: {DRIFT_METRIC}"
    print(f"\n{text}")
