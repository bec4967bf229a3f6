"""The site file's ``monitoring`` section: mistakes at ``file:line: key``, and a round trip."""

from pathlib import Path

import pytest
import yaml
from sites import DEVICES

from reach_receiver.config.monitoring import DEFAULT_ALARMS, AlarmRule, MonitoringSettings
from reach_receiver.config.site import SiteError, load_site, parse_site


def _site_file(tmp_path: Path, monitoring: str) -> Path:
    """A site file whose ``monitoring`` section starts on line 2."""
    path = tmp_path / "site.yaml"
    devices = yaml.safe_dump({"devices": DEVICES}, sort_keys=False)
    path.write_text(f"# site\nmonitoring:\n{monitoring}{devices}")
    return path


@pytest.mark.parametrize(
    ("section", "line", "key", "message"),
    [
        ("  cadence_s: 0\n", 3, "monitoring.cadence_s", "must be in (0, inf), not 0"),
        ("  cadence_s: a minute\n", 3, "monitoring.cadence_s", "must be a number"),
        ("  cadence: 60\n", 3, "monitoring.cadence", "did you mean 'cadence_s'"),
        ("  retention: {minute_days: -1}\n", 3, "monitoring.retention.minute_days", "(0, inf)"),
        ("  prometheus: {port: 70000}\n", 3, "monitoring.prometheus.port", "65535"),
        ("  hook: {command: 7}\n", 3, "monitoring.hook.command", "list of words"),
        ("  alarms:\n    - {name: enclosure temperature, above: hot}\n", 4,
         "monitoring.alarms[0].above", "must be a number"),
        ("  alarms:\n    - {name: low disk, hysteresis: -1}\n", 4,
         "monitoring.alarms[0].hysteresis", "[0, inf)"),
        ("  alarms:\n    - {name: enclosure temperature, below: 30, above: 31,"
         " hysteresis: 1}\n", 4, "monitoring.alarms[0].below", "more than twice the hysteresis"),
        ("  alarms:\n    - {name: enclosure temprature, above: 45}\n", 4,
         "monitoring.alarms[0].metric", "a new alarm needs a metric"),
        ("  alarms:\n    - {name: lna, metric: reach_tc08_temperature_celsius}\n", 4,
         "monitoring.alarms[0].<threshold>", "give above, below or both"),
        ("  alarms:\n    - {name: tec fault, for_s: -60}\n", 4,
         "monitoring.alarms[0].for_s", "[0, inf)"),
        ("  alarms:\n    - {name: tec fault, for_s: ten minutes}\n", 4,
         "monitoring.alarms[0].for_s", "must be a number"),
        ("  alarms:\n    - {name: tec fault, severity: fatal}\n", 4,
         "monitoring.alarms[0].severity", "warn"),
        ("  alarms:\n    - {name: tec fault, enabled: no way}\n", 4,
         "monitoring.alarms[0].enabled", "true or false"),
        ("  alarms:\n    - {name: tec fault, treshold: 1}\n", 4,
         "monitoring.alarms[0].treshold", "unknown key"),
        ("  alarms: {name: tec fault}\n", 3, "monitoring.alarms", "must be a list of alarms"),
    ],
)
def test_each_mistake_is_reported_at_its_line(tmp_path, section, line, key, message):
    path = _site_file(tmp_path, section)
    with pytest.raises(SiteError) as err:
        load_site(path)
    text = str(err.value)
    assert f"{path}:{line}: {key}: " in text, text
    assert message in text, text


def test_mistakes_in_several_alarms_are_reported_at_once(tmp_path):
    path = _site_file(tmp_path, "  cadence_s: -5\n  alarms:\n"
                                "    - {name: low disk, below: lots}\n"
                                "    - {name: new, metric: reach_x, hysteresis: -2, above: 1}\n")
    with pytest.raises(SiteError) as err:
        load_site(path)
    text = str(err.value)
    assert f"{path}:3: monitoring.cadence_s" in text
    assert f"{path}:5: monitoring.alarms[0].below" in text
    assert f"{path}:6: monitoring.alarms[1].hysteresis" in text


def test_alarms_merge_by_name_over_the_defaults(tmp_path):
    path = _site_file(tmp_path, "  alarms:\n    - {name: enclosure temperature, above: 45,"
                                " for_s: 900}\n"
                                "    - {name: lna hot, metric: reach_tc08_temperature_celsius,"
                                " labels: {channel: 7}, above: 50, severity: warn}\n"
                                "    - {name: thermocouple, enabled: false}\n")
    rules = {rule.name: rule for rule in load_site(path).monitoring.alarms}
    assert set(rules) == {rule.name for rule in DEFAULT_ALARMS} | {"lna hot"}
    enclosure = rules["enclosure temperature"]
    assert (enclosure.below, enclosure.above, enclosure.hysteresis) == (10.0, 45.0, 0.5)
    assert (enclosure.for_s, rules["device silent"].for_s) == (900.0, 120.0)
    assert rules["lna hot"] == AlarmRule("lna hot", "reach_tc08_temperature_celsius", above=50.0,
                                         severity="warn", labels={"channel": "7"})
    assert not rules["thermocouple"].enabled


def test_the_section_survives_a_round_trip_through_to_yaml(tmp_path):
    path = _site_file(tmp_path, "  cadence_s: 30\n  database: /var/lib/reach/m.sqlite\n"
                                "  retention: {minute_days: 7, quarter_days: 365}\n"
                                "  prometheus: {port: 0}\n"
                                "  hook: {command: [/usr/bin/mail-alarm, -q], timeout_s: 5}\n"
                                "  alarms:\n    - {name: low disk, below: 2.0e+10}\n"
                                "    - {name: lna, metric: reach_tc08_temperature_celsius,"
                                " labels: {channel: 7}, below: 0, above: 50, hysteresis: 1,"
                                " for_s: 300}\n"
                                "    - {name: spectrometer loss, enabled: false}\n")
    site = load_site(path)
    again = tmp_path / "again.yaml"
    again.write_text(site.to_yaml())
    assert load_site(again).monitoring == site.monitoring
    assert site.monitoring.cadence_s == 30.0
    assert site.monitoring.hook == ("/usr/bin/mail-alarm", "-q")
    default = parse_site({"devices": DEVICES})
    assert "monitoring" not in yaml.safe_load(default.to_yaml())  # defaults are not written
    assert default.monitoring == MonitoringSettings()
