"""Coverage of the radiometric solver's credible intervals over seeded runs.

The 68% and 95% intervals of the calibrated validation source must contain the truth at
their nominal rates. Two versions are checked:

* calibration error only: the noiselessly measured validation source, so the intervals
  test the posterior of the noise-wave parameters (correlated across channels, hence
  many runs and only a few channels per run);
* the full predictive: the noisy validation source, whose own radiometer noise joins.

Two ensembles: the REACH-like receiver with 10-minute positions, and the same with
30-second positions and the VNA's trace noise (1e-3) on every reflection, the receiver's
included; there the noiseless source's interval holds the receiver reflection's error too
(a per-channel error no calibration removes). Then a family of truths and set-ups.

The runs here are fewer than the benchmark's (``python -m benchmarks.coverage``: 200 a
fixed ensemble, 68 +- 5 / 95 +- 3 points; 240 of the family) so that the suite stays
short: the tolerances are wider by the square root of the ratio of runs, enough to catch
error bars off by tens of percent, not the last point of coverage.
"""

import numpy as np
import pytest

from benchmarks.coverage import ENSEMBLES, collect_hits, family_tally

#: Runs per fixed ensemble (the benchmark's 200 hold 68 +- 5 / 95 +- 3 points). At 40 the
#: calibration error covered 70.0/93.1 % and 70.6/95.6 %, at 60 66.9/94.8 % and 72.5/95.8 %.
N_RUNS = 40


@pytest.fixture(scope="module", params=list(ENSEMBLES))
def hits(request):
    return collect_hits(ENSEMBLES[request.param], N_RUNS)


@pytest.mark.slow
@pytest.mark.parametrize(("level", "tolerance"), [(0.68, 0.09), (0.95, 0.05)])
def test_calibration_error_coverage(hits, level, tolerance):
    fraction = float(np.mean(hits[0][level]))
    assert abs(fraction - level) <= tolerance, f"{level:.0%} interval covered {fraction:.1%}"


@pytest.mark.slow
@pytest.mark.parametrize(("level", "tolerance"), [(0.68, 0.05), (0.95, 0.03)])
def test_full_predictive_coverage(hits, level, tolerance):
    fraction = float(np.mean(hits[1][level]))
    assert abs(fraction - level) <= tolerance, f"{level:.0%} interval covered {fraction:.1%}"


#: Runs of the family of truths and set-ups (the benchmark runs 240).
FAMILY_RUNS = 80


@pytest.fixture(scope="module")
def family():
    """The default solver over an ensemble of truths *and* set-ups: each run its own
    calibrators (the cold and hot loads and 2-10 others of REACH's), integration time
    (30 s to 1 h, log-uniform), VNA trace noise (1e-3, in half the runs) and truth (each
    parameter 1-6 terms, each higher term 0.3-30 posterior sd of that set-up): the
    model-choice benchmark's last ensemble, at 205 channels (:func:`benchmarks.coverage.
    family_tally`)."""
    return family_tally(FAMILY_RUNS)


@pytest.mark.slow
def test_an_ensemble_of_truths_and_set_ups_is_covered_at_the_nominal_rates(family):
    """Over runs each with its own calibrators, integration, VNA noise and truth, the
    68/95 % intervals cover within 7 and 4.5 points of the nominal rates (the benchmark's
    240 runs: within 4 and 2.5, 66.4-68.3 % and 93.8-96.0 % over five seeds), the median
    run's error bars are right in size, the RMS over runs of error / floor is within the
    issue's 1.10 and no run is ten times the floor off. Before the rows were corrected for
    the reflections' errors (``calibration.regression.errors_in_variables``) runs came out up to 235
    times the floor off and the RMS was 8-20. A few runs are refused (four calibrators
    that leave T_NS undetermined), at most a tenth."""
    ratios, honesty, hits, refused = family
    print(f"RMS error/floor {np.sqrt(np.mean(ratios**2)):.3f}, median actual/predicted "
          f"{np.median(honesty):.3f}, coverage {hits.mean(axis=0)}, refused {refused}, "
          f"far off {int(np.sum(ratios > 10))}")
    assert refused <= FAMILY_RUNS // 10
    assert abs(hits[:, 0].mean() - 0.68) <= 0.07
    assert abs(hits[:, 1].mean() - 0.95) <= 0.045
    assert 0.9 <= np.median(honesty) <= 1.1
    assert np.median(ratios) <= 1.05
    assert np.sqrt(np.mean(ratios**2)) <= 1.10
    assert np.sum(ratios > 10) == 0
