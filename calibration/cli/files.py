"""What ``reach-cal`` will not write over: its own inputs, and files holding measurements.

Every command that writes a file checks its outputs before any work (:func:`check_outputs`):

* an output may not be one of the command's inputs, however it is spelt (``./run.h5``,
  a symbolic or hard link): ``reach-cal solve RUN -o RUN`` would replace the
  measurements by their solution;
* an existing output must be something the command may replace: for an HDF5 output, an
  empty file or a file of the same kind (a solution replaces a solution), never a file
  holding measurements, unless the command itself makes them again from what it reads:
  ``simulate`` replaces a simulated run (``simulation_truth``, remade from its seed),
  ``import edges DIR`` a run imported from ``DIR``; a text output (CSV, JSON) never
  replaces an HDF5 file; a directory output must not be an existing file;
* two outputs of one command may not be the same file.

A refusal is an :class:`~calibration.core.errors.InvalidDataError` naming the option, the
path and why; nothing has been written.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Literal

import h5py

from ..core.errors import InvalidDataError
from ..io.hdf5_io import RUN_FORMATS

__all__ = ["OutputKind", "check_outputs", "same_file"]

#: What an output is: an HDF5 file of a ``format``, text, or a directory of files.
OutputKind = Literal["run", "solution", "calibrated", "text", "directory"]
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: ``format`` attribute of each HDF5 kind (:mod:`calibration.io.hdf5_io`).
FORMATS = {
    "run": "reach-calibration-run",
    "solution": "reach-calibration-solution",
    "calibrated": "reach-calibrated-spectrum",
}
#: The receiver's parts of a run in progress (``reach_receiver.store.parts``): measurements.
PART_FORMAT = "reach-receiver-part"


def same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    """Whether two paths name one file: the same inode, or the same resolved path."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return Path(a).resolve() == Path(b).resolve()


def check_outputs(
    outputs: Mapping[str, tuple[str | None, OutputKind]],
    inputs: Sequence[str | os.PathLike[str] | None],
    remakes: str | None = None,
) -> None:
    """Refuse outputs that would overwrite an input or measurements (module doc).

    ``outputs`` maps each option (``-o``, ``--csv``) to its path (``None``: not given)
    and the kind written there; ``inputs`` are the files and directories the command
    reads. ``remakes`` is the run this command makes again: ``"simulation"``, or the
    directory it imports.
    """
    given = [(opt, path, kind) for opt, (path, kind) in outputs.items() if path is not None]
    for i, (opt, path, kind) in enumerate(given):
        for read in (p for p in inputs if p is not None):
            if same_file(path, read):
                raise InvalidDataError(
                    f"{opt} {path} is an input of this command ({read}): it would be "
                    "overwritten; nothing written, choose another output"
                )
        for other_opt, other, _ in given[i + 1:]:
            if same_file(path, other):
                raise InvalidDataError(f"{opt} and {other_opt} name the same file {path}")
        _check_existing(opt, Path(path), kind, remakes)


def _check_existing(opt: str, path: Path, kind: OutputKind, remakes: str | None) -> None:
    """Refuse to replace ``path`` when it exists and is not something ``kind`` may replace."""
    try:
        info = path.stat()
    except FileNotFoundError:
        return
    except OSError as err:
        raise InvalidDataError(f"{opt} {path}: {err.strerror or err}") from err
    if kind == "directory":
        if not stat.S_ISDIR(info.st_mode):
            raise InvalidDataError(f"{opt} {path} exists and is not a directory")
        return
    if stat.S_ISDIR(info.st_mode):
        raise InvalidDataError(f"{opt} {path} is a directory, not a file")
    if not stat.S_ISREG(info.st_mode):
        raise InvalidDataError(f"{opt} {path} exists and is not a regular file")
    if info.st_size == 0:
        return
    found = _hdf5_format(path)
    if found is None:
        if kind == "text":
            return
        raise InvalidDataError(
            f"{opt} {path} exists and is not an HDF5 file: it would be replaced; "
            "remove it first or choose another output"
        )
    measured, origin = _holds_measurements(path, found)
    remade = origin is not None and remakes is not None and (
        origin == remakes or (origin != "simulation" and same_file(origin, remakes))
    )
    if measured and not (kind == "run" and remade):
        raise InvalidDataError(
            f"{opt} {path} holds measurements (a {found or 'run'} file): reach-cal never "
            "writes over a run; choose another output"
        )
    if kind == "text":
        raise InvalidDataError(f"{opt} {path} is an HDF5 file: a text output will not replace it")
    if found != FORMATS[kind] and not measured:
        raise InvalidDataError(
            f"{opt} {path} is a {found or 'HDF5'} file, not a {FORMATS[kind]} file: it would "
            "be replaced; remove it first or choose another output"
        )


def _hdf5_format(path: Path) -> str | None:
    """The ``format`` of an HDF5 file (``""`` when it has none), ``None`` if not HDF5."""
    with open(path, "rb") as handle:
        if handle.read(len(HDF5_SIGNATURE)) != HDF5_SIGNATURE:
            return None
    try:
        with h5py.File(path, "r") as f:
            value = f.attrs.get("format", "")
            return value.decode() if isinstance(value, bytes) else str(value)
    except OSError:
        return ""  # an HDF5 signature but unreadable: treat as data, never replace


def _holds_measurements(path: Path, found: str) -> tuple[bool, str | None]:
    """Whether an HDF5 file holds measurements, and where they came from when remade.

    The origin is ``"simulation"`` for a simulated run, the directory of an imported one,
    ``None`` for measurements nothing can make again (a receiver's run, its parts).
    """
    if found not in (*RUN_FORMATS, PART_FORMAT, ""):  # "": no format (REACH's own layout)
        return False, None
    if found != FORMATS["run"]:
        return True, None
    try:
        with h5py.File(path, "r") as f:
            if "simulation_truth" in f:
                return True, "simulation"
            imported = f.attrs.get("imported_from")
    except OSError:
        return True, None
    if imported is None:
        return True, None
    return True, imported.decode() if isinstance(imported, bytes) else str(imported)
