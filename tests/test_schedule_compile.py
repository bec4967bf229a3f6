"""The schedule compiler: YAML with lines -> checked frozen steps, or every mistake at once."""

from datetime import datetime, timezone
from pathlib import Path
from textwrap import dedent

import pytest
from sites import planning_site

from reach_receiver.config.yaml_lines import LineDict, LineList, load_yaml
from reach_receiver.errors import ConfigError
from reach_receiver.run import compile_schedule, compile_text
from reach_receiver.run import steps as s
from reach_receiver.schedule.compile import Problem, ScheduleError

START = datetime(2026, 11, 22, 12, 0, tzinfo=timezone.utc)
SITE = planning_site(name="Karoo", longitude_deg=21.52, latitude_deg=-30.97)


def compiled(text: str, **kwargs) -> s.Schedule:
    return compile_text(dedent(text), "t.yaml", start_utc=START, **kwargs)


def problems_of(text: str, **kwargs) -> list[Problem]:
    with pytest.raises(ScheduleError) as caught:
        compile_text(dedent(text), "t.yaml", start_utc=START, **kwargs)
    return caught.value.problems


def keyed(problems: list[Problem]) -> set[tuple[str, int, str]]:
    return {(Path(p.file).name, p.line, p.key) for p in problems}


# --------------------------------------------------------------------------- YAML with lines
def test_loader_records_lines_of_keys_and_items():
    doc, problems = load_yaml("a: 1\nb:\n  - x\n  - {y: 2}\n", "f.yaml")
    assert problems == []
    assert isinstance(doc, LineDict)
    assert isinstance(doc["b"], LineList)
    assert doc.lines == {"a": 1, "b": 2}
    assert doc["b"].lines == [3, 4]
    assert doc["b"][1].lines == {"y": 4}


def test_loader_reads_exponent_floats_and_yaml11_booleans():
    doc, _ = load_yaml("f: 40e6\ng: -1.5E+3\non_: on\noff_: off\nname: 12v\n", "f")
    assert doc["f"] == 40e6
    assert isinstance(doc["f"], float)
    assert doc["g"] == -1500.0
    assert doc["on_"] is True
    assert doc["off_"] is False
    assert doc["name"] == "12v"


def test_loader_is_safe():
    _, problems = load_yaml("x: !!python/object/apply:os.system ['true']\n", "f")
    assert problems
    assert problems[0].key == "<yaml>"


# --------------------------------------------------------------------------- every step kind
EVERY_KIND = """\
schedule: every kind
steps:
  - initialise: {rails: [12v, 24v, 6v, fan, tec, ns]}
  - power: {ns: off, fan: on}
  - connect: {source: hot, to: vna}
  - vna_calibrate: {sweep: {f_start_hz: 50e6, f_stop_hz: 150e6, points: 801, ifbw_hz: 300}}
  - test_load_check: {reference: refs/ms2_6.s1p, tolerance: 0.03, statistic: max, retries: 1}
  - s11: {targets: [hot, cold, lna]}
  - spectrum: {source: ant, seconds: 120}
  - dicke: {sources: [hot, r25], seconds: 60}
  - temperatures: {period_s: 5}
  - tec: {setpoint_c: 30, wait: {tolerance_c: 0.2, hold_s: 60, timeout_s: 600}}
  - wait: {seconds: 30}
  - repeat:
      count: 2
      period_s: 3600
      steps:
        - spectrum: {source: cold, seconds: 10}
  - calibrate: {benchmark: bench.h5, tolerance: 0.1, f_lo_hz: 55e6, f_hi_hz: 125e6}
  - observe: {cycles: 4, seconds: 30, test_load_every: 2, rfi_threshold_sigma: 4}
  - safe
  - wait: {until_utc: "2026-12-01T18:00Z"}
  - wait: {until_lst_h: 4.5}
"""


