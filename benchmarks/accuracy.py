"""Accuracy benchmark: calibration error against the radiometer noise floor.

For each simulated run (default :class:`~calibration.model.simulate.SimulationConfig`: 12
calibrators, 50-130 MHz, 6554 channels, 600 s per Dicke position; seeds 0..19):

* ``error`` = RMS over channels of (calibrated temperature of the *noiselessly* measured
  validation source ``run.validation_noiseless`` minus its true temperature), so the
  number measures the calibration alone, not the validation source's own noise;
* ``floor`` = ``noise_floor(run.data, run.validation_noiseless, run.truth.parameters).rms``,
  the Cramer-Rao limit of that error for the full 12-calibrator run at the true orders.

The benchmark prints the median over runs of ``error / floor`` for the default solver
(target <= 1.05), the thesis solver, edges-cal's iterative method on its four loads and,
for context, the default solver restricted to the same four loads. Every ratio uses the
*same* 12-calibrator floor as denominator; the four-load floors are printed alongside.

A noiseless run (``rng=None``) first checks the adapters: every method must then recover
the validation source to ~0 error.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from benchmarks.edges_cal_baseline import CTERMS, EDGES_LOADS, WTERMS, solve_edges
from calibration.model.data import CalibrationData
from calibration.model.polynomial_model import Orders, PolynomialParameters, coefficient_slices
from calibration.model.simulate import SimulatedRun, SimulationConfig, simulate_run
from calibration.solve.noise_floor import noise_floor
from calibration.solve.radiometric_solver import solve_radiometric
from calibration.solve.solution import Solution
from calibration.solve.thesis_solver import solve_thesis

FloatArray = NDArray[np.float64]

#: Target of the issue: median error / floor of the default solver.
TARGET_RATIO = 1.05
#: Seeds of the simulated runs.
DEFAULT_SEEDS: tuple[int, ...] = tuple(range(50))
#: The four EDGES loads as REACH calibrator names.
FOUR_LOADS: tuple[str, ...] = tuple(EDGES_LOADS.values())
#: edges-cal's model as our orders (unc, cos, sin, NS, L): ``T_NS = t_load_ns C1`` and
#: ``T_L = t_load - C2`` are ``cterms``-term polynomials, the noise waves ``wterms``.
EDGES_ORDERS: Orders = (WTERMS, WTERMS, WTERMS, CTERMS, CTERMS)

#: Method labels, in print order.
RADIOMETRIC = "ours: solve_radiometric (12 cal)"
THESIS = "thesis: solve_thesis (12 cal)"
EDGES = "edges-cal iterative (4 loads)"
RADIOMETRIC_4 = "ours: solve_radiometric (4 loads)"
METHODS: tuple[str, ...] = (RADIOMETRIC, THESIS, EDGES, RADIOMETRIC_4)


def rms(x: FloatArray) -> float:
    """Root mean square over channels."""
    return float(np.sqrt(np.mean(np.square(x))))


def calibrate_ours(solution: Solution, run: SimulatedRun) -> FloatArray:
    """Calibrated temperature of the noiseless validation source (solution + predictive)."""
    data = run.data
    spectrum = solution.calibrate(
        data.freq_hz, data.gamma_rec, run.validation_noiseless, data.channel_width_hz
    )
    return spectrum.mean


def calibrate_edges(data: CalibrationData, run: SimulatedRun) -> FloatArray:
    """Calibrated validation temperature by edges-cal on the four loads of ``data``."""
    return solve_edges(data.subset(FOUR_LOADS)).calibrate(run.validation_noiseless)


def padded(parameters: PolynomialParameters, orders: Sequence[int]) -> PolynomialParameters:
    """The same polynomials written with more terms (zero higher coefficients)."""
    coefficients = np.zeros(sum(orders))
    new = coefficient_slices(orders)
    for old, s in zip(coefficient_slices(parameters.orders), new, strict=True):
        if old.stop - old.start > s.stop - s.start:
            raise ValueError(f"cannot pad orders {parameters.orders} to {tuple(orders)}")
        coefficients[s.start : s.start + old.stop - old.start] = parameters.coefficients[old]
    return PolynomialParameters(parameters.basis, tuple(orders), coefficients)  # type: ignore[arg-type]


@dataclass(frozen=True)
class RunResult:
    """Errors of every method on one run, with the floors (all in K)."""

    seed: int | None
    floor: float
    floor_4_loads: float
    floor_4_loads_edges_model: float
    errors: dict[str, float]
    orders: Orders
    truth_orders: Orders
    thesis_orders: Orders
    seconds: float

    def ratio(self, method: str) -> float:
        """``error / floor`` with the 12-calibrator floor."""
        return self.errors[method] / self.floor


def evaluate_run(run: SimulatedRun, seed: int | None = None) -> RunResult:
    """Calibrate ``run``'s noiseless validation source with every method."""
    start = time.perf_counter()
    truth_t = run.validation_temperature_k
    data4 = run.data.subset(FOUR_LOADS)
    ours = solve_radiometric(run.data)
    thesis = solve_thesis(run.data)
    ours4 = solve_radiometric(data4)
    estimates: dict[str, Callable[[], FloatArray]] = {
        RADIOMETRIC: lambda: calibrate_ours(ours, run),
        THESIS: lambda: calibrate_ours(thesis, run),
        EDGES: lambda: calibrate_edges(run.data, run),
        RADIOMETRIC_4: lambda: calibrate_ours(ours4, run),
    }
    errors = {name: rms(estimate() - truth_t) for name, estimate in estimates.items()}
    truth = run.truth.parameters
    src = run.validation_noiseless
    return RunResult(
        seed=seed,
        floor=noise_floor(run.data, src, truth).rms,
        floor_4_loads=noise_floor(data4, src, truth).rms,
        floor_4_loads_edges_model=noise_floor(data4, src, padded(truth, EDGES_ORDERS)).rms,
        errors=errors,
        orders=ours.best_orders,
        truth_orders=truth.orders,
        thesis_orders=thesis.orders,
        seconds=time.perf_counter() - start,
    )


