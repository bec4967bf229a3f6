"""Three-term one-port VNA calibration (short-open-load), vectorised over frequency.

Error model (Pozar, *Microwave Engineering*, 4th ed., sec. 4.6; the convention of
scikit-rf's ``OnePort``): a port whose actual reflection is ``G`` reads::

    m = e00 + e01e10 G / (1 - e11 G)                                          (1)

with directivity ``e00``, source match ``e11`` and reflection tracking ``e01e10``, all
complex functions of frequency. Multiplying out, (1) is linear in three unknowns::

    m = e00 + e11 (G m) + D G,        D = e01e10 - e00 e11                     (2)

so the readings ``m_i`` of ``k >= 3`` standards of known reflections ``G_i`` give, per
frequency, a ``k x 3`` linear system. :func:`solve_one_port` solves it for every frequency
at once (a stacked SVD, no loop over channels); with more than three standards this is the
least-squares solution of ``numpy.linalg.lstsq`` and of scikit-rf. The inverse of (1)::

    G = (m - e00) / (e01e10 + e11 (m - e00))                                  (3)

is :func:`correct_reflection`; (1) itself is :func:`embed_reflection`, for simulation.
The standards' actual reflections come from :mod:`calibration.rf.cal_kit` (or are ideal:
short ``-1``, open ``+1``, load ``0``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import DegenerateStandardsError, InvalidDataError

__all__ = [
    "OnePortTerms",
    "correct_reflection",
    "embed_reflection",
    "solve_one_port",
]

ComplexArray = NDArray[np.complex128]

#: Default smallest distance, in reflection units, between two standards' actual reflections.
MIN_SEPARATION = 1e-9
_LISTED = 8  # frequencies named in an error message before "and N more"


class OnePortTerms(NamedTuple):
    """The three error terms of a VNA port over frequency (each of the data's shape).

    A named tuple, so ``e00, e11, e01e10 = terms`` unpacks in the order of (1).
    """

    directivity: ComplexArray
    """``e00``."""
    source_match: ComplexArray
    """``e11``."""
    reflection_tracking: ComplexArray
    """``e01e10`` (``e10e01``; the product, never the factors)."""

    def correct(self, measured: ArrayLike) -> ComplexArray:
        """Actual reflections from raw readings: :func:`correct_reflection`."""
        return correct_reflection(measured, self)

    def embed(self, actual: ArrayLike) -> ComplexArray:
        """Raw readings of actual reflections: :func:`embed_reflection`."""
        return embed_reflection(actual, self)


def embed_reflection(actual: ArrayLike, terms: OnePortTerms) -> ComplexArray:
    """Raw reading ``m = e00 + e01e10 G / (1 - e11 G)`` of actual reflections ``G``, eq. (1).

    ``actual`` broadcasts against the terms (frequency on the last axis).
    """
    e00, e11, tracking = terms
    g = np.asarray(actual, dtype=complex)
    return np.asarray(e00 + tracking * g / (1 - e11 * g), dtype=complex)


def correct_reflection(measured: ArrayLike, terms: OnePortTerms) -> ComplexArray:
    """Actual reflection ``G = (m - e00) / (e01e10 + e11 (m - e00))`` of raw readings, eq. (3).

    ``measured`` broadcasts against the terms (frequency on the last axis).
    """
    e00, e11, tracking = terms
    offset = np.asarray(measured, dtype=complex) - e00
    return np.asarray(offset / (tracking + e11 * offset), dtype=complex)


def solve_one_port(
    measured: ArrayLike,
    actual: ArrayLike | Sequence[ArrayLike],
    freq_hz: ArrayLike | None = None,
    *,
    min_separation: float = MIN_SEPARATION,
) -> OnePortTerms:
    """Error terms of eq. (1) from raw readings of ``k >= 3`` standards, every frequency at once.

    Parameters
    ----------
    measured
        Raw readings, shape ``(k, ...)``: standard on the first axis, frequency after it
        (``(k, n_freq)`` for a sweep, ``(k,)`` for one frequency).
    actual
        The standards' actual reflections: shape ``(k,)`` (one value per standard, the same
        at every frequency, e.g. ideal ``[-1, 1, 0]``), or anything broadcastable to
        ``measured``'s shape (e.g. :meth:`calibration.rf.cal_kit.CalKit.reflections`).
    freq_hz
        Frequencies of the trailing axes, only to name them in errors (else channel indices).
    min_separation
        Two actual reflections closer than this (absolute) count as the same standard.

    Returns
    -------
    OnePortTerms
        ``(e00, e11, e01e10)``, each of ``measured.shape[1:]``. With ``k > 3`` the
        least-squares solution of eq. (2), as ``numpy.linalg.lstsq`` per frequency.

    Raises
    ------
    InvalidDataError
        Fewer than three standards, shapes that do not match, or non-finite values.
    DegenerateStandardsError
        At some frequencies fewer than three standards have distinct actual reflections,
        or the readings leave eq. (2) singular; the message and ``freq_hz`` name them.
    """
    m = np.asarray(measured, dtype=complex)
    if m.ndim == 0 or m.shape[0] < 3:
        raise InvalidDataError(
            f"one-port calibration needs at least three standards, got shape {m.shape}"
        )
    k, trailing = m.shape[0], m.shape[1:]
    g = _broadcast_actual(actual, m.shape)
    m2, g2 = m.reshape(k, -1).T, g.reshape(k, -1).T  # (n, k)
    labels = _labels(freq_hz, trailing)
    bad = ~(np.all(np.isfinite(m2), axis=1) & np.all(np.isfinite(g2), axis=1))
    if bad.any():
        raise InvalidDataError(f"non-finite reflections at {_name(labels, bad)}")
    _check_distinct(g2, min_separation, labels)
    # eq. (2): rows [1, G_i m_i, G_i] times (e00, e11, D) = m_i, solved by SVD per channel
    matrix = np.stack([np.ones_like(g2), g2 * m2, g2], axis=-1)
    u, s, vh = np.linalg.svd(matrix, full_matrices=False)
    singular = s[:, -1] <= s[:, 0] * k * np.finfo(float).eps
    if singular.any():
        raise DegenerateStandardsError(
            "the standards' readings leave the one-port system singular (the same reading "
            f"for different standards?) at {_name(labels, singular)}",
            _values(labels, singular),
        )
    projected = np.conj(u).swapaxes(-1, -2) @ m2[..., None]
    x = (np.conj(vh).swapaxes(-1, -2) / s[:, None, :]) @ projected
    e00, e11, delta = (x[:, i, 0].reshape(trailing) for i in range(3))
    return OnePortTerms(e00, e11, delta + e00 * e11)


def _broadcast_actual(
    actual: ArrayLike | Sequence[ArrayLike], shape: tuple[int, ...]
) -> ComplexArray:
    """``actual`` as an array of ``shape``; a ``(k,)`` vector is one value per standard."""
    if isinstance(actual, Sequence) and not isinstance(actual, str | bytes):
        given = f"{len(actual)} standards' actual reflections"
        if len(actual) == shape[0]:
            try:
                rows = [np.broadcast_to(np.asarray(a, dtype=complex), shape[1:]) for a in actual]
                return np.stack(rows)
            except ValueError:
                pass
    else:
        g = np.asarray(actual, dtype=complex)
        given = f"actual reflections of shape {g.shape}"
        if g.ndim == 1 and len(shape) > 1:
            g = g.reshape((g.size,) + (1,) * (len(shape) - 1))
        try:
            return np.broadcast_to(g, shape)
        except ValueError:
            pass
    raise InvalidDataError(f"{given} do not match readings of shape {shape} (standards first)")


def _labels(
    freq_hz: ArrayLike | None, trailing: tuple[int, ...]
) -> tuple[NDArray[np.float64], str]:
    """Per-channel labels for messages: frequencies in Hz, or channel indices."""
    n = int(np.prod(trailing, dtype=int))
    if freq_hz is None:
        return np.arange(n, dtype=float), "channel"
    try:
        f = np.broadcast_to(np.asarray(freq_hz, dtype=float), trailing).ravel()
    except ValueError:
        raise InvalidDataError(
            f"freq_hz of shape {np.shape(freq_hz)} does not match the channels {trailing}"
        ) from None
    return f, "Hz"


def _values(labels: tuple[NDArray[np.float64], str], mask: NDArray[np.bool_]) -> tuple[float, ...]:
    return tuple(float(v) for v in labels[0][mask])


def _name(labels: tuple[NDArray[np.float64], str], mask: NDArray[np.bool_]) -> str:
    """``"3 frequencies: 1e+08 Hz, 1.1e+08 Hz, 1.2e+08 Hz"`` (or channels), the first few."""
    values, unit = labels
    chosen = values[mask]
    what = "frequencies" if unit == "Hz" else "channels"
    if unit == "Hz":
        shown = ", ".join(f"{v:.9g} Hz" for v in chosen[:_LISTED])
    else:
        shown = ", ".join(f"channel {int(v)}" for v in chosen[:_LISTED])
    more = f" and {chosen.size - _LISTED} more" if chosen.size > _LISTED else ""
    return f"{chosen.size} {what}: {shown}{more}"


def _check_distinct(
    g: ComplexArray, min_separation: float, labels: tuple[NDArray[np.float64], str]
) -> None:
    """Raise unless every channel has at least three distinct actual reflections."""
    k = g.shape[1]
    close = np.abs(g[:, :, None] - g[:, None, :]) <= min_separation  # (n, k, k)
    earlier = np.tril(np.ones((k, k), dtype=bool), -1)
    repeated = np.any(close & earlier, axis=2)  # standard i equals one listed before it
    degenerate = k - repeated.sum(axis=1) < 3
    if not degenerate.any():
        return
    first = int(np.flatnonzero(degenerate)[0])
    pairs = ", ".join(f"{j} and {i}" for i in range(k) for j in range(i) if close[first, i, j])
    raise DegenerateStandardsError(
        "fewer than three standards with distinct actual reflections at "
        f"{_name(labels, degenerate)} (at the first, standards {pairs} coincide within "
        f"{min_separation:g})",
        _values(labels, degenerate),
    )