def test_every_step_kind_compiles_to_its_dataclass_at_its_line():
    schedule = compile_text(EVERY_KIND, "sched/every.yaml", start_utc=START)
    kinds = [type(step) for step in schedule.steps]
    assert kinds == [
        s.Initialise,
        s.Power,
        s.Connect,
        s.VnaCalibrate,
        s.TestLoadCheck,
        s.MeasureS11,
        s.MeasureSpectrum,
        s.Dicke,
        s.Temperatures,
        s.Tec,
        s.Wait,
        s.Repeat,
        s.Calibrate,
        s.Observe,
        s.Safe,
        s.Wait,
        s.Wait,
    ]
    lines = [step.where.line for step in schedule.steps]
    assert lines == [3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 19, 20, 21, 22, 23]
    assert all(step.where.file == "sched/every.yaml" for step in schedule.steps)
    (init, power, connect, vna, tl, s11, spec, dicke, temps, tec, wait, rep, cal, obs, _, *w) = (
        schedule.steps
    )
    assert init.rails == ("12v", "24v", "6v", "fan", "tec", "ns")
    assert power.states == (("ns", False), ("fan", True))
    assert (connect.source, connect.to) == ("hot", "vna")
    assert vna.sweep == s.Sweep(f_start_hz=50e6, f_stop_hz=150e6, points=801, ifbw_hz=300)
    assert tl.reference == Path("sched/refs/ms2_6.s1p")  # relative to the schedule file
    assert (tl.tolerance, tl.statistic, tl.retries) == (0.03, "max", 1)
    assert s11.targets == ("hot", "cold", "lna")
    assert (spec.source, spec.seconds) == ("ant", 120.0)
    assert (dicke.sources, dicke.seconds) == (("hot", "r25"), 60.0)
    assert temps.period_s == 5.0
    assert tec.setpoint_c == 30.0
    assert tec.wait == s.WaitStable(tolerance_c=0.2, hold_s=60.0, timeout_s=600.0)
    assert wait.seconds == 30.0
    assert (rep.count, rep.period_s) == (2, 3600.0)
    assert rep.steps == (s.MeasureSpectrum(s.Where("sched/every.yaml", 18), "cold", 10.0),)
    assert cal.benchmark == Path("sched/bench.h5")
    assert (cal.tolerance, cal.f_lo_hz, cal.f_hi_hz) == (0.1, 55e6, 125e6)
    assert (obs.cycles, obs.seconds, obs.source, obs.test_load_every) == (4, 30.0, "ant", 2)
    assert obs.rfi_threshold_sigma == 4.0
    assert w[0].until_utc == datetime(2026, 12, 1, 18, 0, tzinfo=timezone.utc)
    assert w[1].until_lst_h == 4.5
    assert schedule.name == "every kind"
    assert schedule.files == (("sched/every.yaml", EVERY_KIND),)


def test_defaults_and_bare_steps():
    schedule = compiled(
        """\
        schedule: defaults
        steps:
          - initialise
          - vna_calibrate:
          - test_load_check
          - tec: {setpoint_c: 25, wait: true}
          - calibrate
          - safe
        """
    )
    init, vna, tl, tec, cal, _ = schedule.steps
    assert init.rails == s.Initialise(init.where).rails
    assert vna.sweep == s.Sweep()
    assert (tl.reference, tl.tolerance, tl.statistic, tl.retries) == (None, 0.05, "p95", 2)
    assert tec.wait == s.WaitStable()
    assert (cal.benchmark, cal.tolerance) == (None, 0.05)


# --------------------------------------------------------------------------- vars, includes, blocks
def test_variables_replace_whole_values_and_interpolate_text():
    schedule = compiled(
        """\
        schedule: "night at ${site.name}, lon ${site.longitude_deg}"
        vars:
          calibrators: [hot, cold, c10open]
          dwell_s: 90
          first: "${calibrators}"
        steps:
          - initialise
          - dicke: {sources: "${calibrators}", seconds: "${dwell_s}"}
          - s11: {targets: "${first}"}
        """,
        site=SITE,
    )
    assert schedule.name == "night at Karoo, lon 21.52"
    dicke, s11 = schedule.steps[1:]
    assert dicke.sources == ("hot", "cold", "c10open")
    assert dicke.seconds == 90.0
    assert s11.targets == ("hot", "cold", "c10open")
    assert dict(schedule.variables)["calibrators"] == ["hot", "cold", "c10open"]
    assert type(dict(schedule.variables)["calibrators"]) is list


def test_site_variable_needs_a_site_and_a_known_key():
    text = """\
        schedule: x
        steps:
          - initialise
          - wait: {until_lst_h: "${site.longitude_deg}"}
          - wait: {seconds: "${site.altitude}"}
        """
    assert keyed(problems_of(text)) == {
        ("t.yaml", 4, "wait.until_lst_h"),
        ("t.yaml", 5, "wait.seconds"),
    }
    assert keyed(problems_of(text, site=SITE)) == {("t.yaml", 5, "wait.seconds")}


def test_unknown_variable_is_reported_where_it_is_used():
    problems = problems_of(
        """\
        schedule: x
        vars: {dwell_s: 60}
        steps:
          - initialise
          - spectrum:
              source: ant
              seconds: "${dwel_s}"
        """
    )
    assert keyed(problems) == {("t.yaml", 7, "spectrum.seconds")}
    assert "did you mean 'dwell_s'" in problems[0].message


