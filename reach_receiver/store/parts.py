"""Part files: one HDF5 file per measurement, each made durable atomically.

A run directory holds ``parts/NNNNNN-<kind>-<name>.h5``, numbered in the order the
measurements completed. A part is built in memory, written under a temporary name in
the same directory (``.NNNNNN-<kind>-<name>.h5.<random>.tmp``) once there is room for it
(:mod:`reach_receiver.disk`), ``fsync``-ed, moved onto its final name with
:func:`os.replace` and the directory is ``fsync``-ed. ``rename`` within one
directory is atomic on POSIX file systems, and the directory sync makes the new name
itself durable (the ext4/XFS rule: a rename is only on disk once its directory is). So a
part is complete if and only if its final name exists; a process killed mid-write
leaves at most a temporary, which readers ignore and :func:`clean_temporaries` removes.

Every part carries the root attributes ``format = "reach-receiver-part"``,
``format_version``, ``kind``, ``name``, ``sequence`` and ``timestamp`` (Unix seconds);
its contents are those of one ``/measurements/...`` group of the merged run file.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import os
import re
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from reach_receiver.disk import RESERVE_BYTES, write_durably
from reach_receiver.errors import ReceiverError

log = logging.getLogger(__name__)

PART_FORMAT = "reach-receiver-part"
#: Run files: the writer reads and writes, the observing group reads (the directory's).
FILE_MODE = 0o640
DIRECTORY_MODE = 0o750
FORMAT_VERSION = "1.0"
PARTS_DIR = "parts"

#: ``units`` attribute values used throughout the store.
UNITS_HZ = "Hz"
UNITS_K = "K"
UNITS_C = "degC"
UNITS_S = "s"
UNITS_HOURS = "h"
UNITS_POWER = "power (arbitrary)"
UNITS_REFLECTION = "complex reflection"
UNITS_NONE = "1"
UNITS_TEXT = "text"

#: Kinds of the small records that close a run: they may use the reserve.
CLOSING_KINDS = frozenset({"event", "status"})

_PART_RE = re.compile(r"^(\d{6})-([a-z0-9_]+)-(.+)\.h5$")
_SAFE_RE = re.compile(r"[^A-Za-z0-9_.+]+")


class StoreError(ReceiverError):
    """A run store used out of order or a run directory that cannot be merged."""


@dataclass(frozen=True)
class PartInfo:
    """A complete part file, as found on disk."""

    sequence: int
    kind: str
    name: str
    path: Path


def safe_name(name: str) -> str:
    """``name`` with every run of characters outside ``[A-Za-z0-9_.+]`` replaced by ``_``."""
    cleaned = _SAFE_RE.sub("_", name).strip("._") or "unnamed"
    return cleaned[:80]


def part_filename(sequence: int, kind: str, name: str) -> str:
    """The final file name of a part: ``NNNNNN-<kind>-<name>.h5``."""
    if not 0 <= sequence <= 999_999:
        raise StoreError(f"part number {sequence} outside 0-999999")
    return f"{sequence:06d}-{kind}-{safe_name(name)}.h5"


def to_json(value: Any) -> str:
    """JSON text of ``value``; numpy values become lists/scalars, anything else ``str``."""
    return json.dumps(value, default=lambda v: getattr(v, "tolist", lambda: str(v))())


def as_str(value: Any) -> str:
    """An HDF5 string attribute or dataset value as ``str``."""
    if isinstance(value, np.ndarray) and value.shape == ():
        value = value[()]
    return value.decode() if isinstance(value, bytes) else str(value)


def dataset(group: Any, name: str, value: Any, units: str, **attrs: Any) -> Any:
    """Create ``group[name]`` from ``value`` with a ``units`` attribute (and ``attrs``)."""
    if isinstance(value, str):
        ds = group.create_dataset(name, data=value, dtype=h5py.string_dtype())
    else:
        ds = group.create_dataset(name, data=np.asarray(value))
    ds.attrs["units"] = units
    ds.attrs.update(attrs)
    return ds


def share_with_group(fd: int, directory: Path) -> None:
    """Make an open file ``0640`` and give it ``directory``'s group, where allowed.

    Run files are for the whole observing group to read; only the writer may change
    them. A process that is not in the directory's group keeps its own group (the run
    directory's creation says so once, :func:`make_shared_directory`).
    """
    os.fchmod(fd, FILE_MODE)
    group = os.stat(directory).st_gid
    if group == os.fstat(fd).st_gid:
        return
    with contextlib.suppress(PermissionError):
        os.fchown(fd, -1, group)


def make_shared_directory(directory: Path) -> None:
    """Create ``directory`` (and parents) ``0750``, in its parent's group where allowed."""
    directory.mkdir(parents=True, exist_ok=True)
    os.chmod(directory, DIRECTORY_MODE)
    group = os.stat(directory.parent).st_gid
    if os.stat(directory).st_gid != group:
        try:
            os.chown(directory, -1, group)
        except PermissionError:
            log.warning("%s: cannot take its parent's group %d", directory, group)


