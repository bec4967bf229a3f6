"""The archive on Dask: a season (read, bin, add) as a graph over run files and chunks.

Each run is counted (its calibrated spectra and channels: attributes only), then read
and binned in chunks of rows sized to the workers' memory
(:func:`calibration.season.chunks.rows_per_chunk`), each chunk one task
(:func:`calibration.season.chunks.bin_rows`); the chunks' sums are added in a binary tree
fixed by the order of the runs and chunks (pairs ``(0, 1), (2, 3), ...``, then pairs of
those), never by which task finished first, so the season is the same bit for bit on any
number of workers. It differs from :func:`calibration.season.binning.combine` over the
runs in one loop only by the order of the floating-point additions (relative 1e-15 per
addition; tested to 1e-12).

The tasks run on :mod:`distributed`: a local cluster by default (:func:`archive_client`;
one worker runs as a thread of this process, more as worker processes, one thread each),
or an existing cluster given by its scheduler's address. Each worker's memory is limited
(the cluster's ``memory_limit``: a worker beyond it is paused, then restarted by its
nanny); chunks use a quarter of it. Adds have priority over reading new chunks, so a
worker holds few unreduced sums. An error a user can act on (a missing or unreadable
run, a run with no calibrated spectra, runs on different grids) is returned by the task
as a :class:`Failure` (no worker traceback in the log) and raised here with its message.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, TextIO

from ..core.errors import CalibrationError, InvalidDataError
from .binning import BinnedRun, FloatArray, Season, add, combine
from .chunks import bin_rows, count_rows, rows_per_chunk

__all__ = [
    "CONNECT_TIMEOUT_S",
    "Cluster",
    "Failure",
    "Progress",
    "archive_client",
    "default_memory",
    "guarded",
    "out_of_memory",
    "season_on_dask",
]

#: Seconds to wait for a ``--scheduler`` to answer before giving up.
CONNECT_TIMEOUT_S = 3.0
#: The share of a worker's memory a chunk of rows may use.
CHUNK_SHARE = 0.25


@dataclass(frozen=True)
class Failure:
    """An error a user can act on, returned by a task instead of raised."""

    message: str


def guarded(function: Callable[..., Any], *args: Any) -> Any:
    """``function(*args)``, or a :class:`Failure` holding the message of a user's error."""
    try:
        return function(*args)
    except (CalibrationError, OSError) as err:
        return Failure(str(err))


def _add(a: BinnedRun | Failure, b: BinnedRun | Failure) -> BinnedRun | Failure:
    if isinstance(a, Failure):
        return a
    if isinstance(b, Failure):
        return b
    return guarded(add, a, b)


def default_memory(workers: int) -> int:
    """Bytes per worker when none is given: 80 % of this machine's memory shared out."""
    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    return int(0.8 * total / max(workers, 1))


def _gib(n: float) -> str:
    return f"{n / 2**30:.1f} GiB"


@dataclass
class Cluster:
    """A connected client, what it is (a line to print) and each worker's memory bound."""

    client: Any
    description: str
    workers: int
    memory_per_worker: int


@contextlib.contextmanager
def archive_client(
    scheduler: str | None, workers: int, memory_per_worker: int | None
) -> Iterator[Cluster]:
    """A client of ``scheduler``, or of a local cluster of ``workers`` (module doc)."""
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError) as err:
            raise InvalidDataError(
                f"--scheduler {scheduler}: no Dask scheduler answered within "
                f"{CONNECT_TIMEOUT_S:g} s ({err}); start one (dask scheduler) or leave out "
                "--scheduler to use a local cluster"
            ) from None
        with client:
            info = client.scheduler_info(n_workers=-1)["workers"]
            limits = [int(w.get("memory_limit") or 0) for w in info.values()]
            bound = min([m for m in limits if m] or [memory_per_worker or default_memory(1)])
            if memory_per_worker:
                bound = min(bound, memory_per_worker)
            yield Cluster(
                client, f"dask: scheduler {scheduler}, {len(info)} workers, "
                f"{_gib(bound)} memory per worker used", max(len(info), 1), bound,
            )
        return
    memory = memory_per_worker or default_memory(workers)
    processes = workers > 1
    try:
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=processes,
            # a thread worker's limit would be this whole process's memory: chunks only
            memory_limit=memory if processes else 0, dashboard_address=":0",
            silence_logs=logging.ERROR,
        )
    except (RuntimeError, OSError) as err:
        raise InvalidDataError(
            f"a local Dask cluster of {workers} workers did not start ({err}); run with "
            "--workers 1 (in this process) or --scheduler ADDRESS"
        ) from None
    with cluster, Client(cluster) as client:
        kind = (f"{workers} worker processes, {_gib(memory)} memory limit each" if processes
                else f"1 worker (a thread here), chunks sized to {_gib(memory)}")
        yield Cluster(client, f"dask: local cluster, {kind}", workers, memory)


