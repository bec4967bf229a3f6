"""Invalid input is refused with an error naming the source."""

from dataclasses import replace

import numpy as np
import pytest

from calibration import CalibrationData, IllPosedError, InvalidDataError, OrderChoice
from calibration.model.simulate import SimulationConfig, simulate_run
from calibration.solve.radiometric_solver import solve_radiometric

CFG = SimulationConfig(channel_width_hz=400e6 / 32768 * 32)


@pytest.fixture(scope="module")
def run():
    return simulate_run(CFG, rng=0)


def _with_source(data: CalibrationData, name: str, **changes) -> CalibrationData:
    sources = dict(data.sources)
    sources[name] = replace(sources[name], **changes)
    return replace(data, sources=sources)


def test_nan_in_spectrum_names_source(run):
    p = run.data.sources["r25"].p_source.copy()
    p[5] = np.nan
    with pytest.raises(InvalidDataError, match=r"'r25'.*non-finite"):
        _with_source(run.data, "r25", p_source=p)


def test_mismatched_shape_names_source(run):
    with pytest.raises(InvalidDataError, match=r"'c2r27'.*shape"):
        _with_source(run.data, "c2r27", gamma=run.data.sources["c2r27"].gamma[:-1])


def test_reflection_at_or_above_unity(run):
    g = run.data.sources["c10open"].gamma.copy()
    g[0] = 1.0
    with pytest.raises(InvalidDataError, match=r"'c10open'.*\|Gamma\|"):
        _with_source(run.data, "c10open", gamma=g)


def test_noise_source_not_above_load(run):
    src = run.data.sources["hot"]
    with pytest.raises(InvalidDataError, match=r"'hot'.*P_ns <= P_load"):
        _with_source(run.data, "hot", p_ns=src.p_load)


def test_calibrator_without_temperature(run):
    with pytest.raises(InvalidDataError, match=r"'cold'.*temperature"):
        _with_source(run.data, "cold", temperature_k=None)


def test_frequencies_must_increase(run):
    with pytest.raises(InvalidDataError, match="increasing"):
        replace(run.data, freq_hz=run.data.freq_hz[::-1])


def test_single_calibrator_refused(run):
    with pytest.raises(IllPosedError, match=r"'cold'.*at least two"):
        solve_radiometric(run.data.subset(["cold"]))


def test_too_few_sources_for_orders(run):
    # Two matched loads (|Gamma| < -40 dB) cannot pin down seven-term T_unc, T_cos, T_sin.
    two = run.data.subset(["cold", "hot"])
    with pytest.raises(IllPosedError, match=r"orders \(7, 7, 7, 7, 7\)"):
        solve_radiometric(two, OrderChoice.fixed((7, 7, 7, 7, 7)))


def test_unknown_calibrator_in_subset(run):
    with pytest.raises(InvalidDataError, match="no such calibrators"):
        run.data.subset(["cold", "nonsense"])
