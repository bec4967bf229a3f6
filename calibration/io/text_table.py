"""Numeric text tables as laboratory software writes them, with errors at ``file:line``.

A table is whitespace- or comma-separated numbers, one row a line. Blank lines, and
everything from a comment marker to the end of a line, are skipped; marker lines such
as ``BEGIN`` / ``END`` (the EDGES VNA exports) may be skipped by name. Only the first
``n_columns`` numbers of a row are read, so trailing fields (a header's extra counts, a
weight) do not matter. Every number is parsed by :class:`float` (correctly rounded, as
``numpy.loadtxt`` does), so the values are the same as numpy's, bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..core.errors import FileFormatError

__all__ = ["read_columns", "read_rows"]

FloatArray = NDArray[np.float64]


def read_columns(
    path: str | Path,
    n_columns: int,
    *,
    comments: Sequence[str] = ("#",),
    markers: Sequence[str] = (),
) -> FloatArray:
    """The first ``n_columns`` numbers of every data row: :func:`read_rows` without lines."""
    return read_rows(path, n_columns, comments=comments, markers=markers)[0]


def read_rows(
    path: str | Path,
    n_columns: int,
    *,
    comments: Sequence[str] = ("#",),
    markers: Sequence[str] = (),
) -> tuple[FloatArray, NDArray[np.int_]]:
    """The first ``n_columns`` numbers of every data row, and each row's line number.

    The table has shape ``(n_rows, n_columns)``; the line numbers (from 1) let a caller
    name ``file:line`` when a value is out of range.

    Raises
    ------
    FileFormatError
        ``file:line: message`` for a row with too few fields or a field that is not a
        number; ``file: message`` for a file without data rows. (An unreadable file
        raises :class:`OSError`.)
    """
    rows: list[list[float]] = []
    lines: list[int] = []
    text = Path(path).read_text(errors="replace")
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw
        for marker in comments:
            line = line.split(marker, 1)[0]
        line = line.strip()
        if not line or line in markers:
            continue
        fields = line.replace(",", " ").split()
        if len(fields) < n_columns:
            raise FileFormatError(
                f"{path}:{number}: expected at least {n_columns} numbers, found {len(fields)}"
            )
        try:
            rows.append([float(v) for v in fields[:n_columns]])
            lines.append(number)
        except ValueError:
            bad = next(v for v in fields[:n_columns] if not _is_number(v))
            raise FileFormatError(f"{path}:{number}: {bad!r} is not a number") from None
    if not rows:
        raise FileFormatError(f"{path}: no data rows")
    return np.asarray(rows, dtype=float), np.asarray(lines, dtype=int)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