def out_of_memory(err: BaseException, memory: int) -> InvalidDataError:
    """The message of a task whose worker was killed (its memory limit, as a rule)."""
    return InvalidDataError(
        f"a Dask worker died running a task ({type(err).__name__}), most likely over its "
        f"memory limit of {_gib(memory)}: give --memory-per-worker more, or fewer --workers"
    )


class Progress:
    """A line per tenth of the tasks (or each task, for fewer than ten): no carriage returns."""

    def __init__(self, label: str, total: int, unit: str, stream: TextIO | None = None):
        self.label, self.total, self.unit = label, total, unit
        self.stream = stream or sys.stdout
        self.done = self.items = 0
        self.start = time.monotonic()
        self.next_tenth = 1

    def step(self, items: int) -> None:
        """One more task done, holding ``items`` of the unit."""
        self.done += 1
        self.items += items
        if self.done * 10 >= self.next_tenth * self.total or self.done == self.total:
            while self.next_tenth * self.total <= self.done * 10:
                self.next_tenth += 1
            elapsed = max(time.monotonic() - self.start, 1e-9)
            print(
                f"{self.label}: {self.done}/{self.total} ({100 * self.done // self.total} %), "
                f"{self.items} {self.unit}, {self.items / elapsed:.0f} {self.unit}/s",
                file=self.stream, flush=True,
            )


def raise_failure(value: Any) -> Any:
    """``value``, or the error a :class:`Failure` holds, raised."""
    if isinstance(value, Failure):
        raise InvalidDataError(value.message)
    return value


def _chunks(
    client: Any, runs: Sequence[str], memory_per_worker: int
) -> list[tuple[str, int, int, int]]:
    """(run, first row, end row, rows) of every chunk, runs counted on the cluster."""
    counted = client.gather(client.map(guarded, [count_rows] * len(runs), runs, pure=False))
    out = []
    for run, count in zip(runs, counted, strict=True):
        n_rows, n_channels = raise_failure(count)
        size = rows_per_chunk(n_channels, CHUNK_SHARE * memory_per_worker)
        out += [(run, a, min(a + size, n_rows), min(size, n_rows - a))
                for a in range(0, n_rows, size)]
    return out


def season_on_dask(
    cluster: Cluster, runs: Sequence[str], edges_h: FloatArray, stream: TextIO | None = None
) -> Season:
    """The season of ``runs`` computed on ``cluster`` (module doc)."""
    from distributed import KilledWorker, as_completed

    client = cluster.client
    chunks = _chunks(client, runs, cluster.memory_per_worker)
    print(cluster.description, file=stream or sys.stdout)
    print(
        f"season: {len(runs)} runs in {len(chunks)} chunks of at most "
        f"{max(c[3] for c in chunks)} spectra", file=stream or sys.stdout, flush=True,
    )
    level = [
        client.submit(guarded, bin_rows, run, a, b, edges_h, pure=False, priority=0)
        for run, a, b, _ in chunks
    ]
    leaves = dict(zip(level, (c[3] for c in chunks), strict=True))
    depth = 0
    while len(level) > 1:
        depth += 1
        pairs = [level[i:i + 2] for i in range(0, len(level), 2)]
        level = [
            client.submit(_add, *pair, pure=False, priority=depth) if len(pair) == 2 else pair[0]
            for pair in pairs
        ]
    root = level[0]
    del level
    progress = Progress("season", len(chunks), "spectra", stream)
    try:
        # a chunk's sums stay on the workers (a Failure reaches the root through the adds)
        for future in as_completed(list(leaves)):
            progress.step(leaves.pop(future))
        total = raise_failure(root.result())
    except KilledWorker as err:
        raise out_of_memory(err, cluster.memory_per_worker) from None
    finally:
        root.cancel()
    return combine([total])
