"""Speed benchmark: wall time of a full calibration, ours against edges-cal.

Timed on one simulated run of the default configuration (12 calibrators x 6554 channels):

* ours: ``solve_radiometric(run.data)`` (order selection by evidence, posterior) followed
  by ``solution.calibrate(...)`` of the validation source (predictive mean and
  uncertainties). Target: <= 0.1 s (median), with model averaging, measured side by side
  with edges-cal.
* the thesis solver, the same way (``solve_thesis``).
* edges-cal's iterative method on its four loads (``solve_edges``, see
  :mod:`benchmarks.edges_cal_baseline`), followed by its calibration of the validation
  source; and, for a like-for-like comparison, ours on the same four loads.

Each is timed on :data:`RUNS` simulated runs, once to warm up and then ``repeats``
times on each; the median of all is reported. Times on a
shared machine are noisy: they are printed, never asserted.

The timings run in fresh subprocesses, twice: with the BLAS threading as installed
(OpenBLAS uses every core) and with ``OPENBLAS_NUM_THREADS=1`` (and the OMP/MKL
equivalents). On a 2-core machine that other processes keep busy, multi-threaded OpenBLAS
spin-waits for descheduled threads and every solver slows down several-fold; the
single-threaded numbers show the code's own speed. The radiometric solver runs its BLAS on
one thread whatever is installed (:mod:`calibration.core.blas_threads`): its thousands of small
calls were twice as slow on two threads, on an idle machine too.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from benchmarks.accuracy import FOUR_LOADS
from benchmarks.edges_cal_baseline import solve_edges
from calibration.model.simulate import SimulatedRun, SimulationConfig, simulate_run
from calibration.regression.conjugate import CoefficientPrior
from calibration.solve.radiometric_solver import RadiometricPrior, solve_radiometric
from calibration.solve.thesis_solver import solve_thesis

#: Target for our full solve + calibrate with model averaging, 12 cal x 6554 channels (s).
TARGET_SECONDS = 0.1
REPEATS = 3
#: Simulated runs (seeds ``seed`` to ``seed + RUNS - 1``) each workload is timed on.
RUNS = 5

OURS = "ours: solve_radiometric + calibrate (12 cal)"
OURS_BEST = "ours, single best model (average=False)"
OURS_FIXED = "ours, fixed 3000 K prior (the earlier default)"
THESIS = "thesis: solve_thesis + calibrate (12 cal)"
EDGES = "edges-cal iterative + calibrate (4 loads)"
OURS_4 = "ours: solve_radiometric + calibrate (4 loads)"


def time_call(fn: Callable[[], object], repeats: int = REPEATS) -> list[float]:
    """Wall times of ``repeats`` calls after one warm-up call (s)."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return times


def workloads(run: SimulatedRun) -> dict[str, Callable[[], object]]:
    """The timed calls, each a full calibration of the validation source."""
    data = run.data
    data4 = data.subset(FOUR_LOADS)
    freq, gamma_rec, width = data.freq_hz, data.gamma_rec, data.channel_width_hz

    def ours() -> object:
        return solve_radiometric(data).calibrate(freq, gamma_rec, run.validation, width)

    def ours_best() -> object:
        solution = solve_radiometric(data, average=False)
        return solution.calibrate(freq, gamma_rec, run.validation, width)

    def ours_fixed() -> object:
        fixed = RadiometricPrior(coefficients=CoefficientPrior())
        solution = solve_radiometric(data, prior=fixed, average=False)
        return solution.calibrate(freq, gamma_rec, run.validation, width)

    def ours4() -> object:
        return solve_radiometric(data4).calibrate(freq, gamma_rec, run.validation, width)

    def thesis() -> object:
        return solve_thesis(data).calibrate(freq, gamma_rec, run.validation, width)

    def edges() -> object:
        return solve_edges(data4).calibrate(run.validation)

    return {
        OURS: ours, OURS_BEST: ours_best, OURS_FIXED: ours_fixed, THESIS: thesis, EDGES: edges,
        OURS_4: ours4,
    }


