"""The metrics database: one SQLite file in WAL mode, minute data and 15-minute means.

Layout (``WITHOUT ROWID`` tables keyed by series and time, so one series over a time
range is one range scan)::

    series  (id, key, metric, unit)              one row per series key
    minute  (series, t, milli, status)           every reading: t in milliseconds,
                                                 the value in thousandths (NULL for NaN),
                                                 the status's index in readings.STATUSES
    quarter (series, t, mean_milli, min_milli, max_milli, n, status)
                                                 15-minute buckets of the minute data
                                                 (t in whole seconds, the bucket's start):
                                                 mean, extremes, count, worst status
    meta    (key, value)                         the down-sampling watermark

Values are stored as integers of thousandths: exact to 1e-3 of their unit (1 mK,
1 byte in 1000), and SQLite stores small integers in one to three bytes, which keeps a
month of minute data of the simulated receiver's ~60 series near 40 MB. Times of the
minute data are kept to the millisecond, not the second: two readings of one series
taken within a second of each other (a late sample beside the next punctual one, a
run's last safe point beside the first idle sample) are two rows, and neither replaces
the other. Files written with whole-second times (``user_version`` 0) are converted
when opened.

Durability: WAL with ``synchronous=FULL``; every batch of readings is one transaction,
so a ``kill -9`` or a power cut loses at most the batch being written, and the file is
never left half-written. On a full disk (SQLite's "database or disk is full", an I/O
error) a batch is dropped rather than raised into the sampler or a run: the file keeps
what it had, the failure is logged once and named in :attr:`MetricsDatabase.write_error`,
and writing resumes by itself once there is room. Readings also give way to the runs'
measurements: below :data:`KEEP_FREE_BYTES` free a batch is dropped before SQLite
is asked, so that the room a run keeps for the records that close it stays free.

:meth:`MetricsDatabase.maintain` down-samples the complete 15-minute buckets and
applies the retention (minute data ``minute_days``, 15-minute data ``quarter_days``).
"""

from __future__ import annotations

import logging
import math
import sqlite3
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from reach_receiver.disk import MARGIN_BYTES, RESERVE_BYTES, DiskFull, free_bytes

from .readings import STATUSES, Reading, parse_key

log = logging.getLogger(__name__)

#: Width of a down-sampled bucket (s).
QUARTER_S = 900
DAY_S = 86400.0

_SCHEMA = """
CREATE TABLE IF NOT EXISTS series (
    id INTEGER PRIMARY KEY, key TEXT UNIQUE NOT NULL, metric TEXT NOT NULL, unit TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS minute (
    series INTEGER NOT NULL, t INTEGER NOT NULL, milli INTEGER, status INTEGER NOT NULL,
    PRIMARY KEY (series, t)) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS quarter (
    series INTEGER NOT NULL, t INTEGER NOT NULL, mean_milli INTEGER, min_milli INTEGER,
    max_milli INTEGER, n INTEGER NOT NULL, status INTEGER NOT NULL,
    PRIMARY KEY (series, t)) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value REAL);
"""
#: ``PRAGMA user_version`` of the layout above (0: minute times in whole seconds).
SCHEMA_VERSION = 1
MS = 1000
#: Free space under which readings are dropped: the runs' reserve, and as much again.
KEEP_FREE_BYTES = 2 * (RESERVE_BYTES + MARGIN_BYTES)
#: SQLite's primary result codes of a write the disk had no room for.
_SQLITE_FULL, _SQLITE_IOERR = 13, 10


def disk_trouble(err: sqlite3.Error) -> bool:
    """Whether ``err`` is SQLite's "database or disk is full" or an I/O error."""
    code = getattr(err, "sqlite_errorcode", None)
    if code is not None:
        return (code & 0xFF) in (_SQLITE_FULL, _SQLITE_IOERR)
    text = str(err).lower()
    return "disk is full" in text or "disk i/o error" in text


@dataclass(frozen=True)
class Point:
    """One stored value of a series: time, value (NaN when unusable), status, resolution."""

    t: float
    value: float
    status: str
    resolution_s: int


def _milli(value: float) -> int | None:
    return None if not math.isfinite(value) else round(value * 1000.0)


