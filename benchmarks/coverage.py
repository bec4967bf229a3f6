"""Coverage of the default solver's credible intervals over many seeded runs.

Usage (from the repository root)::

    python -m benchmarks.coverage [--runs 200] [--family-runs 240]

Three ensembles, as ``tests/test_coverage.py`` checks them with fewer runs:

* the REACH-like receiver with 10-minute positions, and with 30-second positions and the
  VNA's trace noise (1e-3) on every reflection: the fraction of channels (8 a run) whose
  68/95 % calibration-only interval of the noiselessly measured validation source holds
  the truth, and of all channels whose full predictive interval (its own radiometer noise
  joining) does. Nominal: 68 +- 5 and 95 +- 3 points over 200 runs.
* the family of truths and set-ups of :mod:`benchmarks.model_choice` (each run its own
  calibrators, integration time, VNA noise and truth): coverage, RMS over runs of error /
  floor, median actual / predicted, runs refused and runs ten times the floor off.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from calibration import solve_radiometric
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run

WIDTH = ITPM_CHANNEL_WIDTH_HZ * 32
ENSEMBLES = {
    "10 min": SimulationConfig(channel_width_hz=WIDTH),
    "30 s, VNA noise": SimulationConfig(channel_width_hz=WIDTH, integration_s=30.0,
                                        vna_sigma=1e-3),
}
LEVELS = (0.68, 0.95)


def collect_hits(
    config: SimulationConfig, n_runs: int, first_seed: int = 10_000
) -> tuple[dict[float, list[np.ndarray]], dict[float, list[np.ndarray]]]:
    """Per-run interval hits: calibration-only (8 channels) and full predictive (all)."""
    channels = np.linspace(0, config.frequencies().size - 1, 8).astype(int)
    calibration_only: dict[float, list[np.ndarray]] = {level: [] for level in LEVELS}
    full: dict[float, list[np.ndarray]] = {level: [] for level in LEVELS}
    for seed in range(n_runs):
        run = simulate_run(config, rng=first_seed + seed)
        data = run.data
        sol = solve_radiometric(data)
        f, gr = data.freq_hz, data.gamma_rec
        truth = run.validation_temperature_k
        # No channel width for the noiseless source: no radiometer term in its interval.
        clean = sol.calibrate(f, gr, run.validation_noiseless, gamma_rec_std=data.gamma_rec_std)
        noisy = sol.calibrate(f, gr, run.validation, data.channel_width_hz, data.gamma_rec_std)
        for level in LEVELS:
            lo, hi = clean.interval(level)
            calibration_only[level].append(((lo <= truth) & (truth <= hi))[channels])
            lo, hi = noisy.interval(level)
            full[level].append((lo <= truth) & (truth <= hi))
    return calibration_only, full


def family_tally(n_runs: int, seed: int = 2026) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The model-choice benchmark's random truths and set-ups at 205 channels.

    Per run: error / floor, actual / predicted, the calibration-only 68/95 % hits; and
    the number of runs the solver refused.
    """
    from benchmarks.model_choice import Ensemble, run_ensemble

    ensemble = Ensemble("random truths and set-ups", channel_width_hz=WIDTH, setups="random")
    tally = run_ensemble(ensemble, n_runs, seed=seed, wanted={"averaged"})["averaged"]
    return (np.array(tally.ratios), np.array(tally.honesty), np.array(tally.hits),
            tally.failures)


def main(argv: list[str] | None = None) -> int:
    """Print the coverage table of each ensemble."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.coverage")
    parser.add_argument("--runs", type=int, default=200, help="runs per fixed ensemble")
    parser.add_argument("--family-runs", type=int, default=240, help="runs of the family")
    args = parser.parse_args(argv)
    print(f"{'ensemble':<18} {'runs':>5} {'cal 68':>7} {'cal 95':>7} {'full 68':>8} {'full 95':>8}")
    for name, config in ENSEMBLES.items():
        cal, full = collect_hits(config, args.runs)
        row = [np.mean(cal[0.68]), np.mean(cal[0.95]), np.mean(full[0.68]), np.mean(full[0.95])]
        print(f"{name:<18} {args.runs:>5} " + " ".join(f"{100 * v:7.1f}" for v in row))
    ratios, honesty, hits, refused = family_tally(args.family_runs)
    print(f"family of truths and set-ups, {args.family_runs} runs: coverage "
          f"{100 * hits[:, 0].mean():.1f}/{100 * hits[:, 1].mean():.1f} %, RMS error/floor "
          f"{np.sqrt(np.mean(ratios**2)):.3f}, median actual/predicted {np.median(honesty):.3f}, "
          f"refused {refused}, over 10x the floor {int(np.sum(ratios > 10))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
