"""The writer of a run: one durable part file per measurement, merged at the end.

:class:`RunStore` is what the scheduler's runner holds. Each ``add_*`` writes one part
(:mod:`reach_receiver.store.parts`) and returns only once it is on disk, so a run
killed at any moment (SIGKILL, power cut) loses at most the measurement in progress;
:func:`~reach_receiver.store.merge.merge_run` turns the parts into ``run.h5`` at
:meth:`RunStore.finish`, or afterwards to recover a killed run. What each kind of
measurement holds, and its ``add_*`` writer, is :mod:`reach_receiver.store.measurements`.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.metadata
import logging
import platform
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from calibration.io.hdf5_io import RunLayout
from calibration.model.data import CalibrationData, SourceData

from .handover import RECEIVER, HandOver, engine_layout, select
from .measurements import MeasurementWriters
from .merge import RUN_FILE, Record, merge_run
from .parts import (
    PARTS_DIR,
    StoreError,
    clean_temporaries,
    dataset,
    fsync_directory,
    list_parts,
    make_shared_directory,
    to_json,
    write_part,
)

log = logging.getLogger(__name__)

STATUSES = ("completed", "interrupted", "failed")


@dataclass(frozen=True)
class EngineView:
    """The run so far as the engine sees it, and what the hand-over chose.

    ``layout`` is ``None`` when there is nothing to show the engine (no LNA S11, or no
    spectra whose S11 covers the band); ``handover.warnings`` then says why.
    """

    layout: RunLayout | None
    handover: HandOver

    @functools.cached_property
    def data(self) -> CalibrationData | None:
        """The calibrators as the engine's run, ``None`` without any."""
        if self.layout is None or not self.layout.calibrators:
            return None
        return self.layout.split()[0]

    @functools.cached_property
    def others(self) -> dict[str, SourceData]:
        """The sources that are not calibrators (the antenna), by name."""
        return {} if self.layout is None else self.layout.others()


def software_versions() -> dict[str, str]:
    """Versions of reach-receiver, numpy, h5py and Python, as stored in every run."""
    try:
        ours = importlib.metadata.version("reach-receiver")
    except importlib.metadata.PackageNotFoundError:
        ours = "not installed"
    return {
        "reach-receiver": ours,
        "numpy": np.__version__,
        "h5py": h5py.__version__,
        "python": platform.python_version(),
    }