class MetricsDatabase:
    """The metrics file (module docstring); safe to use from several threads."""

    def __init__(
        self, path: Path, *, minute_days: float = 30.0, quarter_days: float = 730.0
    ) -> None:
        self.path = Path(path)
        self.minute_days = minute_days
        self.quarter_days = quarter_days
        #: Why the last batch was dropped (``None``: the file takes what it is given).
        self.write_error: str | None = None
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
        self._lock = threading.Lock()
        with self._lock:
            try:
                self._db.execute("PRAGMA journal_mode=WAL")
                self._db.execute("PRAGMA synchronous=FULL")
                self._db.executescript(_SCHEMA)
                self._upgrade()
            except sqlite3.Error as err:
                self._db.close()
                if disk_trouble(err):
                    raise DiskFull(f"{self.path}: cannot be opened ({err}: no room left?)",
                                   self.path.parent, None, 0) from err
                raise
        self._ids: dict[str, int] = dict(self._db.execute("SELECT key, id FROM series"))

    def _upgrade(self) -> None:
        version = int(self._db.execute("PRAGMA user_version").fetchone()[0])
        if version == SCHEMA_VERSION:
            return
        if version != 0:
            raise ValueError(f"{self.path}: metrics layout {version}, this version knows "
                             f"{SCHEMA_VERSION}")
        self._db.execute("BEGIN IMMEDIATE")
        self._db.execute(f"UPDATE minute SET t = t * {MS}")
        self._db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
        self._db.execute("COMMIT")

    def close(self) -> None:
        """Checkpoint and close the file (on a full disk the log stays beside it)."""
        with self._lock:
            try:
                self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            except sqlite3.Error as err:  # the WAL is read back at the next open
                log.warning("%s: not checkpointed at close (%s)", self.path, err)
            self._db.close()

    def _rollback(self) -> None:
        if self._db.in_transaction:  # SQLite may have rolled back on its own already
            self._db.execute("ROLLBACK")
        self._ids = dict(self._db.execute("SELECT key, id FROM series"))

    def _dropped(self, what: str, err: sqlite3.Error | str) -> None:
        error = f"{self.path}: {what} not stored ({err})"
        if self.write_error is None:
            log.error("%s; stored again once there is room", error)
        self.write_error = error

    def _stored(self) -> None:
        if self.write_error is not None:
            log.warning("%s: readings stored again", self.path)
            self.write_error = None

    def _series_id(self, reading: Reading) -> int:
        key = reading.key
        found = self._ids.get(key)
        if found is None:
            cursor = self._db.execute(
                "INSERT INTO series (key, metric, unit) VALUES (?, ?, ?)",
                (key, reading.metric, reading.unit),
            )
            found = self._ids[key] = int(cursor.lastrowid or 0)
        return found

    def write(self, readings: Iterable[Reading]) -> int:
        """Store a batch of readings in one transaction; returns how many.

        0 when the disk has no room: the batch is dropped (:attr:`write_error`).
        """
        with self._lock:
            free = free_bytes(self.path.parent)
            if free < KEEP_FREE_BYTES:
                self._dropped("readings", f"no space left on device: {free // 1024} kB free, "
                                          f"kept for the runs' measurements")
                return 0
            try:
                self._db.execute("BEGIN IMMEDIATE")
                rows = [
                    (self._series_id(r), round(r.timestamp * MS), _milli(r.value),
                     STATUSES.index(r.status))
                    for r in readings
                ]
                self._db.executemany("INSERT OR REPLACE INTO minute VALUES (?, ?, ?, ?)", rows)
                self._db.execute("COMMIT")
            except sqlite3.Error as err:
                self._rollback()
                if not disk_trouble(err):
                    raise
                self._dropped("readings", err)
                return 0
            except BaseException:
                self._rollback()
                raise
            self._stored()
        return len(rows)

    # ----------------------------------------------------------------- maintenance
    def maintain(self, now: float) -> int:
        """Down-sample every complete 15-minute bucket not yet done; apply the retention.

        Returns the number of buckets written. Idempotent: a bucket is recomputed from
        the minute data if asked again (``INSERT OR REPLACE``).
        """
        end = int(now) - int(now) % QUARTER_S
        with self._lock:
            row = self._db.execute("SELECT value FROM meta WHERE key='quarter_done'").fetchone()
            start = int(row[0]) if row else self._first_minute()
            if start is None or start >= end:
                return 0
            start -= start % QUARTER_S
            try:
                return self._maintain(start, end, now)
            except sqlite3.Error as err:
                self._rollback()
                if not disk_trouble(err):
                    raise
                self._dropped("15-minute means", err)
                return 0

    def _maintain(self, start: int, end: int, now: float) -> int:
        """:meth:`maintain`'s one transaction (the lock held)."""
        self._db.execute("BEGIN IMMEDIATE")
        written = 0
        for series_id in self._ids.values():
            cursor = self._db.execute(
                "INSERT OR REPLACE INTO quarter "
                "SELECT series, t / ? - t / ? % ?, round(avg(milli)), min(milli), "
                "max(milli), count(milli), max(status) FROM minute "
                "WHERE series = ? AND t >= ? AND t < ? GROUP BY t / ? - t / ? % ?",
                (MS, MS, QUARTER_S, series_id, start * MS, end * MS, MS, MS, QUARTER_S),
            )
            written += max(cursor.rowcount, 0)
        minute_cut = int(now - self.minute_days * DAY_S)
        quarter_cut = int(now - self.quarter_days * DAY_S)
        for series_id in self._ids.values():
            self._db.execute(
                "DELETE FROM minute WHERE series = ? AND t < ?",
                (series_id, minute_cut * MS),
            )
            self._db.execute(
                "DELETE FROM quarter WHERE series = ? AND t < ?", (series_id, quarter_cut)
            )
        self._db.execute(
            "INSERT OR REPLACE INTO meta VALUES ('quarter_done', ?)", (float(end),)
        )
        self._db.execute("COMMIT")
        return written

    def _first_minute(self) -> int | None:
        row = self._db.execute("SELECT min(t) FROM minute").fetchone()
        return None if row is None or row[0] is None else int(row[0]) // MS

    # ----------------------------------------------------------------- queries
    def keys(self, name: str | None = None) -> list[str]:
        """Series keys: all, those of metric ``name``, or ``name`` itself if it is a key."""
        with self._lock:
            known = sorted(self._ids)
        if name is None:
            return known
        if name in known:
            return [name]
        metric, labels = parse_key(name)
        return [
            k for k in known
            if parse_key(k)[0] == metric and labels.items() <= parse_key(k)[1].items()
        ]

    def unit(self, key: str) -> str:
        """The unit of a series."""
        with self._lock:
            row = self._db.execute("SELECT unit FROM series WHERE key = ?", (key,)).fetchone()
        return str(row[0]) if row else ""

    def series(self, key: str, since: float, until: float = math.inf) -> list[Point]:
        """A series from ``since`` to ``until``: minute data where it is kept, else means.

        Before the oldest minute row of the series (retention), the 15-minute means
        stand in, so ``--since 1y`` works after the minute data of the year is gone.
        """
        with self._lock:
            series_id = self._ids.get(key)
            if series_id is None:
                return []
            high = 2**40 if math.isinf(until) else int(until)  # 2**40 s: beyond any run
            first = self._db.execute(
                "SELECT min(t) FROM minute WHERE series = ?", (series_id,)
            ).fetchone()[0]
            points: list[Point] = []
            cut = high if first is None else min(int(first) // MS, high)
            if since < cut:
                rows = self._db.execute(
                    "SELECT t, mean_milli, status FROM quarter WHERE series = ? AND t >= ? "
                    "AND t <= ? ORDER BY t",
                    (series_id, int(since) - QUARTER_S + 1, cut - QUARTER_S),
                ).fetchall()
                points += [_point(t, m, s, QUARTER_S) for t, m, s in rows]
            rows = self._db.execute(
                "SELECT t, milli, status FROM minute WHERE series = ? AND t >= ? AND t <= ? "
                "ORDER BY t",
                # Rounded as the stored times are: a reading at ``since`` is in.
                (series_id, max(round(since * MS), (cut if points else 0) * MS),
                 high * MS if math.isinf(until) else round(until * MS)),
            ).fetchall()
        return points + [_point(t / MS, m, s, 60) for t, m, s in rows]

    def quarter_means(self, key: str) -> list[tuple[int, float, int]]:
        """Every 15-minute bucket of a series: (start, mean, count)."""
        with self._lock:
            rows = self._db.execute(
                "SELECT t, mean_milli, n FROM quarter WHERE series = ? ORDER BY t",
                (self._ids.get(key, -1),),
            ).fetchall()
        return [(int(t), math.nan if m is None else m / 1000.0, int(n)) for t, m, n in rows]

    def count(self, table: str = "minute") -> int:
        """Rows of ``minute`` or ``quarter``."""
        if table not in ("minute", "quarter"):
            raise ValueError(table)
        with self._lock:
            return int(self._db.execute(f"SELECT count(*) FROM {table}").fetchone()[0])


def _point(t: float, milli: int | None, status: int, resolution: int) -> Point:
    value = math.nan if milli is None else milli / 1000.0
    return Point(float(t), value, STATUSES[int(status)], resolution)


def write_csv(points: Sequence[Point], key: str, unit: str) -> str:
    """A series as CSV: ``time_utc,unix_s,<key> (<unit>),status``."""
    lines = [f"time_utc,unix_s,{key} ({unit}),status"]
    for p in points:
        stamp = datetime.fromtimestamp(p.t, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        value = "" if math.isnan(p.value) else f"{p.value:g}"
        lines.append(f"{stamp},{p.t:.0f},{value},{p.status}")
    return "\n".join(lines) + "\n"
