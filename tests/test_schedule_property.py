"""Property tests of the schedule compiler: no crash on anything, valid schedules compile.

(a) any YAML document or text gives a Schedule or a ScheduleError, never another error;
(b) random valid schedules compile, one top-level step per written step, of the right kind;
(c) one key of a valid schedule renamed to an unknown key is reported with its line.
"""

from datetime import datetime, timezone

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from reach_receiver.frontend.layout import REACH_SOURCES, VNA_STANDARDS
from reach_receiver.run import compile_text
from reach_receiver.run import steps as s
from reach_receiver.run.steps import STANDARD_KINDS
from reach_receiver.schedule.compile import ScheduleError

START = datetime(2026, 11, 22, 12, 0, tzinfo=timezone.utc)
SOURCES = sorted(REACH_SOURCES)
PROFILE = settings(  # derandomized: the same examples every run; more in a dedicated session
    max_examples=120,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)

# --------------------------------------------------------------------------- (a) anything
WORDS = [
    *STANDARD_KINDS.names,
    "use",
    "schedule",
    "steps",
    "vars",
    "blocks",
    "include",
    "version",
    "sources",
    "seconds",
    "source",
    "to",
    "targets",
    "count",
    "period_s",
    "sweep",
    "points",
    "wait",
    "until_utc",
    "until_lst_h",
    "setpoint_c",
    "rails",
    "12v",
    "24v",
    "fan",
    "hot",
    "lna",
    "vna",
    "${x}",
    "${site.name}",
    "x",
]
scalars = (
    st.none()
    | st.booleans()
    | st.integers(-(10**12), 10**12)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.sampled_from(WORDS)
    | st.text(max_size=12)
)
keys = st.sampled_from(WORDS) | st.text(max_size=8)
documents = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(keys, inner, max_size=5),
    max_leaves=30,
)
shaped = st.fixed_dictionaries(
    {"schedule": scalars, "steps": st.lists(st.dictionaries(keys, documents, max_size=2))},
    optional={"vars": st.dictionaries(keys, documents, max_size=3), "version": scalars},
)


def _outcome(text: str) -> None:
    error: ScheduleError | None = None
    try:
        result = compile_text(text, "fuzz.yaml", start_utc=START)
    except ScheduleError as err:
        error = err
    if error is None:
        assert isinstance(result, s.Schedule)
        assert result.steps
        return
    assert error.problems
    assert all(p.file == "fuzz.yaml" and p.line >= 1 for p in error.problems)
    assert str(error).count("\n") == len(error.problems) - 1


@PROFILE
@given(document=documents | shaped, flow=st.booleans())
def test_any_document_compiles_or_raises_schedule_error(document, flow):
    _outcome(yaml.safe_dump(document, default_flow_style=flow, allow_unicode=True))


@settings(max_examples=80, deadline=None, derandomize=True, database=None)
@given(
    text=st.text(
        alphabet=st.sampled_from(list("abc:{}[]-, \n\t'\"&*!|>%@`#$?0123\x00\x08\u2028")),
        max_size=60,
    )
)
def test_any_text_compiles_or_raises_schedule_error(text):
    _outcome(text)


# --------------------------------------------------------------------------- (b) valid schedules
seconds = st.integers(1, 3600) | st.floats(0.5, 3600.0)
SAFE_POWER = [("fan", True), ("tec", True), ("6v", True), ("6v", False), ("ns", False)]


def _step(kind: str, args: object) -> dict:
    return {kind: args}


