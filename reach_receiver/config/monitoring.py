"""The site file's ``monitoring`` section: cadence, storage, Prometheus, alarms, hook.

::

    monitoring:
      cadence_s: 60                  # one sample a minute (thesis 2.1.3)
      database: /var/lib/reach/metrics.sqlite   # default: <state_dir>/metrics.sqlite
      retention: {minute_days: 30, quarter_days: 730}
      prometheus: {port: 9818}       # served on 127.0.0.1 only; 0 = any free port
      hook: {command: [/usr/local/bin/reach-alarm], timeout_s: 10}
      alarms:                        # merged by name over DEFAULT_ALARMS
        - {name: enclosure, metric: reach_tec_temperature_celsius, below: 15, above: 35,
           hysteresis: 0.5, for_s: 600}
        - {name: thermocouple, metric: reach_tc08_fault, above: 0.5, enabled: false}

An alarm rule watches every series of ``metric`` (optionally only those with the given
``labels``): it is raised when a value has been above ``above`` or below ``below`` for
``for_s`` seconds without a break (0: at the first such value), and cleared only once
the value is back inside by ``hysteresis``. A series whose device is not read (powered
off, not yet brought up: status ``unknown``) raises nothing, and clears its alarm.
``severity`` (``warn`` or ``error``, default ``error``) becomes the status of the
readings it concerns. The hook, when given, is run with the alarm's event as its last
arguments (``raised`` or ``cleared``, the alarm's name, its text for people and its
detail, ``name: series key``) and killed after ``timeout_s``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from .fields import Fields, type_name
from .yaml_lines import LineDict, LineList, Problem

MONITORING_KEYS = ("cadence_s", "database", "retention", "prometheus", "hook", "alarms")
ALARM_KEYS = ("name", "metric", "labels", "above", "below", "hysteresis", "for_s", "severity",
              "enabled")


#: The drift check's statistic (:func:`reach_receiver.run.checks.compare_on_source`), one
#: reading per calibration, and the name of its alarm.
DRIFT_METRIC = "reach_calibration_drift_sigma"
DRIFT_ALARM = "calibration drift"


@dataclass(frozen=True)
class AlarmRule:
    """A threshold on the series of one metric, with hysteresis."""

    name: str
    metric: str
    above: float | None = None
    below: float | None = None
    hysteresis: float = 0.0
    severity: Literal["warn", "error"] = "error"
    labels: Mapping[str, str] = field(default_factory=dict)
    enabled: bool = True
    for_s: float = 0.0


#: Alarms every site has unless it changes them (by name).
#:
#: A single failed read (a USB hiccup, an interrupted system call) is not an outage: a
#: device is "silent" after two minutes of failed reads, two samples at the default
#: cadence. The enclosure is held by its TEC at the schedule's setpoint (25 C in
#: ``common.yaml``; the thesis' laboratory runs used 30 C and its thermal test 10 C), so
#: its alarm bounds what the electronics may see, not one setpoint: 10 to 40 C, for ten
#: minutes, as the plate relaxes slowly (an 8-hour settling in the thesis' test) and a
#: passing excursion needs nobody.
#:
#: A calibration drift is one test per calibration of the new solution against the
#: previous one (:func:`reach_receiver.run.checks.compare_on_source`), stated in Gaussian
#: sigma of its tail probability: 3.9 sigma is a false-alarm probability of 1e-4 per
#: calibration, 0.3 % over a week of calibrations every 6 h; it clears when a later
#: calibration agrees with its predecessor within 3 sigma.
DEFAULT_ALARMS: tuple[AlarmRule, ...] = (
    AlarmRule("device silent", "reach_device_up", below=0.5, for_s=120.0),
    AlarmRule("tec fault", "reach_tec_fault_bits", above=0.5),
    AlarmRule("enclosure temperature", "reach_tec_temperature_celsius", below=10.0,
              above=40.0, hysteresis=0.5, for_s=600.0),
    AlarmRule("thermocouple", "reach_tc08_fault", above=0.5, for_s=120.0),
    AlarmRule("low disk", "reach_disk_free_bytes", below=5e9, hysteresis=1e9),
    AlarmRule("spectrometer loss", "reach_spectrometer_loss_ratio", above=1e-3,
              hysteresis=5e-4, severity="warn"),
    AlarmRule(DRIFT_ALARM, DRIFT_METRIC, above=3.9, hysteresis=0.9, severity="warn"),
)


@dataclass(frozen=True)
class MonitoringSettings:
    """How ``reachd`` samples, keeps and reports the receiver's health."""

    cadence_s: float = 60.0
    database: Path | None = None
    minute_days: float = 30.0
    quarter_days: float = 730.0
    prometheus_port: int | None = None
    hook: tuple[str, ...] = ()
    hook_timeout_s: float = 10.0
    alarms: tuple[AlarmRule, ...] = DEFAULT_ALARMS

    def database_path(self, state_dir: Path) -> Path:
        """The metrics file: the site's, else ``metrics.sqlite`` in the state directory."""
        return self.database if self.database is not None else state_dir / "metrics.sqlite"


