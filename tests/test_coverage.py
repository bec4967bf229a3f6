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


#: Runs of the ensemble of truths and set-ups below (the issue asks for at least 200).
FAMILY_RUNS = 240


@pytest.fixture(scope="module")
def family():
    """The default solver over an ensemble of truths *and* set-ups: each run its own
    calibrators (the cold and hot loads and 2-10 others of REACH's), integration time
    (30 s to 1 h, log-uniform), VNA trace noise (1e-3, in half the runs) and truth (each
    parameter 1-6 terms, each higher term 0.3-30 posterior sd of that set-up): the
    model-choice benchmark's last ensemble, run by the benchmark's own loop, at 205
    channels. Per run: error / floor, actual / predicted error and the calibration-only
    68/95 % hits (8 channels); and how many runs the solver refused."""
    from benchmarks.model_choice import Ensemble, run_ensemble

    ensemble = Ensemble("random truths and set-ups", channel_width_hz=WIDTH, setups="random")
    tally = run_ensemble(ensemble, FAMILY_RUNS, seed=2026, wanted={"averaged"})["averaged"]
    return (np.array(tally.ratios), np.array(tally.honesty), np.array(tally.hits),
            tally.failures)


@pytest.mark.slow
def test_an_ensemble_of_truths_and_set_ups_is_covered_at_the_nominal_rates(family):
    """Over 240 runs, each with its own calibrators, integration, VNA noise and truth, the
    68/95 % intervals cover within 4 and 2.5 points of the nominal rates (66.4-68.3 % and
    93.8-96.0 % over this and four other seeds of the family), the median run's error bars
    are right in size (actual / predicted 0.96-0.97 there), the RMS over runs of error /
    floor is within the issue's 1.10 (1.00-1.07 over the five seeds) and no run is ten
    times the floor off (none beyond 3.2x there). Before the rows were corrected for the
    reflections' errors (``calibration.errors_in_variables``) runs came out up to 235
    times the floor off and the RMS was 8-20; with the correction but the search kept to
    the box the calibrators identify whole, one run each at two of the five seeds (this
    one among them) came out 30 and 56 times off, its truth beyond that box (RMS 2.2 and
    3.75). A few runs are refused (four calibrators that leave T_NS undetermined), at
    most a tenth."""
    ratios, honesty, hits, refused = family
    print(f"RMS error/floor {np.sqrt(np.mean(ratios**2)):.3f}, median actual/predicted "
          f"{np.median(honesty):.3f}, coverage {hits.mean(axis=0)}, refused {refused}, "
          f"far off {int(np.sum(ratios > 10))}")
    assert refused <= FAMILY_RUNS // 10
    assert abs(hits[:, 0].mean() - 0.68) <= 0.04
    assert abs(hits[:, 1].mean() - 0.95) <= 0.025
    assert 0.9 <= np.median(honesty) <= 1.1
    assert np.median(ratios) <= 1.05
    assert np.sqrt(np.mean(ratios**2)) <= 1.10
    assert np.sum(ratios > 10) == 0
