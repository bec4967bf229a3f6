"""The instruments' probes: each asked once who it is or for one reading, nothing moved.

The Teensy is connected (identity and protocol version) and closed, never switched; the
VNA answers ``*IDN?``; one complete spectrum arrives; the TC-08 converts once; a TEC on
its own serial port reports its status. Every blocking call has a finite deadline: the
site's timeouts for the Teensy, the VNA and the TEC (the same the run uses),
``timeout_s`` for the spectrum and for each call into the TC-08's library.
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import Callable
from typing import TypeVar

from reach_receiver.clock import Clock
from reach_receiver.config.site import SiteConfig
from reach_receiver.devices.spectrometer import Spectrometer
from reach_receiver.devices.tc08 import Tc08
from reach_receiver.devices.tec import Tec
from reach_receiver.devices.teensy import PROTOCOL_VERSION, Teensy
from reach_receiver.devices.vna import Vna
from reach_receiver.errors import DeviceError, ReceiverError
from reach_receiver.run.instruments import Instruments

from .outcome import Check

log = logging.getLogger(__name__)

T = TypeVar("T")


def device_checks(site: SiteConfig, clock: Clock, *, timeout_s: float = 10.0) -> list[Check]:
    """Probe each instrument of the site once, one line each, never stopping at a failure.

    The drivers are those the run uses (:meth:`Instruments.from_site`), so the probes
    exercise the same transports, addresses and deadlines. See the module's docstring
    for what each probe does; none changes the front-end's state.
    """
    devices = site.devices
    itpm = devices.spectrometer
    addresses = {
        "teensy": devices.teensy.port,
        "vna": devices.vna.resource,
        "spectrometer": f"udp {itpm.host}:{itpm.port}",
        "tc08": devices.tc08.library or "libusbtc08 on the loader's path",
        "tec": devices.tec.port or "via the Teensy",
    }
    try:
        instruments = Instruments.from_site(site, clock)
    except (ReceiverError, OSError, ValueError) as err:
        why = f"cannot build the driver: {err}"
        return [Check(name, "fail", f"{at}: {why}") for name, at in addresses.items()]
    probes: dict[str, Callable[[str], Check]] = {
        "teensy": lambda at: probe_teensy(_as(Teensy, instruments.teensy), at),
        "vna": lambda at: probe_vna(_as(Vna, instruments.vna), at),
        "spectrometer": lambda at: probe_spectrometer(
            _as(Spectrometer, instruments.spectrometer), at, timeout_s
        ),
        "tc08": lambda at: probe_tc08(_as(Tc08, instruments.tc08), at, timeout_s),
    }
    if devices.tec.via == "serial":
        probes["tec"] = lambda at: probe_tec(_as(Tec, instruments.tec), at)
    checks = [_guarded(name, addresses[name], probe) for name, probe in probes.items()]
    if devices.tec.via != "serial":
        detail = "via the Teensy's UART (checked with the Teensy's tec rail on during a run)"
        checks.append(Check("tec", "ok", detail))
    return checks


def probe_teensy(teensy: Teensy, address: str) -> Check:
    """Connect (identity and protocol version are checked there), report, close.

    Only ``ping``, ``id`` and ``version`` are sent: no switch or rail changes.
    """
    with contextlib.closing(teensy):
        teensy.connect()
        firmware = f"firmware {teensy.firmware}, protocol {PROTOCOL_VERSION}"
        return Check("teensy", "ok", f"{address}: {teensy.identity}, {firmware}")


def probe_vna(vna: Vna, address: str) -> Check:
    """Connect (``*IDN?``, which must name a Copper Mountain VNA) and close."""
    with contextlib.closing(vna):
        idn = vna.connect()
        return Check("vna", "ok", f"{address}: {idn.strip()}")


def probe_spectrometer(spectrometer: Spectrometer, address: str, timeout_s: float) -> Check:
    """Bind the port and wait for one complete spectrum; report its shape and the counters.

    A spectrum that does not complete is the usual symptom of an iTPM streaming
    elsewhere (no packets), in the other number format (malformed packets) or into a
    receive buffer too small (lost packets); the counters say which.
    """
    with contextlib.closing(spectrometer):
        spectrometer.connect()
        try:
            spectrum = spectrometer.read_spectrum(timeout_s=timeout_s)
        except ReceiverError as err:
            raise DeviceError("itpm", f"{_message(err)}; {_counters(spectrometer)}") from err
        shape = " x ".join(str(n) for n in spectrum.data.shape)
        detail = f"{address}: one spectrum ({shape}), {_counters(spectrometer)}"
        return Check("spectrometer", "ok", detail)


def probe_tc08(tc08: Tc08, address: str, timeout_s: float) -> Check:
    """Open the unit, convert once, close; flagged channels make a warning.

    A flagged channel (overflow, NaN) is usually an unplugged or broken thermocouple:
    the logger answers, but that component's temperature will be missing from the run.
    """
    tc08.timeout_s = min(tc08.timeout_s, timeout_s)
    with contextlib.closing(tc08):
        tc08.connect()
        reading = tc08.read()
    cold = reading.raw_c.get(0, math.nan)
    thermocouples = [ch for ch in reading.temperatures_c if ch != 0]
    good = [ch for ch in thermocouples if ch not in reading.flags]
    unit = f"unit {tc08.serial}, " if tc08.serial else ""
    detail = (
        f"{address}: {unit}cold junction {cold:.2f} C, "
        f"{len(good)} of {len(thermocouples)} thermocouples read"
    )
    if not reading.flags:
        return Check("tc08", "ok", detail)
    flagged = ", ".join(
        f"channel {ch} ({tc08.ports.get(ch, '?')}) {'/'.join(why)}"
        for ch, why in sorted(reading.flags.items())
    )
    return Check("tc08", "warn", f"{detail}; flagged: {flagged}")


def probe_tec(tec: Tec, address: str) -> Check:
    """Open the TEC's serial port and read its status; a reported fault makes a warning.

    Reading the status changes nothing: the controller keeps regulating as it was.
    """
    with contextlib.closing(tec):
        tec.connect()
        status = tec.status()
    control = "on" if status.controlled else "off"
    detail = (
        f"{address}: {status.temperature:.2f} C, setpoint {status.setpoint:.2f} C, "
        f"control {control}, supply {status.supply_v:.1f} V, firmware {status.version}"
    )
    if status.faults.raw:
        return Check("tec", "warn", f"{detail}; faults: {', '.join(status.faults.active)}")
    return Check("tec", "ok", detail)


def _guarded(name: str, address: str, probe: Callable[[str], Check]) -> Check:
    """Run one probe; any error becomes a ``fail`` line naming the device and address."""
    try:
        return probe(address)
    except (ReceiverError, OSError) as err:
        return Check(name, "fail", f"{address}: {_message(err)}")
    except Exception as err:  # a bug must not hide the other devices' lines
        log.exception("%s: the check itself failed", name)
        return Check(name, "fail", f"{address}: {type(err).__name__}: {err}")


def _as(kind: type[T], device: object) -> T:
    """``device`` as the concrete driver the site builds (the probes need its details)."""
    if not isinstance(device, kind):
        raise TypeError(f"expected a {kind.__name__} driver, found {type(device).__name__}")
    return device


def _message(err: BaseException) -> str:
    """An error's message without a leading ``<device>:`` (the line already names it)."""
    text = str(err)
    if isinstance(err, DeviceError) and text.startswith(f"{err.device}: "):
        text = text[len(err.device) + 2 :]
    return " ".join(text.splitlines()) or type(err).__name__


def _counters(spectrometer: Spectrometer) -> str:
    counts = spectrometer.statistics
    return (
        f"packets received {counts.packets_received}, lost {counts.packets_lost}, "
        f"duplicated {counts.packets_duplicated}, malformed {counts.packets_malformed}, "
        f"late {counts.packets_late}"
    )


__all__ = [
    "device_checks",
    "probe_spectrometer",
    "probe_tc08",
    "probe_tec",
    "probe_teensy",
    "probe_vna",
]
