"""``reach-cal plan`` and ``solve --contributions``: which calibrators earn their time.

Both read the antenna's reflection from the run (``--antenna``, default ``ant``) and judge
the calibrators by the antenna's predicted calibration error over the band of interest
(:mod:`calibration.design.contributions`).
"""

from __future__ import annotations

import argparse

import numpy as np

from ..core.errors import InvalidDataError
from ..design.adaptive import ANTENNA_REF_HZ, AdaptivePlanner, AdaptiveSettings
from ..design.contributions import contributions, plan
from ..design.information import AntennaInformation, band_mask
from ..io.hdf5_io import read_run
from ..model.data import CalibrationData, SourceData
from ..solve.radiometric_solver import solve_radiometric
from ..solve.solution import Solution
from .solve import calibrators_of


def _antenna(args: argparse.Namespace, data: CalibrationData) -> SourceData:
    """The run's antenna on ``data``'s channels."""
    full, sources = read_run(args.run)
    if args.antenna not in sources:
        have = ", ".join(sorted(sources)) or "none"
        raise InvalidDataError(
            f"{args.run} has no source {args.antenna!r} to judge the calibrators by (its "
            f"non-calibrators: {have}): name one with --antenna"
        )
    antenna = sources[args.antenna]
    if full.freq_hz.size != data.freq_hz.size:  # solve's --band or channel masks
        antenna = antenna.select(np.isin(full.freq_hz, data.freq_hz))
    return antenna


def _settings(args: argparse.Namespace, **extra: float) -> AdaptiveSettings:
    band = None if args.interest is None else (args.interest[0] * 1e6, args.interest[1] * 1e6)
    return AdaptiveSettings(band_hz=band, **extra)  # type: ignore[arg-type]


def information(
    args: argparse.Namespace, data: CalibrationData, solution: Solution | None = None,
    **extra: float,
) -> tuple[AntennaInformation, AdaptivePlanner, AdaptiveSettings]:
    """The antenna's information from ``data`` (the planner's posterior: its model fixed).

    The antenna's temperature is ``--antenna-k`` at 75 MHz with ``--antenna-index``, or
    the power law fitted to its spectrum as ``solution`` (the default solve where none is
    given) calibrates it (:func:`power_law`).
    """
    antenna = _antenna(args, data)
    antenna_k, index = args.antenna_k, args.antenna_index
    if antenna_k is None and index != 0:
        raise InvalidDataError("--antenna-index needs --antenna-k (the temperature at 75 MHz)")
    if antenna_k is None:
        solution = solution or solve_radiometric(data)
        spectrum = solution.calibrate(data.freq_hz, data.gamma_rec, antenna)
        antenna_k, index = power_law(data.freq_hz, spectrum.mean, args.antenna)
    settings = _settings(args, antenna_temperature_k=antenna_k, antenna_index=index, **extra)
    planner = AdaptivePlanner(settings, antenna.gamma)
    info, _ = planner.information(data)
    return info, planner, settings


def power_law(freq_hz: np.ndarray, temperature_k: np.ndarray, name: str) -> tuple[float, float]:
    """``(T_0, beta)`` of ``T = T_0 (f / 75 MHz)^beta`` fitted to a calibrated spectrum.

    Least squares in ``log T`` against ``log f``: the sky a global 21-cm antenna sees is
    close to a power law (index about -2.5), a load on the antenna port a flat one; the
    planner needs the antenna's temperature only through its design row, so this smooth
    stand-in for a noisy spectrum serves it.
    """
    if not np.all(temperature_k > 0):
        raise InvalidDataError(
            f"{name} calibrates to {float(np.min(temperature_k)):.4g} K somewhere in the band: "
            "give its temperature with --antenna-k (and --antenna-index)"
        )
    x = np.log(np.asarray(freq_hz, dtype=float) / ANTENNA_REF_HZ)
    slope, intercept = np.polyfit(x, np.log(temperature_k), 1)
    return float(np.exp(intercept)), float(slope)


def _temperature(settings: AdaptiveSettings) -> str:
    """The antenna's assumed temperature in words."""
    if settings.antenna_index == 0:
        return f"{settings.antenna_temperature_k:.4g} K"
    return f"{settings.antenna_temperature_k:.4g} K at 75 MHz, index {settings.antenna_index:.2f}"


def _where(data: CalibrationData, settings: AdaptiveSettings) -> str:
    freq = data.freq_hz[band_mask(data.freq_hz, settings.band_hz)]
    return f"{freq[0] / 1e6:.4g}-{freq[-1] / 1e6:.4g} MHz"


def contribution_lines(
    args: argparse.Namespace, data: CalibrationData, solution: Solution
) -> list[str]:
    """``solve --contributions``: each calibrator's share and the error without it."""
    info, planner, settings = information(args, data, solution)
    now = 1e3 * planner.kappa * float(np.sqrt(info.variance()))
    lines = [
        f"calibrators' contributions to {args.antenna} ({_temperature(settings)}): "
        f"predicted calibration error {now:.4g} mK RMS over {_where(data, settings)}, "
        f"orders {','.join(map(str, info.orders))}",
        f"  {'calibrator':<12}{'s/position':>11}{'share':>8}{'without it (mK)':>17}",
    ]
    for c in sorted(contributions(info, planner.kappa), key=lambda c: -c.share):
        without = f"{c.without_mk:.4g}" if np.isfinite(c.without_mk) else "undetermined"
        lines.append(f"  {c.source:<12}{c.seconds:>11.6g}{c.share:>8.3f}{without:>17}")
    return lines


def cmd_plan(args: argparse.Namespace) -> int:
    """Seconds per calibrator for ``--target-mk``, beside the round-robin."""
    args.calibrators, args.cryogenic = None, False
    data = calibrators_of(args)
    info, planner, settings = information(
        args, data, first_pass_s=args.first_pass_s, overhead_s=args.overhead_s,
        budget_s=args.budget_h * 3600.0,
    )
    now = 1e3 * planner.kappa * float(np.sqrt(info.variance()))
    result = plan(info, args.target_mk, settings, planner.kappa)
    print(
        f"{args.run}: {args.antenna}'s predicted calibration error {now:.4g} mK RMS over "
        f"{_where(data, settings)}, orders {','.join(map(str, info.orders))}"
    )
    print(f"plan for {args.target_mk:g} mK (seconds per Dicke position):")
    for name, seconds in sorted(result.seconds.items(), key=lambda kv: -kv[1]):
        print(f"  {name:<12}{seconds:>10.6g}")
    print(
        f"instrument time {result.instrument_s / 3600:.3g} h (3 positions and "
        f"{settings.overhead_s:g} s overhead per calibrator); "
        f"predicted {result.predicted_mk:.4g} mK"
    )
    if np.isfinite(result.round_robin_seconds):
        print(
            f"round-robin to the same target: {result.round_robin_seconds:.6g} s each, "
            f"{result.round_robin_instrument_s / 3600:.3g} h "
            f"({result.round_robin_instrument_s / result.instrument_s:.2f} x the plan)"
        )
    if not result.reached:
        print(
            f"reach-cal: warning: {args.target_mk:g} mK is not reached within --budget-h "
            f"{args.budget_h:g}: raise --budget-h or the target"
        )
    return 0
