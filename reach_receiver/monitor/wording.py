"""Alarm text for people: what is wrong, since when, against which threshold.

An operator reading a page on a phone, or a line in the journal, should not have to
decode ``reach_device_up{device=tc08} = 0, below 0.5``. Each alarm is worded from its
rule and its series' labels::

    TC-08 not answering for 5 min (since 14:02 UTC; threshold 2 min)
    enclosure 40.6 C above 40 C for 10 min (since 13:55 UTC)
    data disk 3.1 GB free, below 5 GB (since 09:12 UTC)
    calibration drift on 'ant': +0.41 K (5.1 sigma) over 50.0-70.0 MHz against the
        solution of 12:02 UTC; joint 6.3 sigma over 8 sub-bands (threshold 3.9 sigma;
        since 18:05 UTC)

and its clearing likewise (``TC-08 answering again after 7 min``). A rule of the site's
own (not one of the defaults) has its name before the text: the operator's words for
what it watches. The series key
stays beside the text as the alarm's detail (:attr:`Alarm.id
<reach_receiver.monitor.alarms.Alarm.id>`), for scripts and for ``reach-run metrics``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from datetime import datetime, timezone

from reach_receiver.config.monitoring import DEFAULT_ALARMS, DRIFT_METRIC, AlarmRule

_DEFAULT_NAMES = frozenset(rule.name for rule in DEFAULT_ALARMS)
#: How each monitored device is called in text.
DEVICES = {"tc08": "TC-08", "teensy": "Teensy", "tec": "TEC", "vna": "VNA",
           "spectrometer": "spectrometer"}


def duration(seconds: float) -> str:
    """``40 s``, ``5 min``, ``2 h 10 min``, ``3 d 4 h``: two units at most, rounded down."""
    s = max(int(seconds), 0)
    if s < 60:
        return f"{s} s"
    minutes = s // 60
    if minutes < 60:
        return f"{minutes} min"
    hours, minutes = divmod(minutes, 60)
    if hours < 24:
        return f"{hours} h {minutes} min" if minutes else f"{hours} h"
    days, hours = divmod(hours, 24)
    return f"{days} d {hours} h" if hours else f"{days} d"


def clock_time(t: float, now: float) -> str:
    """``14:02 UTC``; with the date when ``t`` is not within the last day."""
    stamp = datetime.fromtimestamp(t, tz=timezone.utc)
    if now - t < 86400.0:
        return stamp.strftime("%H:%M UTC")
    return stamp.strftime("%Y-%m-%d %H:%M UTC")


def subject(metric: str, labels: Mapping[str, str]) -> str:
    """What a series is about, in words (``TC-08``, ``enclosure``, ``thermocouple 3``)."""
    if metric.startswith("reach_device_"):
        device = labels.get("device", "?")
        return DEVICES.get(device, device)
    if metric == "reach_tec_temperature_celsius":
        return "enclosure"
    if metric.startswith("reach_tc08_"):
        channel = labels.get("channel", "?")
        component = labels.get("component")
        return f"thermocouple {channel}" + (f" ({component})" if component else "")
    if metric == "reach_teensy_temperature_celsius":
        return f"front-end sensor {labels.get('sensor', '?')}"
    if metric.startswith("reach_disk_"):
        return "data disk"
    if metric.startswith("reach_spectrometer_"):
        return "spectrometer"
    if metric.startswith("reach_tec_"):
        return "TEC"
    inner = ",".join(f"{k}={v}" for k, v in sorted(labels.items()))
    return f"{metric}{{{inner}}}" if inner else metric


def quantity(metric: str, value: float) -> str:
    """A value with its unit, as people write it (``25.3 C``, ``3.1 GB``, ``0.2 %``)."""
    if math.isnan(value):
        return "unknown"
    if metric.endswith("_celsius"):
        return f"{value:.1f} C".replace(".0 C", " C")
    if metric.endswith("_bytes"):
        return f"{value / 1e9:.1f} GB".replace(".0 GB", " GB")
    if metric.endswith("_ratio"):
        return f"{100 * value:.2g} %"
    if metric.endswith("_seconds"):
        return duration(value)
    return f"{value:g}"


def raised(rule: AlarmRule, labels: Mapping[str, str], value: float, since: float,
           now: float, note: str = "") -> str:
    """The text of a raised alarm at ``now`` (its condition holding since ``since``).

    ``note`` is the latest reading's own words (:attr:`Reading.note
    <reach_receiver.monitor.readings.Reading.note>`), where a number alone says too little.
    """
    what = subject(rule.metric, labels)
    when = clock_time(since, now)
    lasting = duration(now - since)
    if rule.metric == DRIFT_METRIC:
        found = note or f"joint {value:.1f} sigma"
        return f"calibration drift {found} (threshold {rule.above:g} sigma; since {when})"
    if rule.metric == "reach_device_up":
        return (f"{what} not {_answering(labels)} for {lasting} (since {when}; "
                f"threshold {duration(rule.for_s)})")
    if rule.metric == "reach_tc08_fault":
        return f"{what} open or out of range for {lasting} (since {when})"
    if rule.metric == "reach_tec_fault_bits":
        return f"TEC reports fault bits 0x{int(value):02x} (since {when})"
    high = rule.above is not None and value > rule.above
    limit = rule.above if high else rule.below
    side = "above" if high else "below"
    shown = quantity(rule.metric, value)
    bound = quantity(rule.metric, math.nan if limit is None else limit)
    if rule.metric.startswith("reach_disk_free"):
        shown += " free,"
    text = f"{what} {shown} {side} {bound}"
    if rule.name not in _DEFAULT_NAMES:
        text = f"{rule.name}: {text}"
    if rule.for_s > 0:
        return f"{text} for {lasting} (since {when})"
    return f"{text} (since {when})"


def cleared(rule: AlarmRule, labels: Mapping[str, str], value: float, since: float,
            now: float, unknown: bool = False, note: str = "") -> str:
    """The text of an alarm's clearing at ``now``; ``unknown``: its series is no longer read."""
    what = subject(rule.metric, labels)
    lasted = duration(now - since)
    if rule.metric == DRIFT_METRIC:
        return (f"calibration drift over: the new solution agrees with the previous one "
                f"(joint {value:.1f} sigma) after {lasted}")
    if unknown:
        return f"{what} no longer read (powered off or not brought up); alarm lasted {lasted}"
    if rule.metric == "reach_device_up":
        return f"{what} {_answering(labels)} again after {lasted}"
    if rule.metric == "reach_tc08_fault":
        return f"{what} reads again after {lasted}"
    if rule.metric == "reach_tec_fault_bits":
        return f"TEC fault bits clear after {lasted}"
    return f"{what} back to {quantity(rule.metric, value)} after {lasted}"


def _answering(labels: Mapping[str, str]) -> str:
    """What a working device does: the spectrometer sends, the others answer."""
    return "sending" if labels.get("device") == "spectrometer" else "answering"