def test_variable_cycle_is_a_problem():
    problems = problems_of(
        """\
        schedule: x
        vars: {a: "${b}", b: "${a}"}
        steps: [initialise, {wait: {seconds: "${a}"}}]
        """
    )
    assert any("cycle" in p.message for p in problems)


def test_includes_blocks_and_overrides(tmp_path):
    (tmp_path / "lib").mkdir()
    (tmp_path / "lib" / "site_vars.yaml").write_text(
        dedent(
            """\
            include: [more.yaml]
            vars:
              dwell_s: 600
              calibrators: [hot, cold]
            blocks:
              cycle:
                - dicke: {sources: "${calibrators}", seconds: "${dwell_s}"}
                - use: temps
            """
        )
    )
    (tmp_path / "lib" / "more.yaml").write_text("blocks:\n  temps:\n    - temperatures\n")
    main = tmp_path / "cal.yaml"
    main.write_text(
        dedent(
            """\
            schedule: cal
            include: [lib/site_vars.yaml]
            vars: {dwell_s: 30}
            steps:
              - initialise
              - repeat: {count: 2, steps: [{use: cycle}]}
            """
        )
    )
    schedule = compile_schedule(main, start_utc=START)
    repeat = schedule.steps[1]
    dicke, temps = repeat.steps
    assert dicke.seconds == 30.0  # the including file's value wins
    assert dicke.sources == ("hot", "cold")
    assert dicke.where == s.Where(str(tmp_path / "lib" / "site_vars.yaml"), 7)
    assert temps.where == s.Where(str(tmp_path / "lib" / "more.yaml"), 3)
    assert [Path(f).name for f, _ in schedule.files] == ["cal.yaml", "site_vars.yaml", "more.yaml"]


def test_include_cycles_and_missing_files(tmp_path):
    (tmp_path / "a.yaml").write_text("include: [b.yaml]\n")
    (tmp_path / "b.yaml").write_text("vars: {x: 1}\ninclude: [a.yaml]\n")
    main = tmp_path / "main.yaml"
    main.write_text("schedule: x\ninclude: [a.yaml, nowhere.yaml]\nsteps: [initialise]\n")
    with pytest.raises(ScheduleError) as caught:
        compile_schedule(main, start_utc=START)
    found = keyed(caught.value.problems)
    assert found == {("main.yaml", 2, "include[1]"), ("b.yaml", 2, "include[0]")}
    messages = " ".join(p.message for p in caught.value.problems)
    assert "include cycle: a.yaml -> b.yaml -> a.yaml" in messages
    assert "nowhere.yaml" in messages


def test_block_cycle_and_unknown_block():
    problems = problems_of(
        """\
        schedule: x
        blocks:
          a: [{use: b}]
          b: [{use: a}]
        steps:
          - initialise
          - use: a
          - use: cylce
        """
    )
    assert ("t.yaml", 8, "use") in keyed(problems)
    assert any("block cycle: a -> b -> a" in p.message for p in problems)
    assert any(p.line == 4 and p.key == "use" for p in problems)


# --------------------------------------------------------------------------- every mistake at once
def test_a_file_with_several_mistakes_reports_each_with_file_line_key(tmp_path):
    (tmp_path / "inc.yaml").write_text(
        dedent(
            """\
            vars:
              dwell_s: 60
            blocks:
              cycle:
                - dicke:
                    sources: [hot, cld]
                    seconds: "${dwell_s}"
                - temperatures: {period_s: -1}
            """
        )
    )
    main = tmp_path / "bad.yaml"
    main.write_text(
        dedent(
            """\
            schedule: broken
            include: [inc.yaml]
            steps:
              - initialise
              - conect: {source: hot}
              - dicke: {sources: [hot], secnds: 60}
              - tec: {setpoint_c: 60}
              - vna_calibrate: {sweep: {points: 1, ifbw_hz: 1000}}
              - wait: {seconds: -1}
              - use: cycle
              - observe: {cycles: 1.5, seconds: .inf}
              - s11: {targets: [hot, short]}
              - connect: {source: short}
              - test_load_check: {tolerance: 5}
            """
        )
    )
    with pytest.raises(ScheduleError) as caught:
        compile_schedule(main, start_utc=START)
    assert keyed(caught.value.problems) == {
        ("bad.yaml", 5, "conect"),
        ("bad.yaml", 6, "dicke.secnds"),
        ("bad.yaml", 6, "dicke.seconds"),
        ("bad.yaml", 7, "tec.setpoint_c"),
        ("bad.yaml", 8, "vna_calibrate.sweep"),
        ("bad.yaml", 9, "wait.seconds"),
        ("bad.yaml", 11, "observe.cycles"),
        ("bad.yaml", 11, "observe.seconds"),
        ("bad.yaml", 12, "s11.targets[1]"),
        ("bad.yaml", 13, "connect.source"),
        ("bad.yaml", 14, "test_load_check.tolerance"),
        ("inc.yaml", 6, "dicke.sources[1]"),
        ("inc.yaml", 8, "temperatures.period_s"),
    }
    text = str(caught.value)
    first = caught.value.problems[0]
    assert text.splitlines()[0] == f"{main}:5: conect: {first.message}"
    assert "did you mean 'connect'" in first.message
    assert len(text.splitlines()) == 13
    assert isinstance(caught.value, ConfigError)


