"""A healthy simulated day of ``reachd --sim``, observe.yaml and calibrate.yaml: no alarm.

``reachd --sim`` runs as its own process (the CLI, its default 3000x clock: a day in
29 s, and the simulated site's health cadence) with ``-v``; ``observe.yaml`` and
``calibrate.yaml`` are submitted over the control socket as the shipped files, shortened
only through their own variables so that both fit in the day on two shared cores: four
calibrators, one-minute Dicke positions, one night cycle. The night starts 15 h of
sidereal time after the jobs are submitted: at 3000x the runs' own computing (the Dicke
cycles stored, the solves, the reports) is real time, some 13 simulated hours before the
observe job reaches its ``wait``, so a later start is a short wait and an earlier one
would wait a whole sidereal day. Both jobs must complete, a simulated day must
pass, and by then neither the status reply nor the daemon's log may have held an alarm:
not at a run's start (devices not yet brought up are unknown), not during the observe
step (the TC-08 answers through the run's temperature log), not for the enclosure at
the simulator's 25 C, not for the spectrometer between integrations.
"""

import os
import re
import signal
import subprocess
import sys
import time
from datetime import datetime, timezone

import pytest

from reach_receiver.clock import CompressedClock
from reach_receiver.config.site import load_site
from reach_receiver.daemon.client import DaemonClient
from reach_receiver.daemon.control import SOCKET_FILE
from reach_receiver.schedule.lst import local_sidereal_time_h
from tests.test_daemon_link import until
from tests.test_status_page import ENTRY, SCHEDULES

DAY_S = 86400.0


def _shortened(name: str, start_lst_h: float) -> dict[str, str]:
    """The shipped schedule and its include, with shorter values of their own variables."""
    texts = {name: (SCHEDULES / name).read_text(),
             "common.yaml": (SCHEDULES / "common.yaml").read_text()}
    changes = [
        ("common.yaml", r"calibrators: \[cold, hot, r25, [^]]*\]",
         "calibrators: [cold, hot, c10open, c10short]"),
        ("common.yaml", r"dicke_seconds: 600", "dicke_seconds: 60"),
        (name, r"night_cycles: 60", "night_cycles: 1"),
        (name, r"position_seconds: 200", "position_seconds: 60"),
        (name, r"start_lst_h: 22\.0", f"start_lst_h: {start_lst_h:.3f}"),
    ]
    for file, pattern, value in changes:
        texts[file], n = re.subn(pattern, value, texts[file])
        assert n == 1 or (name, file) == ("calibrate.yaml", name), (name, pattern)
    return texts


@pytest.fixture(scope="module")
def day(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("healthy")
    site_file = tmp / "site.yaml"
    with (tmp / "reachd.log").open("w") as log:
        process = subprocess.Popen(
            [sys.executable, "-c", ENTRY, "--sim", "-v", "--state-dir", str(tmp / "state"),
             "--runtime-dir", str(tmp / "run"), "--site-out", str(site_file)],
            stdout=subprocess.PIPE, stderr=log, text=True,
            env={**os.environ, "NOTIFY_SOCKET": ""},
        )
    try:
        for line in process.stdout:
            if "serving" in line:
                break
        site = load_site(site_file)
        clock = CompressedClock(site.simulation["compression"], site.simulation["start"],
                                site.simulation["monotonic_origin"])
        start = clock.now()
        lst = local_sidereal_time_h(datetime.fromtimestamp(start, tz=timezone.utc),
                                    site.longitude_deg)
        jobs = []
        with DaemonClient(tmp / "run" / SOCKET_FILE) as client:
            for name in ("observe.yaml", "calibrate.yaml"):
                files = _shortened(name, (lst + 15.0) % 24.0)
                jobs.append(client.request("submit", schedule=name, files=files)["job"]["id"])

            def ended() -> list[dict] | None:
                listed = {j["id"]: j for j in client.request("queue")["jobs"]}
                done = [listed[i] for i in jobs]
                return done if all(j["state"] not in ("queued", "running") for j in done) \
                    else None

            finished = until(ended, timeout_s=240)
            time.sleep(max(clock.real_seconds(start + DAY_S - clock.now()), 0.0))
            status = client.request("status")
        yield finished, status, start, clock.now(), (tmp / "reachd.log")
    finally:
        process.send_signal(signal.SIGTERM)
        process.wait(timeout=60)
        process.stdout.close()


def test_both_schedules_complete_within_the_day(day):
    jobs, _, start, end, _ = day
    assert [j["state"] for j in jobs] == ["completed", "completed"], jobs
    assert end - start >= DAY_S


def test_no_alarm_is_raised_all_day(day):
    _, status, _, _, log = day
    text = log.read_text()  # raised and cleared again would leave the reply empty
    assert "alarm raised" not in text, [ln for ln in text.splitlines() if "alarm" in ln]
    health = status["health"]
    assert health["alarms"] == []
    assert health["alarm_details"] == []
    assert status["alarms"] == []  # the daemon's own
    up = {r["key"]: r["value"] for r in health["readings"] if r["key"].startswith(
        "reach_device_up")}
    assert up["reach_device_up{device=tc08}"] == 1.0, up  # read while idle again
    assert up["reach_device_up{device=teensy}"] == 1.0, up
