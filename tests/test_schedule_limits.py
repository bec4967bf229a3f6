"""Schedule checking is bounded: bombs, odd files and absurd numbers are refused at their line.

Every schedule below hung, ran out of memory or raised a traceback before checking was
bounded (nested repeats, variable and block "bombs", includes of FIFOs and devices,
numbers that overflow a date or a float). Each must now be refused with a problem at
``file:line: key``, within about a second of CPU (asserted with a margin for a loaded
machine) and, for the bombs, a few MB of memory.
"""

import os
import subprocess
import sys
import time
import tracemalloc
from datetime import datetime, timezone
from pathlib import Path

import pytest
from sites import planning_site

from reach_receiver.run import compile_schedule
from reach_receiver.run.steps import STANDARD_KINDS
from reach_receiver.schedule import compile as language
from reach_receiver.schedule import limits
from reach_receiver.schedule.compile import Problem, ScheduleError

START = datetime(2026, 11, 22, 12, 0, tzinfo=timezone.utc)
SITE = planning_site()
#: CPU seconds a refusal may take: the bound is ~1 s, doubled for a machine under load.
CPU_S = 2.0


def refused(path: Path) -> list[Problem]:
    """The problems of a schedule file that must be refused quickly."""
    began = time.process_time()
    with pytest.raises(ScheduleError) as caught:
        language.compile_schedule(path, kinds=STANDARD_KINDS, site=SITE, start_utc=START)
    assert time.process_time() - began < CPU_S
    return caught.value.problems


