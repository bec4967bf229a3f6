"""What the iTPM driver delivers: one spectrum, the mean of many, and the stream's counters.

Plain records, shared by the driver (:mod:`reach_receiver.devices.spectrometer`), the
measurement procedures that store them and the monitor that watches the counters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Spectrum:
    """One complete spectrum as the iTPM stamped it.

    Attributes
    ----------
    timestamp
        Unix time, ``sync_time + raw_timestamp x 32768 x 2.5 ns`` (taken to be the start
        of the integration).
    data
        Power, float64, shape (n_inputs, n_channels), physical channel order.
    raw_timestamp, sync_time, heap_counter
        The packet items the spectrum carried.
    """

    timestamp: float
    data: np.ndarray
    raw_timestamp: int
    sync_time: int
    heap_counter: int


@dataclass(frozen=True)
class AccumulatedSpectrum:
    """The mean of ``n_spectra`` consecutive complete spectra, with its bookkeeping.

    Attributes
    ----------
    mean
        Mean power per input and channel, float64, shape (n_inputs, n_channels).
    n_spectra
        Spectra averaged.
    n_discarded
        Complete spectra dropped at the start (``discard``).
    n_stale
        Complete spectra skipped because their integration ended before the request.
    start_time, stop_time
        Timestamps of the first and last averaged spectra (Unix seconds).
    timestamps
        Timestamp of every averaged spectrum, in arrival order.
    requested_at
        Clock time when the integration was asked for.
    packets_lost, packets_duplicated, packets_malformed, heaps_dropped, packets_foreign
        Counted while this integration ran (flush included).
    """

    mean: np.ndarray
    n_spectra: int
    n_discarded: int
    n_stale: int
    start_time: float
    stop_time: float
    timestamps: tuple[float, ...]
    requested_at: float
    packets_lost: int
    packets_duplicated: int
    packets_malformed: int
    heaps_dropped: int
    packets_foreign: int = 0


@dataclass(frozen=True)
class SpectrometerStatistics:
    """Counters since :meth:`Spectrometer.connect` (a snapshot).

    ``packets_received`` counts the source's datagrams only; ``packets_foreign`` those of
    other senders, dropped unread.
    """

    packets_received: int = 0
    packets_malformed: int = 0
    packets_duplicated: int = 0
    packets_late: int = 0
    packets_flushed: int = 0
    packets_lost: int = 0
    spectra_completed: int = 0
    heaps_dropped: int = 0
    packets_foreign: int = 0


__all__ = ["AccumulatedSpectrum", "SpectrometerStatistics", "Spectrum"]