def simple_steps() -> st.SearchStrategy[tuple[dict, type]]:
    sweep = st.fixed_dictionaries(
        {},
        optional={
            "f_start_hz": st.sampled_from([40e6, 50e6]),
            "f_stop_hz": st.sampled_from([180e6, 200e6]),
            "points": st.integers(2, 2001),
            "ifbw_hz": st.sampled_from([100.0, 1000.0, 10000.0]),
            "power_dbm": st.sampled_from([-5.0, -10.0, 0.0]),
            "averages": st.integers(1, 30),
        },
    )
    return st.one_of(
        st.tuples(
            st.lists(
                st.sampled_from(SAFE_POWER), min_size=1, max_size=3, unique_by=lambda x: x[0]
            ).map(lambda states: _step("power", dict(states))),
            st.just(s.Power),
        ),
        st.tuples(
            st.one_of(
                st.sampled_from(SOURCES).map(lambda x: {"source": x, "to": "lna"}),
                st.sampled_from([*SOURCES, "lna", *VNA_STANDARDS]).map(
                    lambda x: {"source": x, "to": "vna"}
                ),
            ).map(lambda a: _step("connect", a)),
            st.just(s.Connect),
        ),
        st.tuples(
            sweep.map(lambda w: _step("vna_calibrate", {"sweep": w})), st.just(s.VnaCalibrate)
        ),
        st.tuples(
            st.fixed_dictionaries(
                {},
                optional={
                    "tolerance": st.floats(0.001, 0.5),
                    "statistic": st.sampled_from(["max", "p95", "rms"]),
                    "retries": st.integers(0, 5),
                },
            ).map(lambda a: _step("test_load_check", a)),
            st.just(s.TestLoadCheck),
        ),
        st.tuples(
            st.lists(st.sampled_from([*SOURCES, "lna"]), min_size=1, max_size=4).map(
                lambda t: _step("s11", {"targets": t})
            ),
            st.just(s.MeasureS11),
        ),
        st.tuples(
            st.builds(
                lambda x, t: _step("spectrum", {"source": x, "seconds": t}),
                st.sampled_from(SOURCES),
                seconds,
            ),
            st.just(s.MeasureSpectrum),
        ),
        st.tuples(
            st.builds(
                lambda x, t: _step("dicke", {"sources": x, "seconds": t}),
                st.lists(st.sampled_from(SOURCES), min_size=1, max_size=3),
                seconds,
            ),
            st.just(s.Dicke),
        ),
        st.tuples(st.just("temperatures"), st.just(s.Temperatures)),
        st.tuples(
            st.builds(
                lambda c, w: _step("tec", {"setpoint_c": c, **({"wait": w} if w else {})}),
                st.floats(5.0, 45.0),
                st.none() | st.just(True) | st.fixed_dictionaries({"hold_s": seconds}),
            ),
            st.just(s.Tec),
        ),
        st.tuples(
            (
                seconds.map(lambda t: {"seconds": t})
                | st.floats(0, 23.99).map(lambda h: {"until_lst_h": h})
            ).map(lambda a: _step("wait", a)),
            st.just(s.Wait),
        ),
        st.tuples(st.just({"calibrate": {"tolerance": 0.05}}), st.just(s.Calibrate)),
        st.tuples(
            st.builds(
                lambda n, t, e: _step("observe", {"cycles": n, "seconds": t, "test_load_every": e}),
                st.integers(1, 20),
                seconds,
                st.integers(1, 10),
            ),
            st.just(s.Observe),
        ),
        st.tuples(st.just("safe"), st.just(s.Safe)),
    )


def any_step() -> st.SearchStrategy[tuple[dict, type]]:
    repeat = st.builds(
        lambda n, body: ({"repeat": {"count": n, "steps": [b for b, _ in body]}}, s.Repeat),
        st.integers(1, 4),
        st.lists(simple_steps(), min_size=1, max_size=4),
    )
    return simple_steps() | repeat


valid_schedules = st.lists(any_step(), min_size=0, max_size=10).map(
    lambda steps: (
        {"schedule": "random", "steps": ["initialise", *(step for step, _ in steps)]},
        [s.Initialise, *(kind for _, kind in steps)],
    )
)


@PROFILE
@given(case=valid_schedules, flow=st.booleans())
def test_valid_schedules_compile_step_for_step(case, flow):
    document, kinds = case
    schedule = compile_text(
        yaml.safe_dump(document, default_flow_style=flow, sort_keys=False),
        "ok.yaml",
        start_utc=START,
    )
    assert [type(step) for step in schedule.steps] == kinds
    assert all(step.where.file == "ok.yaml" for step in schedule.steps)
    lines = [step.where.line for step in schedule.steps]
    assert lines == sorted(lines)


# --------------------------------------------------------------------------- (c) one unknown key
BOGUS = "bogus_key_zq"


def _mapping_paths(value, path=()):
    """Every (path to a mapping, key) in a document."""
    if isinstance(value, dict):
        for key, child in value.items():
            yield (path, key)
            yield from _mapping_paths(child, (*path, key))
    elif isinstance(value, list):
        for index, child in enumerate(value):
            yield from _mapping_paths(child, (*path, index))


def _renamed(document, path, key):
    def rebuild(value, rest):
        if not rest:
            return {(BOGUS if k == key else k): v for k, v in value.items()}
        head, *tail = rest
        if isinstance(value, dict):
            return {k: (rebuild(v, tail) if k == head else v) for k, v in value.items()}
        return [rebuild(v, tail) if i == head else v for i, v in enumerate(value)]

    return rebuild(document, list(path))


@PROFILE
@given(case=valid_schedules, choice=st.integers(0, 10**6))
def test_an_unknown_key_is_named_with_its_line(case, choice):
    document, _ = case
    places = list(_mapping_paths(document))
    path, key = places[choice % len(places)]
    text = yaml.safe_dump(_renamed(document, path, key), default_flow_style=False, sort_keys=False)
    (line,) = [i + 1 for i, row in enumerate(text.splitlines()) if BOGUS in row]
    with pytest.raises(ScheduleError) as caught:
        compile_text(text, "mut.yaml", start_utc=START)
    named = [p for p in caught.value.problems if p.key.split(".")[-1] == BOGUS]
    assert named, str(caught.value)
    assert all(p.line == line and p.file == "mut.yaml" for p in named), (str(caught.value), text)
