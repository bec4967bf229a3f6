"""Site files: strict parsing, and a source table that changes table A.2 where a site differs."""

import pytest
from sites import DEVICES

from reach_receiver.clock import ManualClock
from reach_receiver.config.site import load_site, parse_site
from reach_receiver.errors import ConfigError
from reach_receiver.frontend.layout import REACH_SOURCES, SourcePosition
from reach_receiver.run import compile_text
from reach_receiver.run.instruments import Instruments
from reach_receiver.run.steps.adaptive import CalibrateAdaptive
from reach_receiver.run.steps.adaptive_run import settings_of
from reach_receiver.schedule.compile import ScheduleError


def test_round_trip_through_yaml(tmp_path):
    site = parse_site(
        {
            "site": {"name": "lab", "longitude_deg": 0.1},
            "devices": DEVICES,
            "references": {"test_load": "/x.s1p"},
            "sources": {
                "hot": {"ms1": 6},
                "r100": {"ms1": 2},
                "c10r250": None,
                "c10lab": {"ms1": 8, "ms4": 4},
            },
        }
    )
    path = tmp_path / "site.yaml"
    path.write_text(site.to_yaml())
    again = load_site(path)
    assert again.sources == site.sources
    assert again.sources["hot"] == SourcePosition(6)
    assert again.sources["c10lab"] == SourcePosition(8, ("ms4", 4))
    assert "c10r250" not in again.sources
    assert again.sources["c10r10"] == REACH_SOURCES["c10r10"]  # table A.2 otherwise


@pytest.mark.parametrize(
    ("sources", "message"),
    [
        ({"x": {"ms1": 9}}, "sources.x.ms1: must be an integer 1-8"),
        ({"x": {"ms1": 7, "ms3": 1, "ms4": 1}}, "both ms3 and ms4"),
        ({"x": {"ms3": 1}}, "must be {ms1"),
        ({"x": {"ms1": 4}}, "'cold' and 'x' sit at the same position"),
    ],
)
def test_bad_source_tables_are_refused(sources, message):
    with pytest.raises(ConfigError, match=message.replace("{", r"\{")):
        parse_site({"devices": DEVICES, "sources": sources})


def test_unknown_keys_are_named_all_at_once():
    with pytest.raises(ConfigError) as err:
        parse_site({"devices": {"vna": {"addr": 1}, "teensy": {"port": "p", "speed": 9}}, "x": 1})
    text = str(err.value)
    assert "devices.vna.addr" in text
    assert "devices.teensy.speed" in text
    assert "unknown section 'x'" in text


def test_a_new_source_needs_a_free_position_and_the_site_file():
    with pytest.raises(ConfigError, match="sit at the same position"):
        parse_site({"devices": DEVICES, "sources": {"spare": {"ms1": 8, "ms4": 4}}})
    table = {"c10r250": None, "spare": {"ms1": 8, "ms4": 4}}
    site = parse_site({"devices": DEVICES, "sources": table})
    text = "schedule: s\nsteps:\n  - initialise\n  - dicke: {sources: [spare], seconds: 60}\n"
    with pytest.raises(ScheduleError, match="unknown source 'spare'"):
        compile_text(text, "s.yaml")  # table A.2 has no 'spare'
    assert len(compile_text(text, "s.yaml", site=site).steps) == 2
    bad = text.replace("spare", "c10r250")
    with pytest.raises(ScheduleError, match="unknown source 'c10r250'"):
        compile_text(bad, "s.yaml", site=site)  # this site removed it


def test_site_sources_reach_the_front_end_and_the_compiler():
    table = {"c10r250": {"ms1": 1}, "ant": {"ms1": 8, "ms4": 4}}  # antenna and load swapped
    site = parse_site({"devices": DEVICES, "sources": table})
    assert site.sources["ant"] == SourcePosition(8, ("ms4", 4))
    instruments = Instruments.from_site(site, ManualClock())
    path = dict(instruments.frontend.path("ant", "lna").switches)
    assert (path["ms1"], path["ms4"]) == (8, 4)
    text = "schedule: s\nsteps:\n  - initialise\n  - dicke: {sources: [ant], seconds: 60}\n"
    schedule = compile_text(text, "s.yaml", site=site)
    assert len(schedule.steps) == 2
    assert REACH_SOURCES["ant"] == SourcePosition(1)  # the default table is untouched


def test_thermocouple_ports_follow_table_2_2_unless_the_site_says_otherwise(tmp_path):
    site = parse_site(
        {
            "devices": DEVICES,
            "sources": {"c10r250": None, "spare": {"ms1": 8, "ms4": 4}},
            "thermocouples": {"spare": 4, "hot": 7},
        }
    )
    assert site.thermocouples["spare"] == 4
    assert site.thermocouples["hot"] == 7
    assert site.thermocouples["cold"] == 1  # table 2.2
    path = tmp_path / "site.yaml"
    path.write_text(site.to_yaml())
    assert load_site(path).thermocouples == site.thermocouples
    with pytest.raises(ConfigError, match=r"thermocouples\.hot: must be a TC-08 port 1-8"):
        parse_site({"devices": DEVICES, "thermocouples": {"hot": 9}})


def test_a_band_of_interest_round_trips_and_reaches_the_adaptive_step(tmp_path):
    site = parse_site({"devices": DEVICES, "calibration": {
        "band_hz": [50e6, 130e6], "band_of_interest_hz": [60e6, 90e6]}})
    assert site.band_of_interest_hz == (60e6, 90e6)
    path = tmp_path / "site.yaml"
    path.write_text(site.to_yaml())
    assert load_site(path).band_of_interest_hz == (60e6, 90e6)
    assert parse_site({"devices": DEVICES}).band_of_interest_hz is None
    step = CalibrateAdaptive("s.yaml:2", sources=("cold", "hot"))
    assert settings_of(step, 1.0, site.band_of_interest_hz).band_hz == (60e6, 90e6)
    own = CalibrateAdaptive("s.yaml:2", sources=("cold", "hot"), band_hz=(70e6, 80e6))
    assert settings_of(own, 1.0, site.band_of_interest_hz).band_hz == (70e6, 80e6)


@pytest.mark.parametrize(
    ("interest", "message"),
    [
        ([40e6, 90e6], "must lie inside the calibration band"),
        ([90e6, 60e6], "with 0 <= low < high"),
        ("60-90", "with 0 <= low < high"),
    ],
)
def test_a_band_of_interest_outside_the_band_or_malformed_is_named(interest, message):
    with pytest.raises(ConfigError) as err:
        parse_site({"devices": DEVICES, "calibration": {"band_of_interest_hz": interest}})
    assert "calibration.band_of_interest_hz" in str(err.value)
    assert message in str(err.value)
