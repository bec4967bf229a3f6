"""Adaptive calibration against the fixed round-robin: instrument time to a target error.

Run ``python -m benchmarks.adaptive [--runs 20] [--seed 0] [--target-fraction 0.4]
[--antenna-k 298] [--antenna-index 0]`` (24-38 s a run on a shared two-core machine,
about 10 minutes for 20 runs), or ``--coverage --runs 200 --target-fraction 0.6`` for the
coverage of the adaptive runs' final intervals (7-11 s a run, 23-37 minutes).

Each run draws a truth (:mod:`benchmarks.model_choice`'s random truths: random orders 1-6
and term sizes 0.3-30 posterior sd), REACH's twelve calibrators and the antenna's
reflection from the simulator, at 820 channels (the same physics as 6554: the
calibration error depends on the band's total information, not its channelisation). The
target is ``--target-fraction`` of the antenna's predicted error after the first pass
(``--target-mk`` for a fixed one), the same for both schedules:

* adaptive: a first pass of 60 s per Dicke position over every calibrator, then
  :class:`~calibration.design.adaptive.AdaptivePlanner`'s choices until it predicts the
  target;
* round-robin: passes of 60 s per position over the same calibrators in a fixed order,
  the same 10 s overhead per measurement, stopped after the first measurement at which the
  same prediction reaches the target (the finest a fixed schedule could stop).

"t more seconds on source i" is a new Dicke cycle drawn from the truth with that
integration, averaged with the earlier ones by integration time
(:class:`~calibration.design.simulated.SimulatedReceiver`). Both end with the default
solve; the actual error is the RMS over the band of the noiseless antenna's calibrated
minus true temperature (the calibration error alone). Printed: the median time ratio
(round-robin / adaptive) with its quartiles and range, each schedule's actual error and
its ratio to the predicted at the stop. ``--coverage``: per run, 8 channels of the final
solve's 68/95 % intervals (calibration part) hold the truth or not; the fractions over
all runs, with the same of the round-robin's final solve at the adaptive run's time as
the baseline.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np

from benchmarks.model_choice import Ensemble, draw_truth, pilot_sd
from calibration.core.errors import CalibrationError
from calibration.design.adaptive import AdaptivePlanner, AdaptiveSettings
from calibration.design.simulated import SimulatedReceiver
from calibration.model.simulate import REACH_CALIBRATORS, SimulationConfig
from calibration.solve.radiometric_solver import solve_radiometric

ENSEMBLE = Ensemble("random truths, 12 cal", REACH_CALIBRATORS)
FIRST_PASS_S = 60.0
OVERHEAD_S = 10.0
COVERAGE_CHANNELS = 8
#: The antenna's assumed temperature: the settings of the run (``--antenna-k`` at 75 MHz,
#: ``--antenna-index``; by default the simulator's ambient ``ant``, 298 K and flat).
ANTENNA = [AdaptiveSettings()]


@dataclass
class Outcome:
    """One schedule's end: instrument time, predicted and actual error, coverage."""

    time_s: float
    predicted_mk: float
    actual_mk: float
    inside_68: int
    inside_95: int
    measurements: int


def finish(rx: SimulatedReceiver, elapsed: float, predicted: float, n: int) -> Outcome:
    """The default solve of what ``rx`` measured, against the truth."""
    data = rx.data()
    truth = ANTENNA[0].antenna_temperatures(data.freq_hz)
    cal = solve_radiometric(data).calibrate(data.freq_hz, data.gamma_rec, rx.antenna(truth))
    channels = np.linspace(0, data.freq_hz.size - 1, COVERAGE_CHANNELS).astype(int)
    inside = [
        int(np.sum(cal.covers(truth, level, calibration_only=True)[channels]))
        for level in (0.68, 0.95)
    ]
    actual = 1e3 * float(np.sqrt(np.mean((cal.mean - truth) ** 2)))
    return Outcome(elapsed, predicted, actual, inside[0], inside[1], n)


def adaptive(
    config: SimulationConfig, rng: np.random.Generator, settings: AdaptiveSettings,
    fraction: float | None,
) -> tuple[Outcome, AdaptiveSettings]:
    """The adaptive schedule to its target (``fraction`` of the first prediction)."""
    rx = SimulatedReceiver(config, rng)
    planner = AdaptivePlanner(settings, rx.antenna_s11)
    elapsed, n = 0.0, 0
    for name, seconds in planner.first_pass(config.calibrators):
        rx.measure(name, seconds)
        elapsed += settings.cost_s(seconds)
        n += 1
    if fraction is not None:  # the target from the first pass's prediction
        first = planner.predict_mk(rx.data())
        settings = AdaptiveSettings(**{**settings.__dict__, "target_mk": fraction * first})
        planner = AdaptivePlanner(settings, rx.antenna_s11)
    while True:
        decision = planner.decide(rx.data(), elapsed)
        if decision.choice is None:
            return finish(rx, elapsed, decision.predicted_mk, n), settings
        rx.measure(decision.choice.source, decision.choice.seconds)
        elapsed += settings.cost_s(decision.choice.seconds)
        n += 1