def fsync_directory(directory: Path) -> None:
    """Make the directory entries (new names, removals) of ``directory`` durable."""
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_h5(
    target: Path, attrs: Mapping[str, Any], what: str = "the file", reserve_bytes: int = 0
) -> Iterator[Any]:
    """Yield a new HDF5 file that appears as ``target`` only once completely written.

    The file is built in memory and written by :func:`reach_receiver.disk.write_durably`: HDF5 never
    writes to the disk itself, so a full disk is a :class:`reach_receiver.disk.DiskFull` naming the
    room there is and the room ``what`` needs (beyond ``reserve_bytes`` kept free), and
    the library is left as sound as before. The temporary sits beside ``target`` (same
    file system, so the rename is atomic), starts with a dot and ends in ``.tmp`` so
    that listings skip it.
    """
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        f.attrs.update(dict(attrs))
        yield f
    write_durably(
        target, buffer.getbuffer(), what, reserve_bytes=reserve_bytes,
        prepare=lambda fd: share_with_group(fd, target.parent),
    )


def write_part(
    directory: Path,
    sequence: int,
    kind: str,
    name: str,
    timestamp: float,
    fill: Callable[[Any], None],
) -> Path:
    """Write one part durably: ``fill`` receives the open file; returns the final path.

    A measurement is refused (:class:`reach_receiver.disk.DiskFull`) unless :data:`RESERVE_BYTES`
    stay free after it, so that the records that close a run (:data:`CLOSING_KINDS`)
    still fit when the disk fills during the run.
    """
    target = directory / PARTS_DIR / part_filename(sequence, kind, name)
    if target.exists():
        raise StoreError(f"{target}: part already exists (two writers on one run?)")
    attrs = {
        "format": PART_FORMAT,
        "format_version": FORMAT_VERSION,
        "kind": kind,
        "name": name,
        "sequence": sequence,
        "timestamp": float(timestamp),
    }
    reserve = 0 if kind in CLOSING_KINDS else RESERVE_BYTES
    with atomic_h5(target, attrs, f"a measurement ({kind} {name})", reserve) as f:
        fill(f)
    return target


def list_parts(directory: Path) -> list[PartInfo]:
    """The complete parts of a run directory, by increasing number (temporaries ignored)."""
    parts_dir = directory / PARTS_DIR
    if not parts_dir.is_dir():
        return []
    found = []
    for path in parts_dir.iterdir():
        match = _PART_RE.match(path.name)
        if match and path.is_file():
            found.append(PartInfo(int(match[1]), match[2], match[3], path))
    return sorted(found, key=lambda p: p.sequence)


def clean_temporaries(directory: Path) -> int:
    """Remove leftover temporaries of killed writers in ``directory`` and its parts; count."""
    removed = 0
    for folder in (directory, directory / PARTS_DIR):
        if not folder.is_dir():
            continue
        for path in folder.iterdir():
            if path.name.startswith(".") and path.name.endswith(".tmp"):
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()
                    removed += 1
    return removed
