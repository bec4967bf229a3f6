"""Coverage of the radiometric solver's credible intervals over many seeded runs.

Issue requirement: the 68% and 95% intervals of the calibrated validation source contain
the truth 68 +- 5% and 95 +- 3% of the time. Two versions are checked:

* calibration error only: the noiselessly measured validation source, so the intervals
  test the posterior of the noise-wave parameters (correlated across channels, hence
  many runs and only a few channels per run);
* the full predictive: the noisy validation source, whose own radiometer noise joins.

Two ensembles of 200 runs each: the REACH-like receiver with 10-minute positions, and the
same with 30-second positions and the VNA's trace noise (1e-3) on every reflection, the
receiver's included; there the noiseless source's interval holds the receiver
reflection's error too (a per-channel error no calibration removes).
"""

import numpy as np
import pytest

from calibration import solve_radiometric
from calibration.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run

N_RUNS = 200
WIDTH = ITPM_CHANNEL_WIDTH_HZ * 32
ENSEMBLES = {
    "10 min": SimulationConfig(channel_width_hz=WIDTH),
    "30 s, VNA noise": SimulationConfig(channel_width_hz=WIDTH, integration_s=30.0,
                                        vna_sigma=1e-3),
}


def collect_hits(config: SimulationConfig, n_runs: int = N_RUNS):
    """Per-run interval hits: calibration-only (8 channels) and full predictive (all)."""
    channels = np.linspace(0, config.frequencies().size - 1, 8).astype(int)
    calibration_only = {0.68: [], 0.95: []}
    full = {0.68: [], 0.95: []}
    for seed in range(n_runs):
        run = simulate_run(config, rng=10_000 + seed)
        data = run.data
        sol = solve_radiometric(data)
        f, gr = data.freq_hz, data.gamma_rec
        truth = run.validation_temperature_k
        # No channel width for the noiseless source: no radiometer term in its interval.
        clean = sol.calibrate(f, gr, run.validation_noiseless, gamma_rec_std=data.gamma_rec_std)
        noisy = sol.calibrate(
            f, gr, run.validation, data.channel_width_hz, data.gamma_rec_std
        )
        for level in (0.68, 0.95):
            lo, hi = clean.interval(level)
            calibration_only[level].append(((lo <= truth) & (truth <= hi))[channels])
            lo, hi = noisy.interval(level)
            full[level].append((lo <= truth) & (truth <= hi))
    return calibration_only, full


@pytest.fixture(scope="module", params=list(ENSEMBLES))
def hits(request):
    return collect_hits(ENSEMBLES[request.param])


@pytest.mark.slow
@pytest.mark.parametrize(("level", "tolerance"), [(0.68, 0.05), (0.95, 0.03)])
def test_calibration_error_coverage(hits, level, tolerance):
    fraction = float(np.mean(hits[0][level]))
    assert abs(fraction - level) <= tolerance, f"{level:.0%} interval covered {fraction:.1%}"


@pytest.mark.slow
@pytest.mark.parametrize(("level", "tolerance"), [(0.68, 0.05), (0.95, 0.03)])
def test_full_predictive_coverage(hits, level, tolerance):
    fraction = float(np.mean(hits[1][level]))
    assert abs(fraction - level) <= tolerance, f"{level:.0%} interval covered {fraction:.1%}"
