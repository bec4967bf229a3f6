"""A completed run's result as text, the same lines wherever they are shown.

``reach-run`` prints them, ``run.log`` holds them and the daemon's job end carries them
to its followers. One function makes them, so that a local run, a job followed through
``reachd`` and the run's own log say the same thing in the same words: the run file and
its duration, each check (the test load's among them), and for a run that made a
calibration the hand-over, the solution (orders, noise scale ``s^2``), the distance to
the noise floor on the validation source (the antenna when it was measured), and the
VNA's systematic when it was asked for.
Each line fits in 80 columns (an operator's terminal over the satellite link): a longer
one continues on the next, indented, broken between its parts (never inside a number
and its unit, a pair of orders and weight, a parenthesis), so that what reads a line
for a number still finds it beside its words.

A simulated run also knows the truth: ``truth`` (the simulator's physics, passed by the
caller, since the run layer does not import the simulators) adds the actual calibration
error against it, and for a per-channel solution each channel's error in units of its
own floor.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import NDArray

from calibration import CalibrationData
from calibration.model.data import SourceData
from calibration.solve.identifiability import caution_lines, model_choice_line
from calibration.solve.per_frequency import ChannelSolution
from calibration.solve.solvers import AnySolution, NoiseWaveSolution, method_name
from reach_receiver.schedule.timing import hms
from reach_receiver.store.corrections import corrections_line

from .progress_lines import fit, pack
from .steps.calibrate import CalibrationOutcome

if TYPE_CHECKING:
    from .session import RunSummary

FloatArray = NDArray[np.float64]


class Truth(Protocol):
    """What the simulator knows: the calibration's error per channel against the truth."""

    def calibration_errors_k(
        self, solution: NoiseWaveSolution, data: CalibrationData, source: SourceData
    ) -> FloatArray:
        """``T_cal(Q) - T_true(Q)`` per channel (kelvin)."""


def summary_lines(summary: RunSummary, truth: Truth | None = None) -> list[str]:
    """The result of a completed run, line by line (``reach-run`` prints them on stdout)."""
    lines = [
        f"run file: {summary.run_file}",
        f"simulated/real time of the run: {hms(summary.elapsed_s)}",
    ]
    for check in summary.checks:
        verdict = "PASS" if check.passed else "FAIL"
        lines += fit(f"check {check.name}: {verdict} ({check.detail})", "    ")
    if summary.calibration is not None:
        lines += calibration_lines(summary.calibration, truth)
    return lines


def report_line(summary: RunSummary) -> str | None:
    """Where the calibration's report is, for a run that made a calibration.

    Meant for a run whose report was asked for: otherwise it says "not written".
    """
    if summary.calibration is None:
        return None
    return f"report: {summary.report}" if summary.report else "report: not written (see the log)"


def calibration_lines(outcome: CalibrationOutcome, truth: Truth | None = None) -> list[str]:
    """The hand-over, the solution and how it fares on the validation source."""
    solution, handover = outcome.solution, outcome.handover
    cycles = sum(len(v) for v in handover.cycles.values())
    lines = pack([
        f"hand-over: {handover.band_hz[0] / 1e6:g}-{handover.band_hz[1] / 1e6:g} MHz,",
        f"{len(handover.calibrators)} calibrators,", f"{cycles} Dicke cycles,",
        f"{len(handover.s11)} S11s", "(recorded in the run file)",
    ])
    corrections = corrections_line(handover.corrections)
    if corrections:
        lines += fit(f"  corrections: {corrections}", "    ")
    lines += solution_lines(solution)
    floor, predicted, name = outcome.floor_k, outcome.predicted_k, outcome.validation.name
    lines += pack([
        f"  on {name!r}: noise floor {1e3 * floor:.3f} mK,",
        f"predicted calibration std {1e3 * predicted:.3f} mK,",
        f"distance to floor {predicted / floor:.3f}",
    ])
    choice = model_choice_line(outcome.model_choice_share, name)
    if choice:
        lines += fit(f"  {choice}", "    ")
    if outcome.systematics is not None and outcome.systematic_k is not None:
        # The median beside the RMS: one channel where the calibrators' reflections line up
        # can hold most of the RMS.
        median = float(np.median(outcome.systematics.std_k(name)))
        lines += pack([
            f"  VNA systematic on {name!r}: {1e3 * outcome.systematic_k:.3f} mK RMS,",
            f"median {1e3 * median:.3f} mK", f"({outcome.systematics.describe()})",
        ])
    if truth is not None:
        errors = truth.calibration_errors_k(solution, outcome.data, outcome.validation)
        actual = float(np.sqrt(np.mean(errors**2)))
        lines += pack([
            "  actual calibration error against the simulator's truth:",
            f"{1e3 * actual:.3f} mK", f"= {actual / floor:.3f} x floor",
        ])
        if isinstance(solution, ChannelSolution):
            lines += per_channel_error_lines(outcome, errors)
    return lines


