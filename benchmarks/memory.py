"""Memory benchmark: peak memory of the full solve + calibrate at 16384 channels.

The problem is the default run (12 calibrators) at 16384 channels over 50-130 MHz
(``channel_width_hz = 80 MHz / 16383``). It is measured in a fresh subprocess so that
nothing else this process did pollutes the numbers:

1. import numpy, scipy and :mod:`calibration`, simulate the run, collect garbage; read the
   resident set size (``VmRSS``) as the *baseline*;
2. reset the kernel's peak-RSS mark (``echo 5 > /proc/self/clear_refs``, Linux >= 4.0),
   run ``solve_radiometric(data)`` then ``solution.calibrate(...)`` of the validation
   source, and read the peak (``VmHWM``; ``ru_maxrss`` where the reset is unavailable);
3. run the same again under :mod:`tracemalloc`, which tracks numpy's allocations: its
   peak is the memory the solve and calibration themselves allocated.

Reported: the tracemalloc peak, the process's peak RSS, and that peak minus the baseline.
The verdict against the 500 MB target uses the whole process's peak RSS (interpreter,
libraries and data included), the most conservative of the three. For context, the
memory a dense ``N x N`` matrix of the ``N = 12 x 16384`` calibration rows would need is
printed too: the solvers never form it (they work on per-channel normal equations).
"""

from __future__ import annotations

import gc
import json
import os
import resource
import subprocess
import sys
import time
import tracemalloc
from dataclasses import dataclass
from pathlib import Path

#: Target of the issue (bytes): 500 MB.
TARGET_BYTES = 500e6
N_CHANNELS = 16384
BAND_HZ = (50e6, 130e6)
MB = 1e6


def _status_kb(field: str) -> int | None:
    """A ``kB`` field of ``/proc/self/status`` in bytes (``None`` off Linux)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def _reset_peak() -> bool:
    """Reset the peak-RSS mark of this process; ``False`` if the kernel refuses."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        return False
    hwm, rss = _status_kb("VmHWM"), _status_kb("VmRSS")
    return hwm is not None and rss is not None and hwm <= rss + 4 * 1024 * 1024


def _maxrss_bytes() -> int:
    """``ru_maxrss`` in bytes (kB on Linux, bytes on macOS)."""
    value = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(value if sys.platform == "darwin" else value * 1024)


def measure_here(seed: int = 0) -> dict[str, float | int | bool | str]:
    """Measure in this process (meant for a fresh subprocess, see :func:`run_memory`)."""
    import numpy as np  # noqa: F401  (imports are part of the baseline)
    import scipy.linalg  # noqa: F401

    from calibration.model.simulate import SimulationConfig, simulate_run
    from calibration.solve.radiometric_solver import solve_radiometric
    from calibration.solve.thesis_solver import solve_thesis

    f_lo, f_hi = BAND_HZ
    config = SimulationConfig(
        f_lo_hz=f_lo, f_hi_hz=f_hi, channel_width_hz=(f_hi - f_lo) / (N_CHANNELS - 1)
    )
    run = simulate_run(config, rng=seed)
    data = run.data

    def solve_and_calibrate() -> str:
        solution = solve_radiometric(data)
        solution.calibrate(data.freq_hz, data.gamma_rec, run.validation, data.channel_width_hz)
        return str(solution.best_orders)

    gc.collect()
    baseline_rss = _status_kb("VmRSS") or 0
    maxrss_before = _maxrss_bytes()
    reset = _reset_peak()
    start = time.perf_counter()
    orders = solve_and_calibrate()
    seconds = time.perf_counter() - start
    hwm = _status_kb("VmHWM")
    peak_rss = hwm if (reset and hwm is not None) else _maxrss_bytes()

    gc.collect()
    tracemalloc.start()
    solve_and_calibrate()
    traced_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()

    gc.collect()
    tracemalloc.start()
    solve_thesis(data).calibrate(data.freq_hz, data.gamma_rec, run.validation)
    thesis_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()

    return {
        "n_channels": data.n_channels,
        "n_calibrators": len(data.names),
        "orders": orders,
        "baseline_rss": baseline_rss,
        "maxrss_before": maxrss_before,
        "peak_rss": peak_rss,
        "peak_reset": reset,
        "traced_peak": traced_peak,
        "thesis_traced_peak": thesis_peak,
        "seconds": seconds,
    }


