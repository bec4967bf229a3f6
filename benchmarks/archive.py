"""Archive benchmark: a season of 10^5 spectra on Dask, 1 and 2 workers, rate and memory.

A simulated archive is written straight with h5py into a temporary directory (not
through the receiver, which would take hours): :data:`N_RUNS` receiver run files
(``format = "reach-receiver-run"``) of :data:`SPECTRA_PER_RUN` calibrated spectra of
:data:`N_CHANNELS` channels each (power-law sky, radiometer noise, a few flags), each
spectrum with its Dicke cycle's time stamps and the hand-over naming it, as the observe
step stores them: the layout :func:`calibration.io.calibrated_spectra.read_calibrated_spectra`
reads. 10^5 spectra of 1024 channels are 4.2 GB on disk; the files are deleted at the end.

The season (:func:`calibration.season.archive.season_on_dask`: read and bin in chunks,
tree of adds) is timed on local clusters of 1 and 2 worker processes (one thread each,
:data:`MEMORY_PER_WORKER` each; chunks of at most a quarter of it), each started before
its clock runs. Per worker: spectra per second (spectra / wall time / workers) and the
peak resident memory (``VmHWM``, reset when the worker is idle after start, so the
figure is the work's peak over the worker's idle footprint, which is printed too).
Ratios are against the 1-worker run of the same invocation. The two seasons must be
equal bit for bit (the reduction tree is fixed by the order of the runs).

Then a recalibration (:mod:`calibration.season.archive_apply`'s per-run task) of a small
archive made through the engine's simulation (real Dicke powers and S11s), timed per
spectrum on one worker, for the paper scaling of the README: the per-spectrum cost of
apply and flagging grows with the channels (the flagger's smooth fit), reading and
binning with the bytes.

    python -m benchmarks.archive [--runs N] [--spectra-per-run N] [--channels N]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from calibration.season.archive import Cluster, season_on_dask
from calibration.season.binning import lst_edges
from calibration.season.chunks import ROW_ARRAYS, rows_per_chunk

N_RUNS = 50
SPECTRA_PER_RUN = 2000
N_CHANNELS = 1024
MEMORY_PER_WORKER = 2**30
SITE = "site: {name: REACH Karoo, longitude_deg: 21.52, latitude_deg: -30.97}\n"
EPOCH = 1_709_251_200.0
GIB = 2**30
#: Channel widths of the recalibration timing: 1025 and 16385 channels over 50-130 MHz
#: (50 MHz a whole number of channels, as the spectrometer's grid k * width).
RECALIBRATION_WIDTHS_HZ = (78_125.0, 80e6 / 16384)


def write_archive_run(path: Path, seed: int, n: int, n_ch: int, night: int) -> None:
    """One run file of ``n`` calibrated spectra in the observe step's layout."""
    rng = np.random.default_rng(seed)
    freq = np.linspace(50e6, 130e6, n_ch)
    sky = 3000.0 * (freq / 75e6) ** -2.5
    radiometer = sky / np.sqrt(freq[1] - freq[0]) / np.sqrt(600.0)
    t0 = EPOCH + night * 86_164.0905
    with h5py.File(path, "w") as f:
        f.attrs.update(format="reach-receiver-run", format_version="1.0", name=path.parent.name)
        f.create_group("run").create_dataset("site", data=SITE)
        m = f.create_group("measurements")
        sol = m.create_group("000001_solution_radiometric")
        sol.attrs.update(kind="solution", name="radiometric", sequence=1, timestamp=t0)
        s = sol.create_group("solution")
        s.attrs["method"] = "radiometric"
        s.create_dataset("mean", data=rng.normal(size=20 + night))
        noise = rng.normal(size=(n, n_ch)) * radiometer
        flags = rng.random((n, n_ch)) < 0.002
        for i in range(n):
            t = t0 + 30.0 * i
            number = 2 + 2 * i
            d = m.create_group(f"{number:06d}_dicke_ant")
            d.attrs.update(kind="dicke", name="ant", sequence=number, timestamp=t)
            src = d.create_group("source")
            src.create_dataset("timestamps", data=[t - 5.0, t + 5.0])
            src.attrs.update(integration_s=10.0, n_spectra=1)
            c = m.create_group(f"{number + 1:06d}_calibrated_ant_{i:05d}")
            c.attrs.update(kind="calibrated", name=f"ant_{i:05d}", sequence=number + 1,
                           timestamp=t + 20.0,
                           handover=json.dumps({"cycles": {"ant": [number]}, "s11": {}}))
            c.create_dataset("frequencies", data=freq)
            c.create_dataset("mean", data=sky + noise[i])
            c.create_dataset("std", data=np.hypot(radiometer, 0.01 * sky))
            c.create_dataset("flags", data=flags[i])
            c.create_dataset("std_calibration", data=0.01 * sky)
            c.create_dataset("std_radiometer", data=radiometer)