class RunStore(MeasurementWriters):
    """Writes one run as durable part files in ``directory`` and merges them on finish.

    Parameters
    ----------
    directory
        The run's directory (created by :meth:`open`; must not hold another run).
    name
        Name of the run (e.g. the schedule's name and the start time).
    schedule_files
        ``(path, text)`` of the schedule and every file it includes.
    site_yaml
        The site configuration, verbatim.
    metadata
        Anything else worth keeping (JSON-serialisable); also the engine's run metadata.
    channel_width_hz
        Spectrometer channel width; channel ``k`` is centred on ``k * channel_width_hz``.
    band_hz
        Band of the engine layout: the channels whose centres lie in it.

    Notes
    -----
    Thread-safe: parts are numbered in the order their writes complete.
    """

    def __init__(
        self,
        directory: Path,
        *,
        name: str,
        schedule_files: Sequence[tuple[str, str]],
        site_yaml: str,
        metadata: Mapping[str, Any],
        channel_width_hz: float,
        band_hz: tuple[float, float] = (50e6, 130e6),
    ) -> None:
        if not (np.isfinite(channel_width_hz) and channel_width_hz > 0):
            raise ValueError(f"channel_width_hz must be > 0, got {channel_width_hz}")
        if not 0 <= band_hz[0] < band_hz[1]:
            raise ValueError(f"band_hz must be (low, high) with 0 <= low < high, got {band_hz}")
        self.directory = Path(directory)
        self.name = name
        self._schedule_files = [(str(p), str(t)) for p, t in schedule_files]
        self._site_yaml = site_yaml
        self._metadata = dict(metadata)
        self._channel_width_hz = float(channel_width_hz)
        self._band_hz = (float(band_hz[0]), float(band_hz[1]))
        self._lock = threading.Lock()
        self._next = 0
        self._records: list[Record] = []
        self._state = "new"

    @property
    def channel_width_hz(self) -> float:
        """The spectrometer's channel width (Hz)."""
        return self._channel_width_hz

    @property
    def band_hz(self) -> tuple[float, float]:
        """The run's band: the engine layout's, unless a calibration chose another."""
        return self._band_hz

    @property
    def is_open(self) -> bool:
        """Whether measurements can be added (opened, its end not yet recorded)."""
        return self._state == "open"

    @property
    def finished(self) -> bool:
        """Whether the run's end is recorded (its merge may still have failed)."""
        return self._state == "finished"

    @property
    def run_file(self) -> Path:
        """Where :meth:`finish` writes the merged run."""
        return self.directory / RUN_FILE

    def __enter__(self) -> RunStore:
        self.open()
        return self

    def __exit__(
        self, kind: type[BaseException] | None, err: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._state != "open":
            return
        if kind is None:
            self.finish("completed")
        elif issubclass(kind, KeyboardInterrupt):
            self.finish("interrupted", "Ctrl-C")
        else:
            self.finish("failed", f"{kind.__name__}: {err}")

    def open(self) -> None:
        """Create the directory and write the run-description part (number 0).

        When the description cannot be written (a full disk), the directory is removed
        again and the error raised: no run began.
        """
        if self._state != "new":
            raise StoreError(f"{self.directory}: run store already {self._state}")
        make_shared_directory(self.directory)
        if (self.directory / RUN_FILE).exists() or list_parts(self.directory):
            raise StoreError(f"{self.directory}: already holds a run; choose a new directory")
        make_shared_directory(self.directory / PARTS_DIR)
        fsync_directory(self.directory)
        clean_temporaries(self.directory)
        self._state = "open"
        try:
            self._add("run", "description", time.time(), self._write_description)
        except BaseException:
            self._state = "new"  # no run began: leave no empty run directory behind
            for empty in (self.directory / PARTS_DIR, self.directory):
                with contextlib.suppress(OSError):
                    empty.rmdir()
            raise

    def _write_description(self, f: Any) -> None:
        for i, (path, text) in enumerate(self._schedule_files):
            dataset(f, f"schedule_{i}", text, "text", path=path)
        f.attrs["schedule_files"] = [p for p, _ in self._schedule_files]
        dataset(f, "site", self._site_yaml, "text")
        dataset(f, "metadata", to_json(self._metadata), "JSON")
        f.attrs.update(
            run_name=self.name,
            channel_width_hz=self._channel_width_hz,
            band_hz=np.array(self._band_hz),
            software=to_json(software_versions()),
        )

    def _add(self, kind: str, name: str, timestamp: float, fill: Callable[[Any], None]) -> int:
        """Write one part durably; return its measurement number."""
        with self._lock:
            if self._state != "open":
                raise StoreError(f"{self.directory}: cannot add a {kind} to a {self._state} run")
            number = self._next
            path = write_part(self.directory, number, kind, name, timestamp, fill)
            self._records.append(Record(number, kind, name, path, "/"))
            self._next += 1
        log.debug("stored %s", path.name)
        return number

    def records(self, kind: str | None = None) -> list[Record]:
        """The measurements stored so far (of one kind), in order; no I/O."""
        with self._lock:
            return [r for r in self._records if kind is None or r.kind == kind]

    def engine_view(
        self,
        band_hz: tuple[float, float] | None = None,
        *,
        cycles: Mapping[str, Sequence[int]] | None = None,
    ) -> EngineView:
        """What the calibration engine sees of the run so far (the hand-over's rule).

        Parameters
        ----------
        band_hz
            The band; the run's by default.
        cycles
            Use exactly these Dicke cycles (source -> measurement numbers).
        """
        band = self._band_hz if band_hz is None else band_hz
        wanted = [r for r in self.records() if r.kind in ("s11", "dicke")]
        if cycles is not None:
            chosen = {n for numbers in cycles.values() for n in numbers}
            wanted = [r for r in wanted if r.kind == "s11" or r.sequence in chosen]
        with contextlib.ExitStack() as stack:
            groups = {r.sequence: stack.enter_context(h5py.File(r.file, "r")) for r in wanted}
            handover = select(groups, band, self._channel_width_hz, cycles=cycles)
            if RECEIVER not in handover.s11 or not handover.cycles:
                return EngineView(None, handover)
            layout = engine_layout(groups, handover, to_json(self._metadata))
        return EngineView(layout, handover)

    def finish(self, status: str, reason: str = "") -> Path:
        """Record how the run ended and merge it into ``run.h5``; returns its path.

        Called again (e.g. after the merge itself failed), it merges again with the new
        status.
        """
        if status not in STATUSES:
            raise ValueError(f"status must be one of {STATUSES}, got {status!r}")
        if self._state == "finished":
            return merge_run(self.directory, status, reason)

        def fill(f: Any) -> None:
            f.attrs.update(status=status, reason=reason)

        self._add("status", status, time.time(), fill)
        with self._lock:
            self._state = "finished"
        return merge_run(self.directory)


__all__ = ["STATUSES", "EngineView", "RunStore", "software_versions"]