@dataclass(frozen=True)
class AccuracyResult:
    """Per-run results, the noiseless sanity check and the medians."""

    runs: list[RunResult]
    sanity: RunResult
    config: SimulationConfig = field(default_factory=SimulationConfig)

    def median_ratio(self, method: str) -> float:
        """Median over runs of ``error / floor`` (12-calibrator floor)."""
        return float(np.median([r.ratio(method) for r in self.runs]))

    def rms_ratio(self, method: str) -> float:
        """RMS over runs of the error, over the floor: 1 for an efficient estimator."""
        return float(np.sqrt(np.mean([r.ratio(method) ** 2 for r in self.runs])))

    def median_interval(self, method: str, n_boot: int = 2000) -> tuple[float, float]:
        """Bootstrap 16th-84th percentile interval of the median ratio (its run-to-run scatter)."""
        ratios = np.array([r.ratio(method) for r in self.runs])
        rng = np.random.default_rng(12345)
        picks = rng.integers(0, ratios.size, size=(n_boot, ratios.size))
        medians = np.median(ratios[picks], axis=1)
        lo, hi = np.percentile(medians, [16, 84])
        return float(lo), float(hi)

    def median_error(self, method: str) -> float:
        """Median over runs of the error (K)."""
        return float(np.median([r.errors[method] for r in self.runs]))

    @property
    def passed(self) -> bool:
        """Whether the default solver meets :data:`TARGET_RATIO`."""
        return self.median_ratio(RADIOMETRIC) <= TARGET_RATIO


def run_accuracy(
    seeds: Sequence[int] = DEFAULT_SEEDS, config: SimulationConfig | None = None
) -> AccuracyResult:
    """Evaluate every method on a noiseless run and on one run per seed."""
    config = config or SimulationConfig()
    sanity = evaluate_run(simulate_run(config, rng=None), seed=None)
    runs = [evaluate_run(simulate_run(config, rng=seed), seed=seed) for seed in seeds]
    return AccuracyResult(runs=runs, sanity=sanity, config=config)


def _mk(x: float) -> str:
    return f"{1e3 * x:8.3f}"


