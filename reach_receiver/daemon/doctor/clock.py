"""The clock that stamps every spectrum: whether the kernel's clock is synchronised.

Every spectrum is stamped in UTC and sidereal time from this clock, and schedules wait
for sidereal times by it. The kernel's own NTP state (``ntp_adjtime``, read-only), as
chrony or ntpd left it, says whether it is right, with no tool or subprocess.
"""

from __future__ import annotations

import ctypes
import errno
import os
import sys
from dataclasses import dataclass

from .outcome import Check

# The kernel's NTP state (``man 2 adjtimex``).
#: ``ntp_adjtime`` returns this clock state when the clock is not synchronised.
TIME_ERROR = 5
#: ``status`` bit: the clock is not synchronised.
STA_UNSYNC = 0x40


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


__all__ = [
    "STA_UNSYNC",
    "TIME_ERROR",
    "KernelClock",
    "check_clock",
    "clock_check",
    "read_kernel_clock",
]