def solution_lines(solution: AnySolution) -> list[str]:
    """The solution's lines: its orders, or what a per-channel one has."""
    if isinstance(solution, ChannelSolution):
        numbers = solution.summary()
        lines = fit(
            f"solution: {method_name(solution)}, per channel ({numbers['n_channels']} channels, "
            f"{len(solution.calibrators)} calibrators; uncorrelated errors between channels)",
            "    ",
        )
        if numbers["log_evidence"] is not None:
            lines.append(
                f"  log evidence (sum over channels, eq. 4.22): {numbers['log_evidence']:.3f}"
            )
        return lines
    lines = [f"solution: orders {solution.best_orders} (T_unc, T_cos, T_sin, T_NS, T_L)"]
    models = solution.models_line()
    if models:
        pairs = models.split(", ")  # "(4,3,6,8,2) 0.093, ...": never a pair broken
        lines += pack([
            "  averaged over models (orders, weight):",
            *[f"{pair}," for pair in pairs[:-1]], pairs[-1],
        ])
    for line in caution_lines(solution):
        lines += fit(f"  {line}", "    ")
    lines.append(
        f"  noise scale s^2 {solution.posterior.noise_variance:.3f} (1 = radiometer equation)"
    )
    return lines


def per_channel_error_lines(outcome: CalibrationOutcome, errors: FloatArray) -> list[str]:
    """Each channel's error in units of its own floor, for a per-channel solution.

    Where the calibrators' reflections line up (all real at one frequency, so T_cos and
    T_sin cannot be told apart there), a channel's floor is hundreds of times the band's
    median, and that one channel decides both RMS values of the line above. The RMS of
    error / floor over the channels weighs each channel once; it is taken over the
    channels whose floor is within 10x the median, and the others' largest is shown
    apart: there the floor, a first-order error, is not the error's size (one such
    channel once took the RMS over 1229 channels from 1.02 to 1.17). The largest ratio
    among the channels counted is shown with its frequency: about 3-4 over a thousand
    channels of Gaussian errors, far more where one channel alone moves the RMS.
    """
    floor = outcome.floor_std_k
    ratio = np.abs(errors / floor)
    degenerate = floor > 10 * np.median(floor)
    rms = float(np.sqrt(np.mean(ratio[~degenerate] ** 2)))
    worst = int(np.argmax(np.where(degenerate, -np.inf, ratio)))
    chunks = [
        f"  per channel: RMS of error / floor {rms:.3f}",
        f"over {int(np.sum(~degenerate))} channels (largest {ratio[worst]:.2f} at "
        f"{outcome.data.freq_hz[worst] / 1e6:.3f} MHz)",
    ]
    if np.any(degenerate):
        chunks[-1] += ";"
        chunks += [
            f"{int(np.sum(degenerate))} with a floor over 10x the median,",
            f"largest error / floor {float(np.max(ratio[degenerate])):.3f}",
        ]
    return pack(chunks)
