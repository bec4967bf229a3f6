"""Room on the disk: a write that would not fit is refused by name, before it starts.

A full disk must be an error an operator can read ("no space left on device: ... has
120 kB free, a measurement needs 800 kB"), never a crash inside HDF5's C library, which
on ``ENOSPC`` can leave the library in a state where the next call fails with an
unrelated message or the process dies. So the store builds every HDF5 file in memory
(:func:`~.parts.atomic_h5`) and hands the bytes to :func:`write_durably`, which

* compares them with the free space of the directory (``statvfs``, as an unprivileged
  writer sees it) plus a margin, and with the process's file-size limit
  (``RLIMIT_FSIZE``, ``ulimit -f``), raising :class:`DiskFull` when they do not fit;
* writes them with plain ``os.write`` calls into a temporary beside the target (short
  writes continued), ``fsync``-s, renames over the target and syncs the directory; a
  write that still fails (another process filled the disk meanwhile) removes the
  temporary and raises :class:`DiskFull` from the ``OSError``.

The target is then either the complete new file or, as before, absent or the old one.
"""

from __future__ import annotations

import contextlib
import errno
import os
import resource
import tempfile
from collections.abc import Callable
from pathlib import Path

from reach_receiver.errors import ReceiverError

#: Free space every write leaves at least (file-system metadata, log lines).
MARGIN_BYTES = 64 * 1024
#: Room a run's measurement leaves free for the records that close the run (bytes).
RESERVE_BYTES = 256 * 1024
#: Errors of a write that did not fit: no space, over quota, over the file-size limit.
FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})


class DiskFull(ReceiverError):
    """A write refused (or failed) for want of room: the disk, a quota, the file-size limit.

    ``directory`` is where it was to go, ``free`` the bytes free there (``None`` when not
    known), ``needed`` the bytes of the write.
    """

    def __init__(self, message: str, directory: Path, free: int | None, needed: int) -> None:
        self.directory = directory
        self.free = free
        self.needed = needed
        super().__init__(message)


def free_bytes(directory: Path) -> int:
    """Bytes an unprivileged writer may still write under ``directory``."""
    st = os.statvfs(directory)
    return st.f_bavail * st.f_frsize


def _kb(n: int) -> str:
    return f"{(n + 1023) // 1024} kB"


def check_space(directory: Path, needed: int, what: str, reserve_bytes: int = 0) -> None:
    """Raise :class:`DiskFull` unless ``needed`` bytes fit in ``directory``.

    ``reserve_bytes`` is room kept free beyond the margin (a run keeps some for the
    records that close it); ``what`` names the write in the message ("a measurement").
    """
    limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    if limit != resource.RLIM_INFINITY and needed > limit:
        raise DiskFull(
            f"file-size limit (ulimit -f) of {_kb(limit)} reached: {what} needs {_kb(needed)} "
            f"in {directory}",
            directory, None, needed,
        )
    free = free_bytes(directory)
    if free < needed + MARGIN_BYTES + reserve_bytes:
        raise DiskFull(
            f"no space left on device: {directory} has {_kb(free)} free, {what} needs "
            f"{_kb(needed)}" + (f" (and {_kb(reserve_bytes)} kept free)" if reserve_bytes else ""),
            directory, free, needed,
        )


def full(err: OSError, directory: Path, needed: int, what: str) -> DiskFull:
    """The :class:`DiskFull` an ``ENOSPC``/``EDQUOT``/``EFBIG`` of a write stands for."""
    try:
        free: int | None = free_bytes(directory)
    except OSError:
        free = None
    room = f"{_kb(free)} free" if free is not None else "free space unknown"
    cause = {errno.EFBIG: "file-size limit (ulimit -f) reached", errno.EDQUOT: "quota exceeded"}
    return DiskFull(
        f"{cause.get(err.errno or 0, 'no space left on device')}: {directory} has {room}, "
        f"{what} needs {_kb(needed)}",
        directory, free, needed,
    )


def write_durably(
    target: Path, data: bytes | memoryview, what: str, *, reserve_bytes: int = 0,
    prepare: Callable[[int], None] | None = None,
) -> None:
    """Write ``data`` to ``target`` atomically and durably, or raise :class:`DiskFull`.

    ``prepare`` receives the temporary's descriptor before any byte is written (to set
    its mode and group); other ``OSError`` s (permissions, a missing directory) propagate
    as they are.
    """
    directory = target.parent
    size = len(data)
    check_space(directory, size, what, reserve_bytes)
    try:
        fd, tmp_name = tempfile.mkstemp(dir=directory, prefix=f".{target.name}.", suffix=".tmp")
    except OSError as err:  # no inode left
        if err.errno in FULL_ERRNOS:
            raise full(err, directory, size, what) from err
        raise
    tmp = Path(tmp_name)
    try:
        try:
            if prepare is not None:
                prepare(fd)
            view = memoryview(data)
            while view:
                written = os.write(fd, view)  # short under a file-size limit: go on
                view = view[written:]
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, target)
    except OSError as err:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        if err.errno in FULL_ERRNOS:
            raise full(err, directory, size, what) from err
        raise
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
    dir_fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)
