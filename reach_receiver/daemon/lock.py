"""One owner of the hardware: an exclusive lock that the daemon and ``reach-run`` both take.

An advisory ``flock`` on ``<state_dir>/hardware.lock`` (the state directory outlives the
daemon, so ``reach-run`` finds the same file when no daemon runs): the kernel releases it when its
holder exits, however it exits (a crash, SIGKILL, a power cut leaves no stale lock
behind), so a second owner of the front-end is refused while the first lives and
allowed as soon as it is gone. The file holds the owner's pid and what it is, to name
it in the refusal. It is group-writable so that operators of the observing group can
take it too.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from pathlib import Path
from types import TracebackType

from reach_receiver.errors import ReceiverError

LOCK_FILE = "hardware.lock"


class HardwareBusy(ReceiverError):
    """Another process owns the hardware."""


class HardwareLock:
    """The exclusive lock on the hardware, taken with :meth:`acquire` or ``with``."""

    def __init__(self, directory: Path, owner: str) -> None:
        self.path = Path(directory) / LOCK_FILE
        self.owner = owner
        self._fd: int | None = None

    def acquire(self) -> None:
        """Take the lock or raise :class:`HardwareBusy` naming the holder."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o660)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode(errors="replace").strip() or "another process"
            os.close(fd)
            raise HardwareBusy(f"the hardware is owned by {holder} ({self.path})") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{self.owner} (pid {os.getpid()})\n".encode(), 0)
        self._fd = fd

    def release(self) -> None:
        """Give the lock up (closing the file releases it)."""
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, 0)
            os.close(self._fd)
            self._fd = None

    @property
    def held(self) -> bool:
        """Whether this object holds the lock."""
        return self._fd is not None

    def __enter__(self) -> HardwareLock:
        self.acquire()
        return self

    def __exit__(
        self, kind: type[BaseException] | None, err: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.release()
