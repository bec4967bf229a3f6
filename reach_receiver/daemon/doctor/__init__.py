"""``reachd --check``: is this machine ready to observe? One line per check.

Before the daemon takes the hardware (or after something changed on site: a cable, a
USB hub, an upgrade), an operator wants to know at a glance whether each instrument in
the site file answers, whether the udev names it uses exist, whether the clock that
stamps every spectrum is synchronised, whether the data disk has room, and whether the
data and runtime directories have the permissions the observing group relies on.
:func:`run_checks` answers each of these independently, so one failure never hides the
others, and :func:`.outcome.format_checks` prints them one aligned line each::

      ok    teensy port   /dev/reach-teensy -> /dev/ttyACM0: character device, mode 0660, ...
      ok    teensy        /dev/reach-teensy: REACH front-end teensy35, firmware 1.2.0, ...
      fail  vna           TCPIP0::192.168.10.20::5025::SOCKET: write failed: [Errno 113] ...

The device probes only ask: the Teensy is connected (identity and protocol version) and
closed, never switched; the VNA answers ``*IDN?``; one complete spectrum arrives; the
TC-08 converts once; a TEC on its own serial port reports its status. Nothing is armed,
powered or moved. Every blocking call has a finite deadline: the site's timeouts for
the Teensy, the VNA and the TEC (the same the run uses), ``timeout_s`` for the spectrum
and for each call into the TC-08's library.

One module a job: :mod:`.outcome` (a check's line and how the lines print),
:mod:`.paths` (the udev names, the TC-08 library, the directories' permissions),
:mod:`.devices` (the instruments' probes), :mod:`.clock` (the kernel's NTP state) and
:mod:`.disk` (room for how many hours of observation).

The probes open the devices, so run the checks while no daemon or ``reach-run`` holds
them (the spectrometer's UDP port in particular can be bound only once).
"""

from __future__ import annotations

from pathlib import Path

from reach_receiver.clock import Clock
from reach_receiver.config.site import SiteConfig

from .clock import check_clock
from .devices import device_checks
from .disk import DEFAULT_MIN_FREE_BYTES, check_disk, run_bytes_per_hour
from .outcome import Check
from .paths import check_directory, device_path_checks


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


__all__ = ["run_checks"]