def round_robin(
    config: SimulationConfig, rng: np.random.Generator, settings: AdaptiveSettings,
    stop_at_s: float | None = None,
) -> Outcome:
    """Passes of ``first_pass_s`` over the calibrators until the prediction reaches the target.

    ``stop_at_s``: stop instead at the first measurement reaching that instrument time.
    """
    rx = SimulatedReceiver(config, rng)
    planner = AdaptivePlanner(settings, rx.antenna_s11)
    elapsed, n, predicted = 0.0, 0, float("inf")
    target = settings.target_mk or 0.0
    while True:
        for name in config.calibrators:
            rx.measure(name, settings.first_pass_s)
            elapsed += settings.cost_s(settings.first_pass_s)
            n += 1
            if n < len(config.calibrators):
                continue
            if stop_at_s is not None:
                if elapsed >= stop_at_s:
                    return finish(rx, elapsed, planner.predict_mk(rx.data()), n)
                continue
            predicted = planner.predict_mk(rx.data())
            if predicted <= target or elapsed >= settings.budget_s:
                return finish(rx, elapsed, predicted, n)


def quartiles(values: list[float]) -> str:
    """Median [25-75 %] (min-max)."""
    q = np.percentile(values, [0, 25, 50, 75, 100])
    return f"{q[2]:.2f} [{q[1]:.2f}-{q[3]:.2f}] ({q[0]:.2f}-{q[4]:.2f})"


def main(argv: list[str] | None = None) -> dict[str, float]:
    """Run the comparison (or the coverage) and print the table."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.adaptive", description=__doc__)
    p.add_argument("--runs", type=int, default=20)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--target-fraction", type=float, default=0.4)
    p.add_argument("--target-mk", type=float, default=None, help="a fixed target instead")
    p.add_argument("--coverage", action="store_true", help="coverage of the final intervals")
    p.add_argument(
        "--antenna-k", type=float, default=298.0, help="antenna temperature at 75 MHz, K"
    )
    p.add_argument(
        "--antenna-index", type=float, default=0.0,
        help="its spectral index (0: a flat load; about -2.5: the sky)",
    )
    args = p.parse_args(argv)
    fraction = None if args.target_mk is not None else args.target_fraction
    base = AdaptiveSettings(
        target_mk=args.target_mk, budget_s=400_000.0, first_pass_s=FIRST_PASS_S,
        overhead_s=OVERHEAD_S, antenna_temperature_k=args.antenna_k,
        antenna_index=args.antenna_index,
    )
    ANTENNA[0] = base
    sd = pilot_sd(ENSEMBLE)
    rng = np.random.default_rng(args.seed)
    rows: list[tuple[Outcome, Outcome]] = []
    start = time.perf_counter()
    for _ in range(args.runs):
        config = ENSEMBLE.config(draw_truth(ENSEMBLE, sd, rng))
        seeds = rng.integers(2**32, size=2)
        try:
            ada, settings = adaptive(config, np.random.default_rng(seeds[0]), base, fraction)
            if args.coverage:
                rr = round_robin(config, np.random.default_rng(seeds[1]), settings, ada.time_s)
            else:
                rr = round_robin(config, np.random.default_rng(seeds[1]), settings)
        except CalibrationError as err:
            print(f"skipped a run: {err}")
            continue
        rows.append((ada, rr))
        if args.coverage and len(rows) % 50 == 0:  # progress: the adaptive runs' so far
            total = COVERAGE_CHANNELS * len(rows)
            print(
                f"{len(rows)} runs: adaptive inside 68 % "
                f"{100 * sum(r[0].inside_68 for r in rows) / total:.1f}, 95 % "
                f"{100 * sum(r[0].inside_95 for r in rows) / total:.1f}", flush=True,
            )
    wall = time.perf_counter() - start
    n = len(rows)
    print(
        f"{n} runs, antenna at {args.antenna_k:g} K at 75 MHz, index {args.antenna_index:g}, "
        f"{wall:.0f} s ({wall / max(n, 1):.1f} s a run)"
    )
    if args.coverage:
        total = COVERAGE_CHANNELS * n
        out = {}
        print("schedule      inside 68 %   inside 95 %   actual/predicted (median)")
        for k, name in enumerate(("adaptive", "round-robin")):
            c68 = 100 * sum(r[k].inside_68 for r in rows) / total
            c95 = 100 * sum(r[k].inside_95 for r in rows) / total
            ratio = np.median([r[k].actual_mk / r[k].predicted_mk for r in rows])
            print(f"{name:<12}  {c68:9.1f}     {c95:9.1f}     {ratio:.3f}")
            out[f"{name} 68"], out[f"{name} 95"] = c68, c95
        return out
    ratio = [r[1].time_s / r[0].time_s for r in rows]
    print("time to target, round-robin / adaptive: " + quartiles(ratio))
    for k, name in enumerate(("adaptive", "round-robin")):
        print(
            f"{name:<12} time (h) {quartiles([r[k].time_s / 3600 for r in rows])}; "
            f"actual (mK) {quartiles([r[k].actual_mk for r in rows])}; "
            f"actual/predicted {quartiles([r[k].actual_mk / r[k].predicted_mk for r in rows])}; "
            f"measurements {np.median([r[k].measurements for r in rows]):.0f}"
        )
    return {"median ratio": float(np.median(ratio))}


if __name__ == "__main__":
    main()
