"""Replace a file so that a crash or power cut leaves the old version or the new, never half.

The data go to a temporary file beside the target, which is flushed to disk and renamed
over it (``rename`` is atomic on POSIX file systems); the directory is then flushed too,
so that the rename itself survives a power cut. The temporary file is created with the
umask's permissions (not ``mkstemp``'s 0600), as the target would have been.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def replacing(path: Path) -> Iterator[Path]:
    """A temporary path beside ``path`` to write; on success it replaces ``path`` atomically.

    For a file written in pieces by another library (an HDF5 file of gigabytes, which
    :func:`write_atomically` would hold in memory): write to the yielded path; on leaving,
    it is flushed to disk, renamed over ``path`` and the directory flushed. On an error
    the temporary file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
    _flush_directory(path.parent)


def write_atomically(path: Path, data: bytes | str) -> None:
    """Write ``data`` (text as UTF-8) to ``path`` atomically, creating its directory."""
    raw = data.encode() if isinstance(data, str) else data
    with replacing(path) as tmp:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        with os.fdopen(fd, "wb") as handle:
            handle.write(raw)


def _flush_directory(directory: Path) -> None:
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