def test_a_mistake_inside_a_block_is_reported_once_at_the_block_line_even_if_unused():
    problems = problems_of(
        """\
        schedule: x
        blocks:
          cycle:
            - dicke: {sources: [hot], seconds: 60}
            - s11: {targets: [hot, lan]}
          spare:
            - spectrum: {source: ant, seconds: 0}
        steps:
          - initialise
          - use: cycle
          - repeat: {count: 2, steps: [{use: cycle}]}
        """
    )
    assert [(p.line, p.key) for p in problems] == [
        (5, "s11.targets[1]"),
        (7, "spectrum.seconds"),
    ]
    assert "did you mean 'lna'" in problems[0].message


def test_sweep_settings_problem_is_reported_at_the_step_line():
    problems = problems_of(
        """\
        schedule: x
        steps:
          - initialise
          - vna_calibrate:
              sweep:
                f_start_hz: 200e6
                f_stop_hz: 100e6
        """
    )
    assert [(p.line, p.key) for p in problems] == [(4, "vna_calibrate.sweep")]
    assert "start < stop" in problems[0].message


def test_text_with_a_control_character_is_a_problem():
    problems = problems_of("schedule: x\nsteps: [initialise]\n# \x08\n")
    assert [(p.line, p.key) for p in problems] == [(3, "<yaml>")]


def test_duplicate_keys_name_both_lines():
    problems = problems_of(
        """\
        schedule: x
        steps:
          - initialise
          - dicke:
              sources: [hot]
              seconds: 10
              seconds: 20
        """
    )
    assert keyed(problems) == {("t.yaml", 7, "seconds")}
    assert "first on line 6" in problems[0].message


def test_yaml_syntax_error_is_a_problem_with_its_line():
    problems = problems_of("schedule: x\nsteps:\n  - initialise\n  - dicke: {sources: [hot\n")
    assert len(problems) == 1
    assert problems[0].file == "t.yaml"
    assert problems[0].line == 5
    assert problems[0].message.startswith("YAML syntax")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("- just a list\n", ("t.yaml", 1, "<document>")),
        ("schedule: x\n", ("t.yaml", 1, "steps")),
        ("steps: [initialise]\n", ("t.yaml", 1, "schedule")),
        ("schedule: x\nsteps: []\n", ("t.yaml", 2, "steps")),
        ("schedule: x\nversion: 2\nsteps: [initialise]\n", ("t.yaml", 2, "version")),
        ("schedule: x\nstep: [initialise]\nsteps: [initialise]\n", ("t.yaml", 2, "step")),
        ("schedule: x\nsteps: [initialise, {safe: 1}]\n", ("t.yaml", 2, "safe")),
        ("schedule: x\nsteps: [initialise, {safe: , wait: }]\n", ("t.yaml", 2, "<step>")),
        ("schedule: x\nsteps: [initialise, {power: {12v: 1}}]\n", ("t.yaml", 2, "power.12v")),
        ("schedule: x\nsteps: [initialise, {power: {48v: on}}]\n", ("t.yaml", 2, "power.48v")),
        ("schedule: x\nsteps: [initialise, {wait: {}}]\n", ("t.yaml", 2, "wait.<how>")),
        (
            "schedule: x\nsteps: [initialise, {wait: {until_utc: 2026-11-22}}]\n",
            ("t.yaml", 2, "wait.until_utc"),
        ),
        (
            "schedule: x\nsteps: [initialise, {wait: {until_lst_h: 24}}]\n",
            ("t.yaml", 2, "wait.until_lst_h"),
        ),
        (
            "schedule: x\nsteps: [initialise, {vna_calibrate: {sweep: {ifbw_hz: 500}}}]\n",
            ("t.yaml", 2, "vna_calibrate.sweep"),
        ),
        (
            "schedule: x\nsteps: [initialise, {tec: {setpoint_c: 20, wait: {hold_s: 9, "
            "timeout_s: 5}}}]\n",
            ("t.yaml", 2, "tec.wait.timeout_s"),
        ),
        (
            "schedule: x\nsteps: [initialise, {calibrate: {f_lo_hz: 130e6, f_hi_hz: 50e6}}]\n",
            ("t.yaml", 2, "calibrate.f_hi_hz"),
        ),
        (
            "schedule: x\nsteps: [initialise, {dicke: {sources: hot, seconds: 1}}]\n",
            ("t.yaml", 2, "dicke.sources"),
        ),
        ("schedule: x\nsteps: [initialise, {repeat: {count: 2}}]\n", ("t.yaml", 2, "repeat.steps")),
        ("schedule: x\nvars: {site: 1}\nsteps: [initialise]\n", ("t.yaml", 2, "vars.site")),
    ],
)
def test_single_mistakes(text, expected):
    assert keyed(problems_of(text)) == {expected}


