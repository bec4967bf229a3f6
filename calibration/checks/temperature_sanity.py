"""Calibrator temperatures that look like Celsius: refused, in two lines, with the way out.

A load's physical temperature enters the noise-wave equation (eq. 3.27) as its known
``T_i``; a value typed in Celsius (an "ambient" load at 22.85 "K") is a different receiver
altogether, and the solve fits it without complaint (the noise waves absorb the 273 K).
No calibrator of a room-temperature receiver sits below :data:`CELSIUS_SLIP_K`: REACH's
and EDGES' loads are ambient (~295 K) or heated (~370 K). A load in liquid nitrogen
(77 K) is the one real case, and is allowed by ``--cryogenic``.

One function for every entry point: :func:`celsius_slips` finds the suspects (band
medians), :func:`celsius_message` says what to do; ``reach-cal solve`` and ``validate``
check a run's calibrators (:func:`check_temperatures`) and the importer its
``--temperatures``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike

from ..core.constants import CELSIUS_SLIP_K
from ..core.errors import InvalidDataError

__all__ = ["CELSIUS_SLIP_K", "celsius_message", "celsius_slips", "check_temperatures"]

def celsius_slips(temperatures: Mapping[str, ArrayLike | float]) -> dict[str, float]:
    """The calibrators whose band-median temperature (K) is below :data:`CELSIUS_SLIP_K`."""
    out = {}
    for name, values in temperatures.items():
        if values is None:
            continue
        median = float(np.median(np.asarray(values, dtype=float)))
        if np.isfinite(median) and median < CELSIUS_SLIP_K:
            out[name] = median
    return out


def celsius_message(slips: Mapping[str, float], override: str = "--cryogenic") -> str:
    """Two lines: which loads look like Celsius (with their kelvin), and what to do."""
    listed = ", ".join(f"{n} at {t:.4g} K ({t + 273.15:.5g} K if {t:.4g} is Celsius)"
                       for n, t in slips.items())
    return (
        f"calibrator temperatures below {CELSIUS_SLIP_K:g} K look like Celsius: {listed};\n"
        f"give the run's temperatures in kelvin, or {override} if a load really is that cold"
    )


def check_temperatures(data: object, cryogenic: bool = False) -> list[str]:
    """Refuse a run's calibrators at Celsius-like temperatures (module docstring).

    ``data`` is a :class:`~calibration.model.data.CalibrationData`. With ``cryogenic`` the
    cold loads are accepted and named in a note (the lines returned); otherwise an
    :class:`~calibration.core.errors.InvalidDataError` of :func:`celsius_message`.
    """
    sources = getattr(data, "sources", {})
    slips = celsius_slips({n: s.temperature_k for n, s in sources.items()})
    if not slips:
        return []
    if not cryogenic:
        raise InvalidDataError(celsius_message(slips))
    listed = ", ".join(f"{n} {t:.4g} K" for n, t in slips.items())
    return [f"note: cryogenic calibrators accepted (--cryogenic): {listed}"]
