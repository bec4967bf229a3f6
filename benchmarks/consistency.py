"""Calibrator consistency: how often the check names a wrong calibrator, and falsely any.

Run ``python -m benchmarks.consistency [--seeds N] [--null-seeds M] [--search]``. Simulated
runs (820 channels of 8 iTPM channels, 50-130 MHz, 600 s per Dicke position) of the twelve
REACH calibrators and of the eight of thesis table 4.1; in each, one calibrator is given a
stated temperature ``offset`` K above its true one (below, on odd seeds), and
:func:`calibration.checks.consistency.check_consistency` must name it (detection rate over
seeds, per set, culprit and offset). With no wrong calibrator it must name none: the
false-alarm rate over ``--null-seeds`` seeds per set, against the stated ``alpha = 0.01``.
Orders are fixed at the truth's (4, 3, 4, 4, 3) unless ``--search`` (evidence search with
model averaging, about ten times slower).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from calibration.checks.consistency import check_consistency
from calibration.choice.model_fit import OrderChoice
from calibration.model.data import CalibrationData
from calibration.model.simulate import (
    ITPM_CHANNEL_WIDTH_HZ,
    REACH_CALIBRATORS,
    SimulationConfig,
    simulate_run,
)
from calibration.solve.radiometric_solver import solve_radiometric
from calibration.solve.solution import Solution

TABLE_4_1 = ("cold", "hot", "c10r10", "c10r250", "c2r27", "c2r91", "r25", "r100")
SETS = {"reach12": REACH_CALIBRATORS, "table4.1": TABLE_4_1}
CULPRITS = {
    "reach12": ("c2r36", "c10open", "r100", "c10r250"),
    "table4.1": ("cold", "c10r250", "r25", "c2r91"),
}
OFFSETS_K = (0.02, 0.05, 0.5, 1.0, 2.0, 5.0)
TRUE_ORDERS = (4, 3, 4, 4, 3)
WIDTH_HZ = 8 * ITPM_CHANNEL_WIDTH_HZ


def with_offset(data: CalibrationData, name: str, offset_k: float) -> CalibrationData:
    """``data`` with ``name``'s stated temperature ``offset_k`` above the true one."""
    source = data.sources[name]
    wrong = replace(source, temperature_k=np.asarray(source.temperature_k, dtype=float) + offset_k)
    return replace(data, sources={**data.sources, name: wrong})


def solver(search: bool) -> Callable[[CalibrationData], Solution]:
    choice = None if search else OrderChoice.fixed(TRUE_ORDERS)
    return lambda data: solve_radiometric(data, choice)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=10, help="seeds per culprit and offset")
    parser.add_argument("--null-seeds", type=int, default=200, help="seeds per set, no culprit")
    parser.add_argument("--search", action="store_true", help="evidence search of the orders")
    args = parser.parse_args()
    solve = solver(args.search)
    start = time.perf_counter()
    for set_name, calibrators in SETS.items():
        config = SimulationConfig(calibrators=calibrators, channel_width_hz=WIDTH_HZ)
        runs = [simulate_run(config, rng=50_000 + s).data for s in range(args.seeds)]
        print(f"{set_name} ({len(calibrators)} calibrators), {args.seeds} seeds each:")
        for culprit in CULPRITS[set_name]:
            rates = []
            for offset in OFFSETS_K:
                named = [
                    check_consistency(with_offset(d, culprit, (-1) ** i * offset), solve).worst
                    for i, d in enumerate(runs)
                ]
                hits = sum(c is not None and c.name == culprit for c in named)
                rates.append(f"{offset:g} K: {hits}/{len(runs)}")
            print(f"  {culprit:<9} named  " + ", ".join(rates))
        false = by_offset = by_shape = 0
        z_max = []
        for seed in range(args.null_seeds):
            report = check_consistency(simulate_run(config, rng=60_000 + seed).data, solve)
            false += report.worst is not None
            by_offset += any(c.p_offset < report.p_threshold for c in report.checkable)
            by_shape += any(c.p_shape < report.p_threshold for c in report.checkable)
            z_max.append(max(abs(c.z) for c in report.checkable))
        print(
            f"  no culprit: named one in {false}/{args.null_seeds} runs "
            f"(rate {false / args.null_seeds:.3f}, stated alpha 0.01; offset test "
            f"{by_offset}, shape test {by_shape}); max|z| median {np.median(z_max):.2f}, "
            f"99th percentile {np.percentile(z_max, 99):.2f}, threshold {report.z_threshold:.2f}"
        )
    print(
        f"({'evidence search' if args.search else 'fixed true orders'}; "
        f"{time.perf_counter() - start:.0f} s)"
    )


if __name__ == "__main__":
    main()