def read_monitoring(section: Fields, problems: list[Problem]) -> MonitoringSettings:
    """Read the ``monitoring`` section (each mistake reported with its line)."""
    base = MonitoringSettings()
    cadence = section.number("cadence_s", base.cadence_s, low=0.0, open_low=True,
                             fallback=base.cadence_s)
    database = section.text("database", None)
    minute_days, quarter_days = base.minute_days, base.quarter_days
    retention = section.mapping("retention", ("minute_days", "quarter_days"))
    if retention is not None:
        minute_days = retention.number("minute_days", minute_days, low=0.0, open_low=True,
                                       fallback=minute_days)
        quarter_days = retention.number("quarter_days", quarter_days, low=0.0, open_low=True,
                                        fallback=quarter_days)
    port = None
    prometheus = section.mapping("prometheus", ("port",))
    if prometheus is not None:
        port = int(prometheus.number("port", 9818, low=0, high=65535))
    hook: tuple[str, ...] = ()
    timeout = base.hook_timeout_s
    given = section.mapping("hook", ("command", "timeout_s"))
    if given is not None:
        command = given.raw("command", None)
        if isinstance(command, str):
            command = [command]
        if not isinstance(command, list) or not command or not all(
            isinstance(c, str) and c for c in command
        ):
            given.report("command", f"must be a command as a list of words, not "
                                    f"{type_name(command)}")
        else:
            hook = tuple(command)
        timeout = given.number("timeout_s", timeout, low=0.0, open_low=True, fallback=timeout)
    alarms = _alarms(section, problems)
    return MonitoringSettings(
        cadence_s=cadence,
        database=Path(database) if database else None,
        minute_days=minute_days,
        quarter_days=quarter_days,
        prometheus_port=port,
        hook=hook,
        hook_timeout_s=timeout,
        alarms=alarms,
    )


def _alarms(section: Fields, problems: list[Problem]) -> tuple[AlarmRule, ...]:
    rules = {rule.name: rule for rule in DEFAULT_ALARMS}
    written = section.raw("alarms", None)
    if written is None:
        return tuple(rules.values())
    if not isinstance(written, LineList):
        section.report("alarms", f"must be a list of alarms, not {type_name(written)}")
        return tuple(rules.values())
    for index, item in enumerate(written):
        key = f"{section.key}.alarms[{index}]"
        if not isinstance(item, LineDict):
            problems.append(Problem(section.file, written.line_of(index), key,
                                    f"must be a mapping, not {type_name(item)}"))
            continue
        fields = Fields(item, file=section.file, key=key, allowed=ALARM_KEYS, problems=problems)
        rule = _alarm(fields, rules)
        if rule is not None:
            rules[rule.name] = rule
    return tuple(rules.values())


def _alarm(f: Fields, known: Mapping[str, AlarmRule]) -> AlarmRule | None:
    name = f.text("name") or ""
    default = known.get(name)
    metric = f.text("metric", default.metric if default else None)
    if metric is None:
        f.report("metric", "missing required key (a new alarm needs a metric)", f.args.line)
        return None
    above = f.number("above", None) if f.has("above") else (default.above if default else None)
    below = f.number("below", None) if f.has("below") else (default.below if default else None)
    hysteresis = f.number("hysteresis", default.hysteresis if default else 0.0, low=0.0)
    for_s = f.number("for_s", default.for_s if default else 0.0, low=0.0)
    severity = f.choice("severity", ("warn", "error"), default.severity if default else "error")
    enabled = f.raw("enabled", True)
    if not isinstance(enabled, bool):
        f.report("enabled", f"must be true or false, not {type_name(enabled)}")
    labels = f.raw("labels", {})
    if not isinstance(labels, dict) or not all(isinstance(v, str | int) for v in labels.values()):
        f.report("labels", f"must map label names to values, not {type_name(labels)}")
        labels = {}
    if above is None and below is None:
        f.report("<threshold>", "give above, below or both", f.args.line)
    elif above is not None and below is not None and below + hysteresis >= above - hysteresis:
        f.report("below", f"must be below above ({above:g}) by more than twice the hysteresis")
    if f.failed:
        return None
    return AlarmRule(
        name, str(metric), above, below, hysteresis,
        "warn" if severity == "warn" else "error",
        {str(k): str(v) for k, v in labels.items()}, enabled is not False, for_s,
    )


def monitoring_yaml(settings: MonitoringSettings) -> dict[str, Any]:
    """The ``monitoring`` section that :func:`read_monitoring` reads back as ``settings``.

    Only what differs from the defaults is written; of the alarms, those that differ
    from (or are not among) :data:`DEFAULT_ALARMS`, by name.
    """
    base = MonitoringSettings()
    out: dict[str, Any] = {}
    if settings.cadence_s != base.cadence_s:
        out["cadence_s"] = settings.cadence_s
    if settings.database is not None:
        out["database"] = str(settings.database)
    if (settings.minute_days, settings.quarter_days) != (base.minute_days, base.quarter_days):
        out["retention"] = {"minute_days": settings.minute_days,
                            "quarter_days": settings.quarter_days}
    if settings.prometheus_port is not None:
        out["prometheus"] = {"port": settings.prometheus_port}
    if settings.hook:
        out["hook"] = {"command": list(settings.hook), "timeout_s": settings.hook_timeout_s}
    defaults = {rule.name: rule for rule in DEFAULT_ALARMS}
    changed = [rule for rule in settings.alarms if defaults.get(rule.name) != rule]
    if changed:
        out["alarms"] = [_alarm_yaml(rule) for rule in changed]
    return out


def _alarm_yaml(rule: AlarmRule) -> dict[str, Any]:
    out: dict[str, Any] = {"name": rule.name, "metric": rule.metric}
    if rule.above is not None:
        out["above"] = rule.above
    if rule.below is not None:
        out["below"] = rule.below
    out["hysteresis"] = rule.hysteresis
    if rule.for_s:
        out["for_s"] = rule.for_s
    out["severity"] = rule.severity
    if rule.labels:
        out["labels"] = dict(rule.labels)
    if not rule.enabled:
        out["enabled"] = False
    return out