def written(tmp_path: Path, text: str, name: str = "s.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def one(problems: list[Problem], key: str, says: str) -> Problem:
    """The problem under ``key`` that says ``says``."""
    found = [p for p in problems if p.key == key and says in p.message]
    assert found, "\n".join(map(str, problems))
    return found[0]


def flow_repeats(depth: int, count: int = 2, body: str = "{connect: {source: hot}}") -> str:
    inner = body
    for _ in range(depth):
        inner = f"{{repeat: {{count: {count}, steps: [{inner}]}}}}"
    return f"schedule: deep\nsteps:\n  - initialise\n  - {inner}\n"


# --------------------------------------------------------------------------- nesting, bombs
@pytest.mark.parametrize("depth", [17, 18])
def test_repeats_nested_past_the_bound_are_refused(tmp_path, depth):
    problems = refused(written(tmp_path, flow_repeats(depth)))
    assert one(problems, "repeat.steps", "nested more than 16 deep").line == 4


@pytest.mark.parametrize("depth", [25, 40])
def test_repeats_nested_deeper_than_yaml_allows_are_refused_at_their_line(tmp_path, depth):
    assert one(refused(written(tmp_path, flow_repeats(depth))), "<yaml>", "deeper").line == 4


def test_repeats_within_the_nesting_bound_still_bound_the_walks(tmp_path):
    # 15 repeats of 2, each level's body 4 steps: the interlock walk doubles at each level
    body = "{connect: {source: hot}}"
    inner = body
    for _ in range(15):
        inner = f"{{repeat: {{count: 2, steps: [{body}, {body}, {body}, {inner}]}}}}"
    text = f"schedule: deep\nsteps:\n  - initialise\n  - {inner}\n"
    one(refused(written(tmp_path, text)), "connect", "checking visits more than")


@pytest.mark.parametrize(("levels", "key", "says"), [
    (15, "use", "more than 10,000 steps"),  # 2^14 steps within the nesting bound
    (40, "blocks.b24", "nested more than 16 deep"),
])
def test_a_block_bomb_is_refused(tmp_path, levels, key, says):
    lines = ["schedule: bomb", "blocks:", "  b0: [{connect: {source: hot}}]"]
    lines += [f"  b{i}: [{{use: b{i - 1}}}, {{use: b{i - 1}}}]" for i in range(1, levels)]
    lines += ["steps:", "  - initialise", f"  - use: b{levels - 1}"]
    one(refused(written(tmp_path, "\n".join(lines) + "\n")), key, says)


def test_a_chain_of_blocks_is_refused_by_its_nesting(tmp_path):
    lines = ["schedule: chain", "blocks:", "  b0: [{connect: {source: hot}}]"]
    lines += [f"  b{i}: [{{use: b{i - 1}}}]" for i in range(1, 500)]
    lines += ["steps:", "  - initialise", "  - use: b499"]
    one(refused(written(tmp_path, "\n".join(lines) + "\n")), "blocks.b484", "nested more than")


def test_variable_bombs_are_refused_within_a_few_mb(tmp_path):
    lists = ["schedule: v", "vars:", "  v0: [hot, cold]"]
    lists += [f'  v{i}: ["${{v{i - 1}}}", "${{v{i - 1}}}"]' for i in range(1, 40)]
    texts = ["schedule: t", "vars:", "  t0: xxxxxxxxxxxxxxxx"]
    texts += [f'  t{i}: "${{t{i - 1}}}${{t{i - 1}}}"' for i in range(1, 40)]
    tracemalloc.start()
    try:
        values = refused(written(tmp_path, "\n".join([*lists, "steps: [initialise]"]), "v.yaml"))
        text = refused(written(tmp_path, "\n".join([*texts, "steps: [initialise]"]), "t.yaml"))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50e6
    assert one(values, "vars.v12", "16,383 values").line == 15
    assert one(text, "vars.t13", "more than 65,536 characters").line == 16


def test_a_large_variable_used_many_times_is_refused_by_the_copies(tmp_path):
    uses = ", ".join(['"${a}"'] * 100)
    text = (
        "schedule: u\n"
        f"vars:\n  a: [{', '.join(['hot'] * 5000)}]\n"
        f"  b: [{uses}]\n"
        "steps: [initialise]\n"
    )
    one(refused(written(tmp_path, text)), "vars.b[19]", "copies more than 100,000 values")


def test_a_chain_of_variables_is_refused_by_its_length(tmp_path):
    lines = ["schedule: c", "vars:", "  v0: hot"]
    lines += [f'  v{i}: "${{v{i - 1}}}"' for i in range(1, 1000)]
    lines += ["steps:", "  - initialise", "  - connect: {source: '${v999}'}"]
    problems = refused(written(tmp_path, "\n".join(lines) + "\n"))
    assert any("defined through more than 16 others" in p.message for p in problems), problems


def test_variables_nested_through_variables_are_refused_by_depth(tmp_path):
    # each variable 10 lists deep around the one before: 70 deep at v7
    lines = ["schedule: n", "vars:", "  v0: hot"]
    lines += [f'  v{i}: {"[" * 10}"${{v{i - 1}}}"{"]" * 10}' for i in range(1, 9)]
    lines += ["steps: [initialise]"]
    problems = refused(written(tmp_path, "\n".join(lines) + "\n"))
    assert one(problems, "vars.v7", "nests more than 64 deep").line == 10


def test_a_run_of_too_many_steps_is_refused_at_the_step(tmp_path):
    text = (
        "schedule: r\nsteps:\n  - initialise\n"
        "  - repeat: {count: 100000, steps: [{repeat: {count: 1000, steps: [{power: {fan: on}}]}}]}"
        "\n"
    )
    assert one(refused(written(tmp_path, text)), "power", "10,000,000 steps").line == 4


# --------------------------------------------------------------------------- included files
def including(tmp_path: Path, target: str | Path) -> Path:
    return written(tmp_path, f"schedule: i\ninclude: ['{target}']\nsteps: [initialise]\n")


@pytest.mark.parametrize(
    ("target", "kind"),
    [
        ("/dev/zero", "character device"),
        ("/dev/urandom", "character device"),
        ("/dev/null", "character device"),
        ("/tmp", "directory"),
    ],
)
def test_an_include_that_is_not_a_regular_file_is_refused_by_kind(tmp_path, target, kind):
    problem = one(refused(including(tmp_path, target)), "include[0]", kind)
    assert problem.line == 2


def test_an_include_of_stdin_is_refused_without_reading_it(tmp_path):
    # stdin a pipe that is never written to: a read would block
    reader, writer = os.pipe()
    saved = os.dup(0)
    os.dup2(reader, 0)
    try:
        problem = one(refused(including(tmp_path, "/dev/stdin")), "include[0]", "FIFO")
    finally:
        os.dup2(saved, 0)
        for fd in (saved, reader, writer):
            os.close(fd)
    assert problem.line == 2


@pytest.mark.skipif(not Path("/proc/kmsg").exists(), reason="no /proc/kmsg")
def test_an_include_of_a_kernel_file_of_size_zero_is_not_read(tmp_path):
    problems = refused(including(tmp_path, "/proc/kmsg"))
    one(problems, "<document>", "not null")


def test_an_include_too_large_is_refused_by_size_before_reading(tmp_path):
    big = tmp_path / "big.yaml"
    big.write_text("vars: {a: 1}\n" + "#" * limits.MAX_FILE_BYTES + "\n")
    one(refused(including(tmp_path, big)), "include[0]", "at most 65,536")


def test_includes_too_deep_too_many_and_cyclic_are_named(tmp_path):
    for i in range(12):
        written(tmp_path, f"include: [d{i + 1}.yaml]\n" if i < 11 else "vars: {}\n", f"d{i}.yaml")
    deep = refused(including(tmp_path, "d0.yaml"))
    assert one(deep, "include[0]", "nested more than 8 deep").file.endswith("d6.yaml")
    written(tmp_path, "vars: {x: 1}\n", "w0.yaml")
    for i in range(1, 6):
        written(tmp_path, f"include: [w{i - 1}.yaml, w{i - 1}.yaml, w{i - 1}.yaml]\n", f"w{i}.yaml")
    one(refused(including(tmp_path, "w5.yaml")), "include[0]", "more than 32 files")
    written(tmp_path, "include: [b.yaml]\n", "a.yaml")
    written(tmp_path, "include: [a.yaml]\n", "b.yaml")
    one(refused(including(tmp_path, "a.yaml")), "include[0]", "a.yaml -> b.yaml -> a.yaml")


def test_texts_sent_to_the_daemon_are_bounded_like_files():
    sent = {"top.yaml": "schedule: t\ninclude: [big.yaml]\nsteps: [initialise]\n",
            "big.yaml": "vars: {a: 1}\n" + "#" * 2 * limits.MAX_FILE_BYTES + "\n"}
    with pytest.raises(ScheduleError) as caught:
        language.compile_text(sent["top.yaml"], "top.yaml", kinds=STANDARD_KINDS,
                              read=lambda path: sent[str(path)])
    one(caught.value.problems, "<file>", "at most 65,536")
    with pytest.raises(ScheduleError) as caught:
        language.compile_text("schedule: t\n" + "#" * 10**7, "top.yaml", kinds=STANDARD_KINDS)
    one(caught.value.problems, "<file>", "at most 65,536")


def reach_run(*args: str, timeout_s: float = 120) -> subprocess.CompletedProcess[str]:
    entry = "from reach_receiver.cli import run_main; raise SystemExit(run_main())"
    return subprocess.run(
        [sys.executable, "-c", entry, "--sim", "--validate", *args],
        capture_output=True, text=True, timeout=timeout_s, stdin=subprocess.DEVNULL,
    )


def test_reach_run_refuses_a_fifo_schedule_and_a_fifo_include_without_blocking(tmp_path):
    fifo = tmp_path / "pipe.yaml"
    os.mkfifo(fifo)
    top = including(tmp_path, fifo)
    for path, says in ((top, f"{top}:2: include[0]: cannot read"), (fifo, "pipe.yaml:1: <file>")):
        done = reach_run(str(path))
        assert done.returncode == 2, done.stderr
        assert says in done.stderr
        assert "a FIFO, not a regular file" in done.stderr
        assert "Traceback" not in done.stderr


# --------------------------------------------------------------------------- numbers
@pytest.mark.parametrize(
    ("step", "key", "says"),
    [
        ("{wait: {seconds: 1e300}}", "wait.seconds", "at most 3.156e+08 s"),
        ("{wait: {seconds: 123456789012345678901234567890}}", "wait.seconds", "at most"),
        ("{wait: {seconds: .nan}}", "wait.seconds", "finite"),
        ("{wait: {seconds: .inf}}", "wait.seconds", "finite"),
        ("{wait: {seconds: -.inf}}", "wait.seconds", "finite"),
        ("{wait: {seconds: -5}}", "wait.seconds", "must be in (0, inf)"),
        ("{wait: {until_utc: 9999-12-31T23:00Z}}", "wait.until_utc", "years 2000-2199"),
        ("{wait: {until_utc: '9999-12-31T23:00:00-05:00'}}", "wait.until_utc", "not 9999"),
        ("{wait: {until_utc: '0001-01-01T00:00:00+05:00'}}", "wait.until_utc", "not 1"),
        ("{wait: {until_utc: 2150-01-01T00:00Z}}", "wait", "more than 10 years"),
        ("{repeat: {count: 12345678901234567890, steps: [safe]}}", "repeat.count", "at most"),
        ("{repeat: {count: 900000, period_s: 3e8, steps: [safe]}}", "repeat", "10 years"),
        ("{observe: {cycles: 100000000, seconds: 200}}", "observe.cycles", "1,000,000"),
        ("{tec: {setpoint_c: 1e300}}", "tec.setpoint_c", "at most 1e+12"),
        ("{tec: {setpoint_c: 123456789012345678901234567890}}", "tec.setpoint_c", "at most"),
        ("{tec: {setpoint_c: -1e30}}", "tec.setpoint_c", "at most 1e+12"),
        ("{tec: {setpoint_c: 25, wait: {hold_s: 1e300}}}", "tec.wait.hold_s", "at most"),
        ("{vna_calibrate: {sweep: {points: 99999999999}}}", "vna_calibrate.sweep.points", "most"),
        ("{calibrate: {f_lo_hz: 1e300}}", "calibrate.f_lo_hz", "at most 1e+12"),
        ("{temperatures: {period_s: 9e99}}", "temperatures.period_s", "at most"),
    ],
)
def test_numbers_out_of_range_are_problems_at_their_line_and_key(tmp_path, step, key, says):
    text = f"schedule: n\nsteps:\n  - initialise: {{rails: [tec]}}\n  - {step}\n"
    assert one(refused(written(tmp_path, text)), key, says).line == 4


def test_durations_that_add_up_past_the_bound_are_refused_at_the_step_passing_it(tmp_path):
    text = "schedule: n\nsteps:\n  - initialise\n" + "  - wait: {seconds: 2e8}\n" * 3
    problems = refused(written(tmp_path, text))
    assert [(p.line, p.key) for p in problems] == [(5, "wait")]
    assert "more than 10 years by the end of this step" in problems[0].message


def test_a_huge_number_through_a_variable_is_refused_where_it_is_used(tmp_path):
    text = "schedule: n\nvars: {long: 1e300}\nsteps:\n  - initialise\n"
    text += "  - wait: {seconds: '${long}'}\n"
    assert one(refused(written(tmp_path, text)), "wait.seconds", "at most").line == 5


# --------------------------------------------------------------------------- YAML itself
def test_yaml_alias_bomb_is_refused(tmp_path):
    lines = ["schedule: lol", "vars:", "  a: &a [x, x, x, x, x, x, x, x, x, x]"]
    for i in range(1, 9):
        name, previous = chr(ord("a") + i), chr(ord("a") + i - 1)
        lines.append(f"  {name}: &{name} [{', '.join([f'*{previous}'] * 10)}]")
    lines.append("steps: [initialise]")
    one(refused(written(tmp_path, "\n".join(lines) + "\n")), "<yaml>", "aliases are expanded")


def test_deep_flow_nesting_is_refused_at_its_line(tmp_path):
    text = "schedule: x\nsteps: [initialise]\nvars:\n  a: " + "[" * 5000 + "]" * 5000 + "\n"
    assert one(refused(written(tmp_path, text)), "<yaml>", "deeper than 64").line == 4


def test_a_huge_document_is_refused_before_parsing(tmp_path):
    path = written(tmp_path, "schedule: x\nsteps: [initialise]\n" + "# x\n" * 10**6)
    one(refused(path), "<file>", "at most 65,536")


def test_an_integer_of_many_digits_is_refused_at_its_line(tmp_path):
    text = "schedule: x\nsteps:\n  - initialise\n  - wait: {seconds: " + "9" * 5000 + "}\n"
    assert one(refused(written(tmp_path, text)), "<yaml>", "integer of 5000").line == 4


# --------------------------------------------------------------------------- real schedules
def test_real_schedules_far_from_the_bounds_are_accepted(tmp_path):
    # a year of nights: wait for LST 22 h, observe 60 cycles; REACH's operations for 300 days
    year = (
        "schedule: year\ninclude: [common.yaml]\nsteps:\n  - use: bring_up\n"
        "  - repeat: {count: 365, steps: [{wait: {until_lst_h: 22}},"
        " {observe: {cycles: 60, seconds: 200, test_load_every: 6}}]}\n  - safe\n"
    )
    operations = (
        "schedule: ops\nsteps:\n  - initialise\n  - repeat:\n      count: 86400\n"
        "      period_s: 300\n      steps: [{spectrum: {source: ant, seconds: 60}},"
        " {spectrum: {source: cold, seconds: 60}}, {spectrum: {source: ns, seconds: 60}}]\n"
        "  - safe\n"
    )
    common = Path(__file__).parent.parent / "schedules" / "common.yaml"
    written(tmp_path, common.read_text(), "common.yaml")
    for name, text in (("year.yaml", year), ("ops.yaml", operations)):
        began = time.process_time()
        path = written(tmp_path, text, name)
        schedule = compile_schedule(path, site=planning_site(period_s=1.0), start_utc=START)
        assert time.process_time() - began < CPU_S
        assert schedule.steps


def test_a_chain_of_variables_is_refused_whatever_order_they_are_resolved_in(tmp_path):
    lines = ["schedule: c", "vars:", "  v0: hot"]
    lines += [f'  v{i}: "${{v{i - 1}}}"' for i in range(1, 40)]
    lines += ["steps: [initialise]"]  # resolved in the order written: one level at a time
    problems = refused(written(tmp_path, "\n".join(lines) + "\n"))
    assert one(problems, "vars.v16", "through more than 16 variables").line == 19


def test_the_daemons_compile_of_sent_files_is_bounded_too():
    # reachd compiles what a client sent with schedule_reader: the same bounds apply
    from reach_receiver.daemon.running import schedule_reader

    bomb = ["schedule: v", "include: [more.yaml]", "vars:", "  v0: [hot, cold]"]
    bomb += [f'  v{i}: ["${{v{i - 1}}}", "${{v{i - 1}}}"]' for i in range(1, 40)]
    inner = "{connect: {source: hot}}"
    for _ in range(18):
        inner = f"{{repeat: {{count: 2, steps: [{inner}]}}}}"
    top = "\n".join([*bomb, "steps: [initialise]"]) + "\n"
    for more, key, says in (
        ("vars: {}\n", "vars.v12", "16,383 values"),
        (f"blocks:\n  deep: [{inner}]\n", "repeat.steps", "nested more than 16 deep"),
    ):
        sent = {"top.yaml": top, "more.yaml": more}
        began = time.process_time()
        with pytest.raises(ScheduleError) as caught:
            language.compile_text(top, "top.yaml", kinds=STANDARD_KINDS, site=SITE,
                                  read=schedule_reader(sent))
        assert time.process_time() - began < CPU_S
        one(caught.value.problems, key, says)


def test_integers_in_units_are_not_taken_for_counts(tmp_path):
    text = (
        "schedule: f\nsteps:\n  - initialise: {rails: [tec]}\n  - tec: {setpoint_c: 25}\n"
        "  - vna_calibrate: {sweep: {f_start_hz: 40000000, f_stop_hz: 200000000, points: 2001}}\n"
        "  - s11: {targets: [hot]}\n  - dicke: {sources: [hot], seconds: 3000000}\n"
        "  - calibrate: {f_lo_hz: 50000000, f_hi_hz: 130000000}\n"
    )
    schedule = compile_schedule(written(tmp_path, text), site=SITE, start_utc=START)
    assert schedule.steps[-1].f_lo_hz == 50e6
