"""The ``calibrate`` and ``observe`` steps: the calibration engine inside the loop.

``calibrate`` hands the run's latest Dicke cycle and S11 of every calibrator (sources
with a thermocouple temperature, not the validation antenna) and the LNA's S11 to
:func:`calibration.solve_radiometric`, stores the solution, verifies it against a
benchmark solution if one is given, and reports the solution's distance to the noise
floor on the validation source. In a simulated run the true noise-wave parameters are
known, so the actual calibration error of the validation source is reported too:
``T_cal(Q) - T_true(Q)`` with the same measured Q (eq. 3.21), which isolates the error
the calibration adds.

``observe`` takes antenna Dicke cycles, checks the VNA against its test load every
``test_load_every`` cycles, and calibrates each cycle with the current solution, flagging
RFI channels.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from calibration import CalibrationData, solve_radiometric
from calibration.data import SourceData
from calibration.errors import FileFormatError
from calibration.hdf5_io import read_solution
from calibration.noise_floor import noise_floor
from calibration.noise_waves import design_terms, source_temperature
from calibration.simulate import ITPM_CHANNEL_WIDTH_HZ
from calibration.solution import Solution
from reach_receiver.acquire import band_channels, interpolate_s11, source_data
from reach_receiver.schedule import steps as st
from reach_receiver.schedule.actions import VALIDATION_SOURCE, Actions, CheckFailed, CheckRecord
from reach_receiver.schedule.checks import compare_with_benchmark, rfi_flags
from reach_receiver.store import read_run_file

log = logging.getLogger(__name__)


def run_data(
    actions: Actions, f_lo_hz: float, f_hi_hz: float
) -> tuple[CalibrationData, dict[str, SourceData]]:
    """The engine's view of the run so far: calibrators, and the other sources apart."""
    if "lna" not in actions.s11:
        raise CheckFailed("calibrate needs the LNA's S11: add 'lna' to an s11 step before it")
    channels, freq = band_channels(ITPM_CHANNEL_WIDTH_HZ, f_lo_hz, f_hi_hz)
    calibrators: dict[str, SourceData] = {}
    others: dict[str, SourceData] = {}
    ports = actions.instruments.site.thermocouples
    for name, cycles in actions.cycles.items():
        if name not in actions.s11:
            log.warning("calibrate: %s has spectra but no S11; left out", name)
            continue
        known = (
            name != VALIDATION_SOURCE
            and name in ports
            and bool(cycles[-1].temperatures.get("source"))
        )
        source = source_data(
            cycles[-1],
            actions.s11[name],
            freq,
            channels,
            known_temperature=known,
            thermocouple=ports.get(name),
        )
        (calibrators if known else others)[name] = source
    if len(calibrators) < 2:
        raise CheckFailed(
            f"calibrate needs at least two calibrators with spectra, S11 and temperatures; "
            f"have {sorted(calibrators)}"
        )
    data = CalibrationData(
        freq_hz=freq,
        gamma_rec=interpolate_s11(actions.s11["lna"], freq),
        sources=calibrators,
        channel_width_hz=ITPM_CHANNEL_WIDTH_HZ,
        metadata={"source": "reach-run"},
    )
    return data, others


def calibrate(actions: Actions, step: st.Calibrate) -> None:
    """Solve, verify against the benchmark, store, and summarise."""
    data, others = run_data(actions, step.f_lo_hz, step.f_hi_hz)
    solution = solve_radiometric(data)
    verification: dict[str, object] = {}
    if step.benchmark is not None:
        verdict = compare_with_benchmark(
            solution, benchmark_solution(step.benchmark), data.freq_hz, step.tolerance
        )
        verification = {"passed": verdict.passed, **verdict.differences}
        worst = max(verdict.differences, key=verdict.differences.__getitem__)
        detail = (
            f"largest change {worst} {100 * verdict.differences[worst]:.2f} % "
            f"(tolerance {100 * step.tolerance:.0f} %)"
        )
        actions.checks.append(CheckRecord("benchmark solution", verdict.passed, detail))
        actions.store.add_check(
            "benchmark_solution", verdict.passed, timestamp=actions.clock.now(),
            details=verification,
        )
    actions.store.add_solution(solution, timestamp=actions.clock.now(), verification=verification)
    actions.solution = solution
    actions.results["solution"] = _summary(actions, solution, data, others)


def benchmark_solution(path: Path) -> Solution:
    """A benchmark solution: a solution file (``reach-cal solve``) or an earlier run file."""
    try:
        return read_solution(path)
    except FileFormatError:
        previous = read_run_file(path).solution()
        if previous is None:
            raise CheckFailed(f"{path} holds no calibration solution") from None
        return previous


def _summary(
    actions: Actions, solution: Solution, data: CalibrationData, others: dict[str, SourceData]
) -> dict[str, object]:
    summary: dict[str, object] = {
        "orders": solution.orders,
        "noise_scale": solution.posterior.noise_variance,
        "calibrators": list(data.names),
    }
    target = others.get(VALIDATION_SOURCE) or data.sources[data.names[0]]
    spectrum = solution.calibrate(data.freq_hz, data.gamma_rec, target, data.channel_width_hz)
    floor = noise_floor(data, target, solution.parameters).rms
    predicted = float(np.sqrt(np.mean(spectrum.std_calibration**2)))
    summary.update(validation=target.name, floor_k=floor, predicted_k=predicted)
    if actions.truth is not None:
        terms = design_terms(target.gamma, data.gamma_rec)
        true_t = source_temperature(actions.truth(data.freq_hz), terms, target.q)
        summary["actual_k"] = float(np.sqrt(np.mean((spectrum.mean - true_t) ** 2)))
    return summary


def observe(actions: Actions, step: st.Observe) -> None:
    """Antenna Dicke cycles with test-load checks, each calibrated and RFI-flagged."""
    for cycle_index in range(step.cycles):
        if cycle_index and step.test_load_every and cycle_index % step.test_load_every == 0:
            actions.test_load_check(st.TestLoadCheck(step.where))
        cycle = actions._dicke_cycle(step.source, step.seconds)
        solution = actions.solution
        if solution is None or step.source not in actions.s11 or "lna" not in actions.s11:
            continue
        lo, hi = solution.basis.f_lo_hz, solution.basis.f_hi_hz
        channels, freq = band_channels(ITPM_CHANNEL_WIDTH_HZ, lo, hi)
        source = source_data(
            cycle, actions.s11[step.source], freq, channels, known_temperature=False
        )
        gamma_rec = interpolate_s11(actions.s11["lna"], freq)
        spectrum = solution.calibrate(freq, gamma_rec, source, ITPM_CHANNEL_WIDTH_HZ)
        flags = rfi_flags(spectrum.mean, step.rfi_threshold_sigma)
        actions.store.add_calibrated(
            f"{step.source}_{cycle_index:04d}", freq, spectrum.mean, spectrum.std, flags,
            timestamp=actions.clock.now(),
        )
        log.info("observe: cycle %d calibrated, %d channels flagged", cycle_index, flags.sum())
