"""The paths the site file names and the directories the daemon writes: present, usable, safe.

A udev name that is missing, a device node the observing group may not open, the TC-08's
library not where the site says, a data directory others can write to: each is a line
of its own, with the fix (install the rules, join the group, ``chmod``) in it.
"""

from __future__ import annotations

import ctypes.util
import grp
import os
import pwd
import stat
from pathlib import Path

from reach_receiver.config.site import SiteConfig

from .outcome import Check

#: Where the udev rules that give the instruments their stable names live.
UDEV_RULES = "deploy/udev/99-reach.rules"


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
    parent = existing(path)
    if parent.is_dir() and os.access(parent, os.W_OK | os.X_OK):
        return Check(name, "ok", f"{path}: does not exist yet; {_user()} can create it")
    return Check(name, "fail", f"{path}: does not exist, and {parent} is not writable by {_user()}")


def existing(path: Path) -> Path:
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
    "UDEV_RULES",
    "check_device_path",
    "check_directory",
    "check_library_path",
    "device_path_checks",
    "existing",
]
