"""``reachd --check``: is this machine ready to observe? One line per check.

Before the daemon takes the hardware (or after something changed on site: a cable, a
USB hub, an upgrade), an operator wants to know at a glance whether each instrument in
the site file answers, whether the udev names it uses exist, whether the clock that
stamps every spectrum is synchronised, whether the data disk has room, and whether the
data and runtime directories have the permissions the observing group relies on.
:func:`run_checks` answers each of these independently, so one failure never hides the
others, and :func:`format_checks` prints them one aligned line each::

      ok    teensy port   /dev/reach-teensy -> /dev/ttyACM0: character device, mode 0660, ...
      ok    teensy        /dev/reach-teensy: REACH front-end teensy35, firmware 1.2.0, ...
      fail  vna           TCPIP0::192.168.10.20::5025::SOCKET: write failed: [Errno 113] ...

The device probes only ask: the Teensy is connected (identity and protocol version) and
closed, never switched; the VNA answers ``*IDN?``; one complete spectrum arrives; the
TC-08 converts once; a TEC on its own serial port reports its status. Nothing is armed,
powered or moved. Every blocking call has a finite deadline: the site's timeouts for
the Teensy, the VNA and the TEC (the same the run uses), ``timeout_s`` for the spectrum
and for each call into the TC-08's library.

The probes open the devices, so run the checks while no daemon or ``reach-run`` holds
them (the spectrometer's UDP port in particular can be bound only once).
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import grp
import logging
import math
import os
import pwd
import shutil
import stat
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, TypeVar

from reach_receiver.clock import Clock
from reach_receiver.config.site import SiteConfig
from reach_receiver.devices.spectrometer import Spectrometer
from reach_receiver.devices.tc08 import Tc08
from reach_receiver.devices.tec import Tec
from reach_receiver.devices.teensy import PROTOCOL_VERSION, Teensy
from reach_receiver.devices.vna import Vna
from reach_receiver.errors import DeviceError, ReceiverError
from reach_receiver.run.instruments import Instruments
from reach_receiver.store.run_store import DICKE_POSITIONS

log = logging.getLogger(__name__)

T = TypeVar("T")
Status = Literal["ok", "warn", "fail"]
STATUSES: tuple[Status, ...] = ("ok", "warn", "fail")

#: Free space below which the disk check fails (a warning below twice this).
DEFAULT_MIN_FREE_BYTES = 10 * 2**30
#: Where the udev rules that give the instruments their stable names live.
UDEV_RULES = "deploy/udev/99-reach.rules"

# The assumptions of the data rate estimate (:func:`run_bytes_per_hour`).
#: The iTPM's spectrum: 2 inputs x 16384 channels of float64 (devices.spectrometer).
SPECTRUM_INPUTS, SPECTRUM_CHANNELS, VALUE_BYTES = 2, 16384, 8
#: One Dicke cycle (source, load, noise source) every ten minutes, as ``observe.yaml``.
CYCLE_S = 600.0
#: Part files and the merged ``run.h5`` coexist until the merge at the end of a run.
MERGE_FACTOR = 2

# The kernel's NTP state (``man 2 adjtimex``).
#: ``ntp_adjtime`` returns this clock state when the clock is not synchronised.
TIME_ERROR = 5
#: ``status`` bit: the clock is not synchronised.
STA_UNSYNC = 0x40


@dataclass(frozen=True)
class Check:
    """The outcome of one check: what was checked, how it went, and the evidence.

    Attributes
    ----------
    name
        What was checked, as the operator knows it (``"teensy"``, ``"disk"``...).
    status
        ``"ok"``; ``"warn"`` (usable, but look at it); ``"fail"`` (do not observe).
    detail
        One line: the address or path from the site file and what was found there.
    """

    name: str
    status: Status
    detail: str

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"check status must be one of {STATUSES}, not {self.status!r}")


def failed(checks: Iterable[Check]) -> bool:
    """Whether any check failed (the command's exit status is non-zero then)."""
    return any(check.status == "fail" for check in checks)


def format_checks(checks: Iterable[Check]) -> str:
    """One aligned line per check: ``  <status> <name> <detail>``, no trailing newline."""
    checks = list(checks)
    width = max((len(check.name) for check in checks), default=0)
    return "\n".join(
        f"  {check.status:<5} {check.name:<{width}} {' '.join(check.detail.splitlines())}"
        for check in checks
    )


def run_checks(
    site: SiteConfig,
    *,
    clock: Clock,
    data_dir: Path,
    runtime_dir: Path | None,
    min_free_bytes: int = DEFAULT_MIN_FREE_BYTES,
    timeout_s: float = 10.0,
) -> list[Check]:
    """Every check of ``reachd --check``, each independent of the others.

    Parameters
    ----------
    site
        The site file: which devices to probe and where.
    clock
        The clock the drivers stamp with (the wall clock on site).
    data_dir
        Where runs are written: its free space and permissions are checked.
    runtime_dir
        The daemon's runtime directory (control socket, state); None skips it.
    min_free_bytes
        Free space on the data disk below which the disk check fails.
    timeout_s
        Longest wait for one spectrum and for each call into the TC-08's library.

    Returns
    -------
    list of Check
        Device names, devices, clock, disk, then directories; :func:`failed` tells
        whether the machine is ready.
    """
    checks = device_path_checks(site)
    checks += device_checks(site, clock, timeout_s=timeout_s)
    checks.append(check_clock())
    checks.append(check_disk(data_dir, min_free_bytes, run_bytes_per_hour(site)))
    checks.append(check_directory("data dir", data_dir, private=True))
    if runtime_dir is not None:
        checks.append(check_directory("runtime dir", runtime_dir, private=False))
    return checks


# -- device names ------------------------------------------------------------------------


def device_path_checks(site: SiteConfig) -> list[Check]:
    """The paths the site file names: the Teensy's port, a serial TEC's, the TC-08 library.

    A missing udev name is the commonest reason a device "does not answer", and the
    fix (install the rules, plug it in, join the group) is not the same as for a
    device that is there but silent, so these get lines of their own.
    """
    devices = site.devices
    plug = f"are the udev rules installed ({UDEV_RULES}) and the"
    checks = [check_device_path("teensy port", devices.teensy.port, f"{plug} board plugged in?")]
    if devices.tec.via == "serial" and devices.tec.port is not None:
        hint = f"{plug} TEC's serial adapter plugged in?"
        checks.append(check_device_path("tec port", devices.tec.port, hint))
    checks.append(check_library_path("tc08 library", devices.tc08.library))
    return checks


def check_device_path(name: str, path: str, hint: str) -> Check:
    """A serial port: it exists, is a character device, and this process may use it.

    Parameters
    ----------
    name
        The check's name.
    path
        The port from the site file (often a udev symlink such as ``/dev/reach-teensy``).
    hint
        What to look at when the path does not exist.
    """
    shown = _with_target(path)
    try:
        info = os.stat(path)
    except FileNotFoundError:
        return Check(name, "fail", f"no {path}: {hint}")
    except OSError as err:
        return Check(name, "fail", f"{path}: {err.strerror or err}")
    described = f"mode {_mode(info)}, group {_group(info.st_gid)}"
    if not stat.S_ISCHR(info.st_mode):
        return Check(name, "fail", f"{shown}: not a character device ({described})")
    if not os.access(path, os.R_OK | os.W_OK):
        who = _user()
        advice = f"add {who} to group {_group(info.st_gid)} (or fix the udev rule's MODE)"
        return Check(name, "fail", f"{shown}: not readable and writable by {who}: {advice}")
    return Check(name, "ok", f"{shown}: character device, {described}")


def check_library_path(name: str, path: str | None) -> Check:
    """The TC-08's ``libusbtc08``: the site's file exists, or the loader can find one.

    Without a path the driver asks the dynamic loader; whether the library it finds
    loads is the ``tc08`` device line's business.
    """
    if path is None:
        found = ctypes.util.find_library("usbtc08")
        if found is None:
            detail = "not set, and the loader finds no usbtc08 (the tc08 line tries /opt)"
            return Check(name, "warn", detail)
        return Check(name, "ok", f"not set; the loader finds {found}")
    if not os.path.isfile(path):
        hint = "install Pico's libusbtc08 package or fix devices.tc08.library"
        return Check(name, "fail", f"no {path}: {hint}")
    return Check(name, "ok", f"{_with_target(path)}: file exists")


# -- devices -------------------------------------------------------------------------------


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


# -- clock ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class KernelClock:
    """The kernel's view of its clock discipline, as ``ntp_adjtime`` returns it.

    Attributes
    ----------
    state
        The call's return value: ``TIME_OK`` (0) ... ``TIME_ERROR`` (5).
    status
        The ``STA_*`` bits; ``STA_UNSYNC`` (0x40) while not synchronised.
    esterror_us, maxerror_us
        The estimated and maximum error of the clock, microseconds.
    """

    state: int
    status: int
    esterror_us: int
    maxerror_us: int

    @property
    def synchronised(self) -> bool:
        """Whether the kernel considers its clock synchronised (by chrony or ntpd)."""
        return self.state != TIME_ERROR and not self.status & STA_UNSYNC


class _Timex(ctypes.Structure):
    """Linux's ``struct timex`` (``<sys/timex.h>``), with room to spare at the end."""

    _fields_ = [
        ("modes", ctypes.c_uint),
        ("offset", ctypes.c_long),
        ("freq", ctypes.c_long),
        ("maxerror", ctypes.c_long),
        ("esterror", ctypes.c_long),
        ("status", ctypes.c_int),
        ("constant", ctypes.c_long),
        ("precision", ctypes.c_long),
        ("tolerance", ctypes.c_long),
        ("time_sec", ctypes.c_long),
        ("time_usec", ctypes.c_long),
        ("tick", ctypes.c_long),
        ("ppsfreq", ctypes.c_long),
        ("jitter", ctypes.c_long),
        ("shift", ctypes.c_int),
        ("stabil", ctypes.c_long),
        ("jitcnt", ctypes.c_long),
        ("calcnt", ctypes.c_long),
        ("errcnt", ctypes.c_long),
        ("stbcnt", ctypes.c_long),
        ("tai", ctypes.c_int),
        # The kernel's 11 reserved ints, and more: it must never write past our buffer.
        ("reserved", ctypes.c_int * 64),
    ]


def read_kernel_clock() -> KernelClock | None:
    """Ask the kernel (``ntp_adjtime``, read-only: ``modes = 0``) for its NTP state.

    The kernel's state is what chrony or ntpd set after each update, so this needs no
    daemon-specific tool or subprocess.

    Returns
    -------
    KernelClock or None
        None where the call does not exist (not Linux, no such libc symbol).

    Raises
    ------
    OSError
        When the call fails.
    """
    if not sys.platform.startswith("linux"):
        return None
    libc = ctypes.CDLL(None, use_errno=True)
    call = getattr(libc, "ntp_adjtime", None) or getattr(libc, "adjtimex", None)
    if call is None:
        return None
    call.argtypes = [ctypes.POINTER(_Timex)]
    call.restype = ctypes.c_int
    timex = _Timex()
    state = call(ctypes.byref(timex))
    if state < 0:
        code = ctypes.get_errno()
        raise OSError(code, os.strerror(code))
    return KernelClock(state, timex.status, timex.esterror, timex.maxerror)


def clock_check(kernel: KernelClock) -> Check:
    """Decode the kernel's NTP state into a line: ``fail`` when not synchronised.

    Every spectrum is stamped in UTC and sidereal time from this clock, and the
    schedule waits for sidereal times by it: an unsynchronised clock misplaces both.
    """
    if kernel.synchronised:
        error = f"estimated error {_duration_us(kernel.esterror_us)}"
        bound = f"at most {_duration_us(kernel.maxerror_us)}"
        return Check("clock", "ok", f"synchronised ({error}, {bound})")
    reasons = []
    if kernel.state == TIME_ERROR:
        reasons.append("clock state TIME_ERROR")
    if kernel.status & STA_UNSYNC:
        reasons.append("STA_UNSYNC set")
    detail = f"not synchronised ({', '.join(reasons)}): is chrony or ntpd running with a source?"
    return Check("clock", "fail", detail)


def check_clock() -> Check:
    """The clock line: the kernel's NTP state, or a warning where it cannot be read."""
    try:
        kernel = read_kernel_clock()
    except OSError as err:
        detail = f"cannot read the kernel's NTP state: {err}"
        if err.errno == errno.EPERM:
            # systemd's ProtectClock= blocks even a read-only adjtimex (systemd#26413).
            detail += " (a seccomp filter such as systemd's ProtectClock=; run it from a shell)"
        return Check("clock", "warn", detail)
    if kernel is None:
        detail = f"cannot read the kernel's NTP state on {sys.platform}: check it by hand"
        return Check("clock", "warn", detail)
    return clock_check(kernel)


def _duration_us(microseconds: float) -> str:
    if microseconds >= 1e6:
        return f"{microseconds / 1e6:.1f} s"
    if microseconds >= 1e3:
        return f"{microseconds / 1e3:.1f} ms"
    return f"{microseconds:.0f} us"


# -- disk ----------------------------------------------------------------------------------


def run_bytes_per_hour(site: SiteConfig) -> float:
    """Bytes an hour of observation adds to the data disk, roughly and on the high side.

    Assumes Dicke cycles back to back, one every :data:`CYCLE_S` (10 minutes, as
    ``schedules/observe.yaml``): each of the three positions stores one mean spectrum
    (2 inputs x 16384 channels, float64: 256 KiB) and the UTC and sidereal time
    (2 float64) of every spectrum it averaged (``period_s`` from the site: 600 per cycle
    at REACH's 1 s). Part files and the merged ``run.h5`` coexist until the merge, hence
    :data:`MERGE_FACTOR`. S11s, temperatures, solutions and HDF5's overhead are small
    beside this and left out. About 9.6 MB an hour at 1 s spectra.
    """
    spectra = len(DICKE_POSITIONS) * SPECTRUM_INPUTS * SPECTRUM_CHANNELS * VALUE_BYTES
    timestamps = CYCLE_S / site.devices.spectrometer.period_s * 2 * VALUE_BYTES
    return MERGE_FACTOR * (spectra + timestamps) * 3600.0 / CYCLE_S


def check_disk(data_dir: Path, min_free_bytes: int, bytes_per_hour: float) -> Check:
    """Free space where runs are written: ``fail`` below the minimum, ``warn`` below twice.

    The line says how many hours of observation the free space holds at
    ``bytes_per_hour`` (:func:`run_bytes_per_hour`), which is what an operator planning
    a campaign wants to know.
    """
    where = _existing(data_dir)
    try:
        usage = shutil.disk_usage(where)
    except OSError as err:
        return Check("disk", "fail", f"{data_dir}: {err.strerror or err}")
    hours = usage.free / bytes_per_hour
    detail = (
        f"{data_dir}: {_gib(usage.free)} free of {_gib(usage.total)}, about {hours:,.0f} h "
        f"of observation at {bytes_per_hour / 1e6:.1f} MB/h"
    )
    minimum = _gib(min_free_bytes)
    if usage.free < min_free_bytes:
        return Check("disk", "fail", f"{detail}; below the minimum {minimum}")
    if usage.free < 2 * min_free_bytes:
        return Check("disk", "warn", f"{detail}; less than twice the minimum {minimum}")
    return Check("disk", "ok", detail)


def _gib(n_bytes: float) -> str:
    return f"{n_bytes / 2**30:.1f} GiB"


# -- directories ---------------------------------------------------------------------------


def check_directory(name: str, path: Path, *, private: bool) -> Check:
    """A directory the daemon writes: usable by this process and safe from others.

    ``fail`` when it is not a directory, is not writable by this process (nor can be
    created), or is world-writable (anyone could replace a run file or the control
    socket). With ``private`` (the data directory) a directory readable by others is a
    warning: run files are meant for the observing group (directories ``0750``, files
    ``0640``, as the store makes them).
    """
    path = Path(path)
    if not path.exists() and not path.is_symlink():
        return _creatable(name, path)
    try:
        info = path.stat()
    except OSError as err:
        return Check(name, "fail", f"{path}: {err.strerror or err}")
    described = f"mode {_mode(info)}, group {_group(info.st_gid)}"
    if not stat.S_ISDIR(info.st_mode):
        return Check(name, "fail", f"{path}: not a directory ({described})")
    if info.st_mode & stat.S_IWOTH:
        return Check(name, "fail", f"{path}: world-writable ({described}): chmod o-w")
    if not os.access(path, os.W_OK | os.X_OK):
        return Check(name, "fail", f"{path}: not writable by {_user()} ({described})")
    if private and info.st_mode & stat.S_IROTH:
        advice = "run files are for the observing group: chmod 0750"
        return Check(name, "warn", f"{path}: readable by others ({described}); {advice}")
    return Check(name, "ok", f"{path}: {described}")


def _creatable(name: str, path: Path) -> Check:
    """The line of a directory that does not exist yet: whether this process can create it."""
    parent = _existing(path)
    if parent.is_dir() and os.access(parent, os.W_OK | os.X_OK):
        return Check(name, "ok", f"{path}: does not exist yet; {_user()} can create it")
    return Check(name, "fail", f"{path}: does not exist, and {parent} is not writable by {_user()}")


def _existing(path: Path) -> Path:
    """``path`` or its nearest ancestor that exists."""
    path = Path(path).absolute()
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def _mode(info: os.stat_result) -> str:
    return f"{stat.S_IMODE(info.st_mode):04o}"


def _group(gid: int) -> str:
    try:
        return grp.getgrgid(gid).gr_name
    except KeyError:
        return str(gid)


def _user() -> str:
    uid = os.geteuid()
    try:
        return pwd.getpwuid(uid).pw_name
    except KeyError:
        return f"uid {uid}"


def _with_target(path: str) -> str:
    """``path``, with where it points when it is a symlink (udev names are)."""
    if os.path.islink(path):
        return f"{path} -> {os.path.realpath(path)}"
    return path


__all__ = [
    "DEFAULT_MIN_FREE_BYTES",
    "STATUSES",
    "Check",
    "KernelClock",
    "Status",
    "check_clock",
    "check_device_path",
    "check_directory",
    "check_disk",
    "check_library_path",
    "clock_check",
    "device_checks",
    "device_path_checks",
    "failed",
    "format_checks",
    "read_kernel_clock",
    "run_bytes_per_hour",
    "run_checks",
]