@dataclass(frozen=True)
class MemoryResult:
    """What the subprocess measured (bytes, except ``seconds``)."""

    n_channels: int
    n_calibrators: int
    orders: str
    baseline_rss: int
    maxrss_before: int
    peak_rss: int
    peak_reset: bool
    traced_peak: int
    thesis_traced_peak: int
    seconds: float

    @property
    def rss_delta(self) -> int:
        """Peak RSS during solve + calibrate above the baseline."""
        return self.peak_rss - self.baseline_rss

    @property
    def ratio(self) -> float:
        """Whole-process peak RSS over the 500 MB target."""
        return self.peak_rss / TARGET_BYTES

    @property
    def passed(self) -> bool:
        """Whether the whole process stayed within the target."""
        return self.peak_rss <= TARGET_BYTES

    @property
    def dense_bytes(self) -> int:
        """Bytes of a dense float64 ``N x N`` matrix, ``N`` = calibrators x channels."""
        n = self.n_calibrators * self.n_channels
        return 8 * n * n


def run_memory(seed: int = 0) -> MemoryResult:
    """Measure in a fresh subprocess (``python -m benchmarks.memory --worker``)."""
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks.memory", "--worker", str(seed)],
        check=True,
        capture_output=True,
        text=True,
        env=dict(os.environ),
    )
    return MemoryResult(**json.loads(out.stdout.strip().splitlines()[-1]))


def report(result: MemoryResult) -> None:
    """Print the measurements and the verdict."""
    n_rows = result.n_calibrators * result.n_channels
    print("=" * 100)
    print(
        f"MEMORY  solve_radiometric + calibrate, {result.n_calibrators} calibrators x "
        f"{result.n_channels} channels ({n_rows} rows), fresh subprocess"
    )
    print("=" * 100)
    print(f"  baseline RSS after imports + simulation          {result.baseline_rss / MB:8.1f} MB")
    print(
        f"  (ru_maxrss before the solve {result.maxrss_before / MB:.1f} MB: "
        "it may hold the parent's peak, inherited on fork)"
    )
    how = "VmHWM after reset" if result.peak_reset else "ru_maxrss, reset unavailable"
    peak = result.peak_rss / MB
    print(f"  peak RSS of the process during solve + calibrate {peak:8.1f} MB   ({how})")
    print(f"  peak RSS - baseline                              {result.rss_delta / MB:8.1f} MB")
    print(f"  tracemalloc peak of solve + calibrate            {result.traced_peak / MB:8.1f} MB")
    print(
        f"  (thesis solver + calibrate, tracemalloc peak     "
        f"{result.thesis_traced_peak / MB:8.1f} MB)"
    )
    verdict = "PASS" if result.passed else "FAIL"
    print(
        f"  ratio to 500 MB: whole process {result.ratio:.3f}, solve's own allocations "
        f"{result.traced_peak / TARGET_BYTES:.3f}; target <= 500 MB (whole process): {verdict}"
    )
    print(
        f"  for context: a dense {n_rows} x {n_rows} float64 matrix would need "
        f"{result.dense_bytes / 1e9:.1f} GB ({result.dense_bytes / 2**30:.1f} GiB)"
    )
    print(f"  (chosen orders {result.orders}; solve + calibrate took {result.seconds:.2f} s)")


def main() -> MemoryResult:
    """Run and print the memory benchmark."""
    result = run_memory()
    report(result)
    return result


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        print(json.dumps(measure_here(int(sys.argv[2]) if len(sys.argv) > 2 else 0)))
    else:
        main()