def _reset_peak() -> int:
    """Reset this process's peak RSS mark; its resident memory now (bytes)."""
    Path("/proc/self/clear_refs").write_text("5")
    return _status("VmRSS")


def _status(key: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1]) * 1024
    return 0


def _peak() -> int:
    return _status("VmHWM")


def time_season(runs: list[str], workers: int) -> dict[str, Any]:
    """The season on a local cluster of ``workers`` processes: wall time, memory, result."""
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      memory_limit=MEMORY_PER_WORKER, dashboard_address=":0") as cluster, \
            Client(cluster) as client, open(os.devnull, "w") as quiet:  # not the table
        idle = client.run(_reset_peak)
        start = time.perf_counter()
        season = season_on_dask(Cluster(client, f"{workers} workers", workers,
                                        MEMORY_PER_WORKER), runs, lst_edges(1.0), quiet)
        wall = time.perf_counter() - start
        peaks = client.run(_peak)
    return {"wall": wall, "idle": max(idle.values()), "peak": max(peaks.values()),
            "season": season}


def write_recalibration_run(path: Path, sim: Any, n: int, rng: np.random.Generator) -> None:
    """A run of ``n`` antenna cycles with real simulated powers and the S11s, observe's layout."""
    from calibration.model.data import Integration
    from calibration.model.reflections import reach_source_reflection
    from calibration.model.simulate import simulate_source

    freq, width = sim.data.freq_hz, sim.data.channel_width_hz
    below = round(freq[0] / width)
    gamma = reach_source_reflection("ant", freq)
    sky = 3000.0 * (freq / 75e6) ** -2.5
    with h5py.File(path, "w") as f:
        f.attrs.update(format="reach-receiver-run", format_version="1.0", name="recal")
        f.create_group("run").create_dataset("site", data=SITE)
        m = f.create_group("measurements")
        for number, name, values in ((1, "ant", gamma), (2, "lna", sim.data.gamma_rec)):
            g = m.create_group(f"{number:06d}_s11_{name}")
            g.attrs.update(kind="s11", name=name, sequence=number, timestamp=EPOCH,
                           calibrated=True)
            g.create_dataset("frequencies", data=freq)
            g.create_dataset("s11", data=values)
        for i in range(n):
            ant = simulate_source("ant", freq, gamma, sim.gamma_rec_true, sky, sim.truth,
                                  Integration(600.0, 600.0, 600.0), width, rng,
                                  known_temperature=False)
            number, t = 3 + 2 * i, EPOCH + 1800.0 * i
            d = m.create_group(f"{number:06d}_dicke_ant")
            d.attrs.update(kind="dicke", name="ant", sequence=number, timestamp=t)
            for position, power in (("source", ant.p_source), ("load", ant.p_load),
                                    ("ns", ant.p_ns)):
                g = d.create_group(position)
                g.create_dataset("spectrum", data=np.concatenate([np.ones(below), power])[None])
                g.create_dataset("timestamps", data=[t - 5.0, t + 5.0])
                g.attrs.update(integration_s=600.0, n_spectra=1)
            c = m.create_group(f"{number + 1:06d}_calibrated_ant_{i:05d}")
            c.attrs.update(kind="calibrated", name=f"ant_{i:05d}", sequence=number + 1,
                           timestamp=t + 20.0, handover=json.dumps(
                               {"channel_width_hz": width, "cycles": {"ant": [number]},
                                "s11": {"ant": 1, "lna": 2}}))


