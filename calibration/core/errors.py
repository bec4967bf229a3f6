"""Errors raised by the calibration engine.

One root, :class:`CalibrationError`, so that callers (the daemon, the CLI) can catch
everything the engine reports about bad input or an unsolvable problem in one place.
"""

from __future__ import annotations


class CalibrationError(Exception):
    """Root of every error the calibration engine raises on purpose."""


class InvalidDataError(CalibrationError, ValueError):
    """Calibration or source data that cannot be used; the message names the source."""

    def __init__(self, message: str, source: str | None = None) -> None:
        self.source = source
        prefix = f"source {source!r}: " if source else ""
        super().__init__(prefix + message)


class IllPosedError(CalibrationError):
    """The data do not constrain the requested model (too few sources or too high orders)."""


class FileFormatError(CalibrationError, ValueError):
    """An HDF5 or text file that is not in a format this engine reads."""


class DegenerateStandardsError(InvalidDataError):
    """Calibration standards that do not determine the VNA error terms at some frequencies.

    ``freq_hz`` holds those frequencies (channel indices when no frequencies were given).
    """

    def __init__(self, message: str, freq_hz: tuple[float, ...]) -> None:
        self.freq_hz = freq_hz
        super().__init__(message)
