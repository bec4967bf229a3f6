"""Report benchmark: the time of ``write_report`` on a simulated 12-calibrator run.

Run ``python -m benchmarks.report [--repeats 3]`` (about half a minute). It simulates the
default run (:class:`~calibration.model.simulate.SimulationConfig`: the twelve REACH
calibrators and the mock antenna, 6554 channels over 50-130 MHz, seed 1), writes it and
its solution to files, as ``reach-cal report`` and ``reach-run`` find them, and times,
each the median of ``--repeats`` in this process after one untimed report (the first
pays for matplotlib's imports and font cache, once per process):

* **report**: :func:`calibration.report.writer.write_report` with the run, all seven figures
  and the summary (target: under 3 s);
* **figures, fixed layout**: the figures alone as the report draws them (margins in
  inches, :func:`calibration.report.figures.style.grid`);
* **figures, constrained layout**: the same figures with matplotlib's constrained
  layout engine set before saving, as every figure was drawn before: the baseline;
* **solve**: :func:`~calibration.solve.radiometric_solver.solve_radiometric` on the run,
  for scale.

Wall times (``time.perf_counter``) and the process's CPU time are both printed: on a
loaded machine the CPU time is the steadier number.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from calibration.io.hdf5_io import write_run
from calibration.io.solution_file import write_solution
from calibration.model.simulate import SimulationConfig, simulate_run
from calibration.report import figures
from calibration.report.writer import calibrate_run, figure_builders, load_inputs, write_report
from calibration.solve.radiometric_solver import solve_radiometric

#: The issue's target for one report (s).
TARGET_S = 3.0


def timed(work: Callable[[], object], repeats: int) -> tuple[float, float]:
    """Median wall and CPU seconds of ``repeats`` calls of ``work``."""
    walls, cpus = [], []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        work()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return statistics.median(walls), statistics.median(cpus)


def draw_figures(solution: Path, run: Path, out: Path, constrained: bool) -> None:
    """Every figure of the report into ``out``, with constrained layout if asked."""
    inputs = load_inputs(solution, run)
    calibrated = calibrate_run(inputs)
    for stem, build in figure_builders(inputs, calibrated).items():
        fig = build()
        if constrained:
            fig.set_layout_engine("constrained")
        figures.save_png(fig, out / f"{stem}.png")


def main(argv: list[str] | None = None) -> dict[str, tuple[float, float]]:
    """Run the benchmark; print and return ``{name: (wall s, CPU s)}``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        simulated = simulate_run(SimulationConfig(), rng=1)
        run, solution_file = root / "run.h5", root / "solution.h5"
        write_run(run, simulated.data, {"ant": simulated.validation}, truth=simulated.truth)
        solution = solve_radiometric(simulated.data)
        write_solution(solution_file, solution)
        write_report(solution_file, root / "warm-up", run)  # imports, fonts: once a process
        for name in ("fixed", "constrained"):
            (root / name).mkdir()
        results = {
            "report": timed(lambda: write_report(solution_file, root / "report", run),
                            args.repeats),
            "figures, fixed layout": timed(
                lambda: draw_figures(solution_file, run, root / "fixed", False), args.repeats
            ),
            "figures, constrained layout": timed(
                lambda: draw_figures(solution_file, run, root / "constrained", True),
                args.repeats,
            ),
            "solve": timed(lambda: solve_radiometric(simulated.data), args.repeats),
        }
    print(f"report of a simulated run: {len(simulated.data.sources)} calibrators and the "
          f"antenna, {simulated.data.n_channels} channels; median of {args.repeats}")
    for name, (wall, cpu) in results.items():
        print(f"  {name:30s} {wall:6.2f} s wall  {cpu:6.2f} s CPU")
    fixed, constrained = results["figures, fixed layout"], results["figures, constrained layout"]
    report = results["report"][0]
    print(f"  constrained / fixed layout     {constrained[0] / fixed[0]:6.2f} x wall  "
          f"{constrained[1] / fixed[1]:6.2f} x CPU")
    print(f"  report / solve                 {report / results['solve'][0]:6.1f} x")
    print(f"  report under {TARGET_S:g} s: {'PASS' if report < TARGET_S else 'FAIL'}")
    return results


if __name__ == "__main__":
    main()
