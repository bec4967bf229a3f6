"""``reach-run``'s command words, run as the installed command is: a process of its own.

The words, their own ``--help`` with exit codes, a typo named with the closest word,
bare ``reach-run`` as usage, ``--version`` everywhere, ``--json`` that parses, shell
completion that bash accepts, ``recover`` of a killed run's parts, and ``status``
against a real ``reachd --sim`` as a summary within 80 columns.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from reach_receiver.cli.commands import COMMANDS

ROOT = Path(__file__).resolve().parents[1]
ENTRY = "from reach_receiver.cli import {main}; import sys; sys.exit({main}(sys.argv[1:]))"


def cli(*args: str, main: str = "run_main", cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", ENTRY.format(main=main), *args],
        capture_output=True, text=True, timeout=120, cwd=cwd,
    )


def test_bare_reach_run_prints_its_usage_and_exits_2():
    done = cli()
    assert done.returncode == 2
    for word in COMMANDS:
        assert f"  {word} " in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize(("typo", "hint"), [("stauts", "did you mean 'status'?"),
                                            ("metrcis", "did you mean 'metrics'?"),
                                            ("doctor", "see reach-run --help")])
def test_an_unknown_word_is_named_not_taken_for_a_schedule(typo, hint):
    done = cli(typo)
    assert done.returncode == 2
    assert done.stderr.strip() == f"reach-run: unknown command {typo!r}; {hint}"


@pytest.mark.parametrize("word", [w for w in COMMANDS if w != "run"])
def test_each_command_has_its_own_help_with_exit_codes_and_a_version(word):
    done = cli(word, "--help")
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"usage: reach-run {word}")
    assert "exit codes: 0 " in done.stdout
    assert max(map(len, done.stdout.splitlines())) <= 80
    version = cli(word, "--version")
    assert version.returncode == 0
    assert version.stdout.startswith(f"reach-run {word} ")


def test_run_help_and_versions_of_every_command():
    done = cli("run", "--help")
    assert done.returncode == 0
    assert "usage: reach-run run" in done.stdout
    assert "exit codes: 0 the run completed" in done.stdout
    for main in ("run_main", "reachd_main", "sim_main"):
        assert cli("--version", main=main).stdout.split()[1:] == cli("--version").stdout.split()[1:]
    cal = subprocess.run([sys.executable, "-c", "from calibration.cli import main; import sys; "
                          "sys.exit(main(sys.argv[1:]))", "--version"],
                         capture_output=True, text=True, timeout=120)
    assert cal.returncode == 0
    assert cal.stdout.startswith("reach-cal ")


def test_check_validates_and_prints_json():
    done = cli("check", "--sim", "--json", "schedules/quick.yaml")
    assert done.returncode == 0, done.stderr
    checked = json.loads(done.stdout)
    assert checked["valid"]
    assert checked["duration_s"] > 0
    assert checked["steps"][0]["where"] == "schedules/quick.yaml:12"
    bad = cli("check", "--sim", "schedules/nope.yaml")
    assert bad.returncode == 2
    assert "Traceback" not in bad.stderr


def test_the_old_flags_still_work():
    done = cli("--sim", "--validate", "schedules/quick.yaml")
    assert done.returncode == 0
    assert "estimated duration" in done.stdout


def test_reachd_refuses_a_site_out_in_a_missing_directory_before_it_starts():
    started = time.monotonic()
    done = cli("--sim", "--site-out", "/missing/dir/x.yaml", main="reachd_main")
    assert done.returncode == 2
    said = "reachd: --site-out /missing/dir/x.yaml: no directory /missing/dir"
    assert done.stderr.strip() == said
    assert time.monotonic() - started < 10  # no simulator was started


def test_the_completion_script_completes_the_words_in_bash():
    script = cli("completion", "bash").stdout
    show = '; _reach_run; echo "${COMPREPLY[@]}"'
    probe = f"{script}\nCOMP_WORDS=(reach-run sta); COMP_CWORD=1{show}"
    probe += f"\nCOMP_WORDS=(reach-run status --a); COMP_CWORD=2{show}"
    out = subprocess.run(["bash", "-c", probe], capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == ["status", "--all"]


def test_recover_merges_the_parts_of_a_killed_run(tmp_path):
    from reach_receiver.store import RunStore, read_run_file

    directory = tmp_path / "run"
    # Opened and never finished: what a writer killed with SIGKILL leaves.
    RunStore(directory, name="killed", schedule_files=[("s.yaml", "x: 1")], site_yaml="",
             metadata={}, channel_width_hz=1e3).open()
    assert not (directory / "run.h5").exists()
    done = cli("recover", "--json", str(directory))
    assert done.returncode == 0, done.stderr
    answer = json.loads(done.stdout)
    assert read_run_file(Path(answer["run_file"])).status == "interrupted"
    again = cli("recover", str(directory))
    assert again.returncode == 0
    assert "nothing to merge" in again.stdout
    assert cli("recover", str(tmp_path)).returncode == 2


def test_the_status_summary_of_a_busy_daemon_fits_80_columns():
    from reach_receiver.cli.status_summary import summary_lines

    now = 1_800_000_000.0
    devices = ["teensy", "tec", "tc08", "vna", "itpm", "ms1", "ms2", "ms3", "ms4", "ms5"]
    reply = {
        "state": "running", "now": now, "since": now - 7200,
        "job": {"id": 7, "name": "observe"}, "step": "[ 4/13] Dicke cycles of cold, hot, "
        "r25, r100, c2r27, c2r36, c2r69, c2r91, c10open, c10short", "left_s": 23_000.0,
        "queue": [8, 9], "paused": False, "alarms": [],
        "health": {"alarms": ["TC-08 not answering for 5 min (since 12:00 UTC; threshold "
                              "300 s) reach_device_up{device=tc08} = 0 " + "x" * 40],
                   "readings": [{"key": f"reach_device_up{{device={d}}}", "value": 1.0,
                                 "unit": "1", "status": "nominal", "t": now} for d in devices]},
        "last_calibration": {"time": now - 3 * 86400, "name": "calibrate",
                             "status": "completed", "run": "/var/lib/reach/runs/x/run.h5"},
    }
    lines = summary_lines(reply, now)
    assert max(map(len, lines)) <= 80
    assert lines[0] == "state:     running since 2027-01-15 06:00 UTC (2.0 h ago)"
    assert "time left: 6.4 h" in lines
    assert "queue:     8, 9" in lines
    assert lines[lines.index("alarms:    1 raised") + 1].startswith("  ! TC-08 not answering")
    assert "last calibration: 2027-01-12 08:00 UTC (3.0 d ago)" in lines
    shown = " ".join(line for line in lines if line.startswith(("devices:", "    ")))
    assert all(f"{d} up" in shown for d in devices)


def test_the_commands_default_compression_is_the_simulators():
    from reach_receiver.cli.run import DEFAULT_COMPRESSION
    from reach_receiver.sim.receiver import DEFAULT_COMPRESSION as SIMULATOR

    assert DEFAULT_COMPRESSION == SIMULATOR