def time_recalibration(n_spectra: int, width_hz: float) -> tuple[int, float]:
    """Channels, and seconds per spectrum of recalibrating a run (apply, flags, write)."""
    from calibration.choice.model_fit import OrderChoice
    from calibration.model.simulate import SimulationConfig, simulate_run
    from calibration.season.archive_apply import recalibrate_file
    from calibration.solve.solvers import solve

    sim = simulate_run(SimulationConfig(channel_width_hz=width_hz, integration_s=30.0), rng=1)
    solution = solve(sim.data, choice=OrderChoice.fixed((4, 4, 4, 4, 4)))
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run.h5"
        write_recalibration_run(run, sim, n_spectra, np.random.default_rng(0))
        start = time.perf_counter()
        recalibrate_file(str(run), str(Path(tmp) / "out" / "run.h5"), solution, "bench", 0.0,
                         False)
        return sim.data.freq_hz.size, (time.perf_counter() - start) / n_spectra


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=N_RUNS)
    parser.add_argument("--spectra-per-run", type=int, default=SPECTRA_PER_RUN)
    parser.add_argument("--channels", type=int, default=N_CHANNELS)
    parser.add_argument("--recalibrate-spectra", type=int, default=20)
    args = parser.parse_args(argv)
    n_total = args.runs * args.spectra_per_run
    root = Path(tempfile.mkdtemp(prefix="archive-bench-"))
    try:
        rng = np.random.default_rng(0)
        start = time.perf_counter()
        runs = [root / f"run{k:03d}" / "run.h5" for k in range(args.runs)]
        for path in runs:
            path.parent.mkdir()
        seeds = rng.integers(0, 2**32, size=args.runs)
        with ProcessPoolExecutor(max_workers=os.cpu_count()) as pool:
            list(pool.map(write_archive_run, runs, seeds, [args.spectra_per_run] * args.runs,
                          [args.channels] * args.runs, range(args.runs)))
        size = sum(os.path.getsize(r) for r in runs)
        names = [str(r) for r in runs]
        chunk = rows_per_chunk(args.channels, 0.25 * MEMORY_PER_WORKER)
        print(f"archive: {args.runs} runs x {args.spectra_per_run} spectra x {args.channels} "
              f"channels = {n_total} spectra, {size / 1e9:.2f} GB, written in "
              f"{time.perf_counter() - start:.0f} s")
        print(f"workers: {MEMORY_PER_WORKER / GIB:.1f} GiB memory limit each; chunks of "
              f"{chunk} spectra (model: {ROW_ARRAYS} arrays of a row's channels, "
              f"{chunk * ROW_ARRAYS * 8 * args.channels / 2**20:.0f} MiB a chunk)")
        results = {w: time_season(names, w) for w in (1, 2)}
        base = results[1]
        print(f"\n{'workers':>7} {'wall s':>8} {'spectra/s/worker':>17} {'ratio':>6} "
              f"{'idle MiB':>9} {'peak MiB/worker':>16} {'ratio':>6}")
        for w, r in results.items():
            rate = n_total / r["wall"] / w
            print(f"{w:>7} {r['wall']:>8.1f} {rate:>17.0f} "
                  f"{rate / (n_total / base['wall']):>6.2f} {r['idle'] / 2**20:>9.0f} "
                  f"{r['peak'] / 2**20:>16.0f} {r['peak'] / base['peak']:>6.2f}")
        same = all(
            np.array_equal(getattr(results[1]["season"], k), getattr(results[2]["season"], k),
                           equal_nan=True)
            for k in ("mean", "std_radiometer", "std_calibration", "weight", "count")
        )
        print(f"\nseasons on 1 and 2 workers bit for bit equal: {same}")
        if args.recalibrate_spectra:
            print("\nrecalibration (apply, flags, write), one worker:")
            for width in RECALIBRATION_WIDTHS_HZ:
                n_ch, per = time_recalibration(args.recalibrate_spectra, width)
                print(f"  {n_ch:>6} channels: {1e3 * per:7.0f} ms a spectrum "
                      f"({1 / per:.1f} spectra/s)")
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