def report(result: AccuracyResult) -> None:
    """Print the sanity check, the per-run table and the medians."""
    cfg = result.config
    n = len(result.runs)
    n_channels = cfg.frequencies().size
    print("=" * 100)
    print(
        f"ACCURACY  {n} runs, {len(cfg.calibrators)} calibrators, "
        f"{cfg.f_lo_hz / 1e6:.0f}-{cfg.f_hi_hz / 1e6:.0f} MHz, {n_channels} channels, "
        f"{cfg.integration_s:.0f} s per Dicke position"
    )
    print(
        "error = RMS over channels of (calibrated noiseless validation source - truth); "
        "floor = Cramer-Rao RMS"
    )
    print("=" * 100)
    s = result.sanity
    print("Sanity check, noiseless calibration data (rng=None): every error should be ~0")
    for name in METHODS:
        print(f"  {name:36s} error = {s.errors[name]:.3e} K   error/floor = {s.ratio(name):.2e}")
    print(f"  (floor of that run, 12 cal: {1e3 * s.floor:.3f} mK)")
    print()
    print("Per run: floors in mK, then error/floor (denominator: the 12-calibrator floor)")
    header = (
        f"{'seed':>4} {'floor12':>8} {'floor4':>8} {'floor4E':>8} | {'ours':>6} {'thesis':>6} "
        f"{'edges':>6} {'ours4':>6} | orders chosen (truth)"
    )
    print(header)
    for r in result.runs:
        mark = "" if r.orders == r.truth_orders else "  <- differs"
        print(
            f"{r.seed:>4} {_mk(r.floor)} {_mk(r.floor_4_loads)} "
            f"{_mk(r.floor_4_loads_edges_model)} | "
            + " ".join(f"{r.ratio(m):6.3f}" for m in METHODS)
            + f" | {r.orders} ({r.truth_orders}){mark}"
        )
    print()
    print(f"Median over {n} runs (error/floor uses the same 12-calibrator floor for every method):")
    for name in METHODS:
        line = (
            f"  {name:36s} median error = {1e3 * result.median_error(name):7.3f} mK   "
            f"median error/floor = {result.median_ratio(name):6.3f}   "
            f"(RMS over runs: {result.rms_ratio(name):6.3f})"
        )
        if name == RADIOMETRIC:
            verdict = "PASS" if result.passed else "FAIL"
            line += f"   target <= {TARGET_RATIO}: {verdict}"
        print(line)
    lo, hi = result.median_interval(RADIOMETRIC)
    print(
        f"  ours: bootstrap 68% interval of the median ratio over these {n} runs: "
        f"[{lo:.3f}, {hi:.3f}] (run-to-run scatter; the 1.05 verdict is only that precise)"
    )
    med = {
        "floor": np.median([r.floor for r in result.runs]),
        "floor4": np.median([r.floor_4_loads for r in result.runs]),
        "floor4E": np.median([r.floor_4_loads_edges_model for r in result.runs]),
    }
    edges_vs_own = np.median([r.errors[EDGES] / r.floor_4_loads_edges_model for r in result.runs])
    ours4_vs_own = np.median([r.errors[RADIOMETRIC_4] / r.floor_4_loads for r in result.runs])
    print(
        f"  median floors: floor12 = {1e3 * med['floor']:.3f} mK (12 calibrators, true orders); "
        f"floor4 = {1e3 * med['floor4']:.3f} mK (4 loads, true orders);"
    )
    print(
        f"                 floor4E = {1e3 * med['floor4E']:.3f} mK (4 loads, edges-cal's model "
        f"orders {EDGES_ORDERS} = wterms x3, cterms x2)"
    )
    print(
        f"  against their own 4-load floors: edges-cal error/floor4E = {edges_vs_own:.3f}, "
        f"ours (4 loads) error/floor4 = {ours4_vs_own:.3f}"
    )
    chosen = sum(r.orders == r.truth_orders for r in result.runs)
    thesis_chosen = sum(r.thesis_orders == r.truth_orders for r in result.runs)
    print(
        f"  orders: ours chose the truth orders in {chosen}/{n} runs, "
        f"the thesis solver in {thesis_chosen}/{n}"
    )
    print(f"  ({sum(r.seconds for r in result.runs):.1f} s for the {n} runs, all methods)")


def main() -> AccuracyResult:
    """Run and print the accuracy benchmark."""
    result = run_accuracy()
    report(result)
    return result


if __name__ == "__main__":
    main()