#: Environment variables that pin the BLAS libraries to one thread.
SINGLE_THREAD_ENV = {
    "OPENBLAS_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}


@dataclass(frozen=True)
class SpeedResult:
    """Wall times of every workload (s), with the problem size and the threading label."""

    times: dict[str, list[float]]
    n_channels: int
    n_calibrators: int
    label: str = "BLAS threads as installed"

    def median(self, name: str) -> float:
        """Median wall time (s)."""
        return float(np.median(self.times[name]))

    @property
    def ratio_to_edges(self) -> float:
        """Our median time over edges-cal's."""
        return self.median(OURS) / self.median(EDGES)

    @property
    def passed(self) -> bool:
        """Whether our median time meets :data:`TARGET_SECONDS`."""
        return self.median(OURS) <= TARGET_SECONDS


def run_speed_here(repeats: int = REPEATS, seed: int = 0) -> SpeedResult:
    """Time every workload on :data:`RUNS` simulated default runs, in this process.

    Several runs, because the time depends on the data: a run whose evidence wants more
    terms than the first order limits (seed 0: T_sin at 8 terms) is solved twice over.
    """
    times: dict[str, list[float]] = {}
    for k in range(RUNS):
        run = simulate_run(SimulationConfig(), rng=seed + k)
        for name, fn in workloads(run).items():
            times.setdefault(name, []).extend(time_call(fn, repeats))
    return SpeedResult(times, run.data.n_channels, len(run.data.names))


def run_speed(single_thread: bool, repeats: int = REPEATS, seed: int = 0) -> SpeedResult:
    """Time every workload in a fresh subprocess (BLAS pinned to one thread or not)."""
    env = dict(os.environ)
    if single_thread:
        env.update(SINGLE_THREAD_ENV)
        label = "BLAS pinned to 1 thread (OPENBLAS/OMP/MKL_NUM_THREADS=1)"
    else:
        pinned = os.environ.get("OPENBLAS_NUM_THREADS")
        label = "BLAS threads as installed" + (
            f" (OPENBLAS_NUM_THREADS={pinned} inherited)" if pinned else ""
        )
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks.speed", "--worker", str(repeats), str(seed)],
        env=env,
        check=True,
        capture_output=True,
        text=True,
    )
    payload = json.loads(out.stdout.strip().splitlines()[-1])
    return SpeedResult(payload["times"], payload["n_channels"], payload["n_calibrators"], label)


def report(result: SpeedResult) -> None:
    """Print the times and the ratio."""
    print(
        f"-- {result.label}: median of {len(next(iter(result.times.values())))} timings "
        f"({RUNS} runs x {REPEATS}, each after a warm-up); load average now "
        f"{os.getloadavg()[0]:.2f}"
    )
    for name, times in result.times.items():
        print(
            f"  {name:46s} median {1e3 * result.median(name):8.1f} ms   "
            f"(min {1e3 * min(times):7.1f}, max {1e3 * max(times):7.1f})"
        )
    verdict = "PASS" if result.passed else "FAIL"
    print(f"  ours: {result.median(OURS):.3f} s, target <= {TARGET_SECONDS:.1f} s: {verdict}")
    print(
        f"  ratio ours (12 cal) / edges-cal (4 loads) = {result.ratio_to_edges:.2f}; "
        f"ours (4 loads) / edges-cal (4 loads) = "
        f"{result.median(OURS_4) / result.median(EDGES):.2f}"
    )
    print(
        f"  ratio ours (averaged) / single best model = "
        f"{result.median(OURS) / result.median(OURS_BEST):.2f}; / fixed 3000 K prior = "
        f"{result.median(OURS) / result.median(OURS_FIXED):.2f}"
    )


def main() -> tuple[SpeedResult, SpeedResult]:
    """Run and print the speed benchmark: as installed, then single-threaded BLAS."""
    results = (run_speed(single_thread=False), run_speed(single_thread=True))
    print("=" * 100)
    print(
        f"SPEED  {results[0].n_calibrators} calibrators x {results[0].n_channels} channels "
        f"(order selection + posterior + predictive); {os.cpu_count()} CPUs"
    )
    print("=" * 100)
    for result in results:
        report(result)
    return results


def _worker(argv: list[str]) -> None:
    repeats, seed = (int(a) for a in argv[:2])
    result = run_speed_here(repeats, seed)
    print(
        json.dumps(
            {
                "times": result.times,
                "n_channels": result.n_channels,
                "n_calibrators": result.n_calibrators,
            }
        )
    )


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        _worker(sys.argv[2:])
    else:
        main()