def test_unreadable_schedule_file(tmp_path):
    with pytest.raises(ScheduleError) as caught:
        compile_schedule(tmp_path / "absent.yaml")
    assert caught.value.problems[0].key == "<file>"


# --------------------------------------------------------------------------- interlocks
@pytest.mark.parametrize(
    ("steps", "expected"),
    [
        ("[{connect: {source: hot}}, initialise]", (3, "connect")),
        ("[{s11: {targets: [hot]}}, initialise]", (3, "s11")),
        ("[{dicke: {sources: [hot], seconds: 1}}, initialise]", (3, "dicke")),
        ("[initialise, {power: {5v: off}}]", (3, "power.5v")),
        ("[{initialise: {rails: [3v3, 12v]}}]", (3, "initialise.rails")),
        ("[initialise, {power: {24v: off}}]", (3, "power.24v")),  # fan on since initialise
        ("[initialise, {power: {24v: off, fan: off}}]", (3, "power.24v")),  # order matters
        ("[initialise, {connect: {source: hot}}, {power: {12v: off}}]", (3, "power.12v")),
        (
            "[initialise, {s11: {targets: [hot]}}, {power: {fan: off}}, {power: {24v: off}}]",
            (3, "power.24v"),
        ),
        ("[initialise, {power: {tec: off}}, {tec: {setpoint_c: 25}}]", (3, "tec")),
        (
            "[{initialise: {rails: [12v]}}, {power: {24v: off}}, {power: {fan: on}}]",
            (3, "power.fan"),
        ),
    ],
)
def test_interlock_violations(steps, expected):
    problems = problems_of(f"schedule: x\nsteps:\n  {steps}\n")
    assert {(p.line, p.key) for p in problems} == {expected}


@pytest.mark.parametrize(
    "steps",
    [
        "[initialise, {connect: {source: hot}}, safe, {power: {12v: off}}]",
        "[initialise, {power: {fan: off, 24v: off}}]",
        "[initialise, {connect: {source: ant}}, safe, {power: {fan: off}}, {power: {24v: off}}]",
        "[initialise, {power: {tec: off}}, {power: {tec: on}}, {tec: {setpoint_c: 25}}]",
        "[{initialise: {rails: []}}]",
    ],
)
def test_allowed_sequences_compile(steps):
    compiled(f"schedule: x\nsteps:\n  {steps}\n")


def test_interlocks_follow_blocks_and_repeats():
    problems = problems_of(
        """\
        schedule: x
        blocks:
          measure: [{s11: {targets: [lna]}}]
        steps:
          - initialise
          - repeat:
              count: 2
              steps:
                - power: {fan: off}
                - use: measure
                - power: {12v: on}
          - power: {24v: off}
        """
    )
    assert keyed(problems) == {("t.yaml", 12, "power.24v")}
    assert "mts" in problems[0].message


def test_unknown_step_does_not_cascade_into_interlock_noise():
    problems = problems_of("schedule: x\nsteps:\n  - initialse\n  - connect: {source: hot}\n")
    assert keyed(problems) == {("t.yaml", 3, "initialse")}
    assert "did you mean 'initialise'" in problems[0].message


def test_error_lists_one_problem_per_line_and_returns_nothing():
    with pytest.raises(ScheduleError) as caught:
        compile_text("schedule: x\nsteps: [initialise, {wait: {seconds: 0}}, {safe: 3}]\n")
    lines = str(caught.value).splitlines()
    assert lines == [
        "<string>:2: wait.seconds: must be in (0, inf), not 0",
        "<string>:2: safe: takes a mapping of nothing, not int 3",
    ]
