"""Run the accuracy, speed, memory and spectra-rate benchmarks; print ratios from this run.

Usage (from the repository root, with the ``bench`` extra installed)::

    python -m benchmarks.run_all

Every number in the final summary was measured by this invocation; nothing is cached.
See ``benchmarks/README.md`` for what each number means.
"""

from __future__ import annotations

import platform
import time

import numpy as np

from benchmarks import accuracy, main_job, memory, model_choice, spectra_rate, speed


def main() -> int:
    """Run all the benchmarks; print the summary. Returns 0 (timings are not asserted)."""
    import edges_cal
    import scipy

    start = time.perf_counter()
    print(
        f"python {platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}, "
        f"edges-cal {edges_cal.__version__}, {platform.machine()}"
    )
    acc = accuracy.main()
    speeds = speed.main()
    mem = memory.main()
    rates = spectra_rate.main([])
    print("=" * 100)
    job = main_job.main(["--seeds", "3"])
    print("=" * 100)
    choices = model_choice.main(["--runs", "30"])
    print("=" * 100)
    print("SUMMARY (all measured in this run)")
    print("=" * 100)
    ours = acc.median_ratio(accuracy.RADIOMETRIC)
    print(
        f"  accuracy  median error/floor, ours            {ours:6.3f}   target <= "
        f"{accuracy.TARGET_RATIO}: {'PASS' if acc.passed else 'FAIL'}"
    )
    print(
        f"            median error/floor, thesis          {acc.median_ratio(accuracy.THESIS):6.3f}"
    )
    print(
        f"            median error/floor, edges-cal       "
        f"{acc.median_ratio(accuracy.EDGES):6.3f}   (4 loads; same 12-calibrator floor)"
    )
    print(
        f"            error ratio ours / edges-cal        "
        f"{acc.median_error(accuracy.RADIOMETRIC) / acc.median_error(accuracy.EDGES):6.3f}"
        "   (median errors)"
    )
    for result in speeds:
        print(
            f"  speed     ours {result.median(speed.OURS):6.3f} s, edges-cal "
            f"{result.median(speed.EDGES):6.3f} s, thesis {result.median(speed.THESIS):6.3f} s; "
            f"ours/edges-cal = {result.ratio_to_edges:5.2f}; target <= {speed.TARGET_SECONDS:g} s: "
            f"{'PASS' if result.passed else 'FAIL'}   [{result.label}]"
        )
    print(
        f"  memory    peak RSS {mem.peak_rss / memory.MB:6.1f} MB = {mem.ratio:.3f} x 500 MB "
        f"(solve's own allocations {mem.traced_peak / memory.MB:.1f} MB); "
        f"target <= 500 MB: {'PASS' if mem.passed else 'FAIL'}"
    )
    real_rate = spectra_rate.REAL_PACKETS_PER_S
    lossless = [r for r in rates if r.zero_loss and r.target_spectra_per_s > 0]
    best = max(lossless, key=lambda r: r.packets_per_s, default=None)
    if best is not None:
        at_100 = min(lossless, key=lambda r: abs(r.packets_per_s / real_rate - 100))
        passed = (
            best.packets_per_s >= spectra_rate.TARGET_RATIO * real_rate
            and at_100.cpu_fraction < 1.0
        )
        print(
            f"  spectra   {best.packets_per_s / real_rate:6.0f} x the real iTPM rate, zero loss "
            f"(best paced run); at ~100x the receiver used {at_100.cpu_fraction:.2f} core; "
            f"target >= {spectra_rate.TARGET_RATIO:g}x, < 1 core: "
            f"{'PASS' if passed else 'FAIL'}"
        )
    else:
        print("  spectra   no paced run was loss-free: FAIL")
    print(
        f"  main job  median {job.median_wall_s:5.1f} s wall (max {job.max_wall_s:.1f} s) for ten "
        f"simulated hours; target <= 60 s: {'PASS' if job.passed else 'FAIL'}; error bars: "
        f"actual/predicted RMS {job.honesty_rms:.2f} over {job.runs} seeds"
    )
    for name, tallies in choices.items():
        print(f"  model     {name}: averaged {tallies['averaged'].line()}; "
              f"true orders {tallies['true orders'].line()}")
    print(f"  total benchmark time {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
