"""A simulated week of ``reachd --sim`` on its timers, then ``reach-cal season`` over its runs.

The site file gives ``reachd --sim`` four timers a sidereal day, 6 h apart (thesis 2.1.3:
a receiver calibration every 6 h): the first ``--observing`` of them, the LST window,
run the shipped ``observe.yaml`` (its calibration, then ``--cycles`` antenna Dicke cycles,
each calibrated at once with that calibration), the others the shipped
``calibrate.yaml``. Both are shortened through their own variables and the site's band
(four calibrators, the band ``--band-mhz``), and observe's ``wait`` for an LST is left
out: its timer is the window. The week runs at ``--compression`` (simulated seconds per
real second); the runs' own computing is real time, so the compression is chosen for the
day's runs to fit in a day. After ``--days`` simulated days the daemon stops (a run
still going is stopped and left out) and ``reach-cal season`` bins the completed
observing runs (``--lst-bin-h``).

The simulator's sky is :meth:`reach_receiver.sim.physics.ReceiverPhysics.sky_temperature_k`,
a power law that is the same at every LST, so each bin's truth is known without recording
anything. With ``T_b`` a bin's average, ``s_b`` its stated error (radiometer and
calibration parts in quadrature, :mod:`calibration.season.binning`)::

    z = (T_b - T_sky) / s_b,     RMS over channels, bins and seeds: 1 +- 0.1

and each part against a Monte Carlo of its own source, per run file (one solution):

* radiometer: every cycle is a new draw of radiometer noise while the run's calibration
  error (and its S11s' trace noise) is shared, so the scatter of a run's cycles about
  their weighted mean, ``chi2 = sum_i w_i (T_i - T_run)^2`` with ``w_i = 1 / r_i^2``, has
  ``n - 1`` degrees of freedom per channel when the stated ``r_i`` are right;
  ``ratio_r = sum chi2 / sum (n - 1)`` is actual over stated variance.
* calibration: every run is a new calibration (new calibrator noise); its weighted mean
  residual ``T_run - T_sky`` has the variance ``s_c^2 + s_g^2 + 1 / W`` (solution, trace
  noise, radiometer); ``ratio_c = (sum (T_run - T_sky)^2 - sum 1/W) / sum (s_c^2 + s_g^2)``
  is actual over stated variance of the calibration part, over runs and channels.

``python -m benchmarks.season_week --seeds N --days 7`` prints a table and exits 1 when the
RMS is outside 1 +- 0.1. Measured (``--seeds 6 --days 7``, defaults otherwise: 1000x,
60-70 MHz, four calibrators at 60 s, 4 cycles of 200 s an observing run; two shared cores
at a load of 5-12, about 620 s of real time a week)::

    seed  real s  sim d runs spectra bins  rms z  var r  var c share r alarms
       0     618   7.07   13      52   20  1.069  0.998  1.055    0.58      0
       1     616   7.00   14      56   15  1.140  1.016  1.503    0.62      1
       2     620   7.00   14      56   15  1.077  0.990  0.894    0.57      2
       3     613   7.00   14      56   17  1.089  1.011  1.362    0.59      3
       4     610   7.00   14      56    9  0.937  1.011  0.697    0.54      0
       5     609   7.00   14      56    6  1.237  1.006  1.094    0.54      0

    season (T_b - T_sky) / s_b: RMS 1.088 over 67144 bin-channels of 6 seeds (PASS)
    radiometer part: variance ratio 1.006 (203917 degrees of freedom)
    calibration part: variance ratio 1.080 (83 solutions)

A solution's error over the band holds few independent numbers: its posterior says
about 1.5 (:func:`calibration_numbers`; two nearly constant shapes over 5-10 MHz), and the
seeds' spread of ``var c`` (0.70-1.50 over 14 solutions each, standard deviation 0.30)
says 1.6. So 83 solutions know the calibration ratio to about +-0.12: 1.080 is 0.7 of
that above 1, and the seeds scatter as they should about it.

The 6 alarms: ``device silent`` (the spectrometer or the Teensy), each a few simulated
minutes of the loaded machine's simulators behind their clock, and in seed 2 one
``calibration drift`` of 3.9 sigma on a receiver that does not drift: an observing run's
check, which then compared on the cold load (a calibrator, where two solutions' model
averaging differs by 1.18 times the stated variance). It now compares on the antenna
as the previous run measured it (:mod:`reach_receiver.run.drift`); measured again
(``--seeds 3``, seed 0 still with the cold-load check)::

    seed  real s  sim d runs spectra bins  rms z  var r  var c share r alarms
       0     610   7.00   14      56   10  0.932  0.977  0.987    0.59      0
       1     609   7.00   14      56    6  1.225  0.996  0.954    0.55      0
       2     609   7.00   14      56    9  1.139  1.002  0.974    0.58      0

    season (T_b - T_sky) / s_b: RMS 1.084 over 20475 bin-channels of 3 seeds (PASS)
    radiometer part: variance ratio 0.992 (103194 degrees of freedom)
    calibration part: variance ratio 0.972 (42 solutions, 70 independent numbers)

with the 54 drift checks of seeds 1-2 all on the antenna: largest 2.8 sigma, 3 beyond 2.
Seed 5 is a second run of that seed: the first stopped after 2.07 days when its
simulated Teensy was killed from outside (RMS 1.366 and calibration ratio 2.59 over its
two days, which had taken the totals to 1.099 and 1.157).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibration.core.sidereal import apparent_lst_h
from calibration.io.calibrated_spectra import RunSpectra, open_run_file, read_calibrated_spectra
from calibration.io.solution_file import read_solution_group
from calibration.report.writer import RUN_SOLUTION
from calibration.season.binning import Season
from calibration.season.recalibrate import cycle_inputs, run_cycles
from calibration.season.season_file import read_season
from calibration.solve.solution import Solution
from calibration.solve.solvers import band_hz
from reach_receiver.clock import CompressedClock, ManualClock
from reach_receiver.config.site import load_site
from reach_receiver.daemon.client import DaemonClient
from reach_receiver.daemon.control import SOCKET_FILE
from reach_receiver.sim.physics import PhysicsConfig, ReceiverPhysics
from reach_receiver.sim.receiver import SimulationSettings, simulated_site

SCHEDULES = Path(__file__).resolve().parents[1] / "schedules"
REACHD = "import sys; from reach_receiver.cli import reachd_main as m; sys.exit(m(sys.argv[1:]))"
REACH_CAL = "import sys; from calibration.cli import main; sys.exit(main(sys.argv[1:]))"
DAY_S = 86_400.0
SLOT_H = 6.0
#: Real seconds ``reachd --sim`` takes to serve (the simulators, its imports), allowed for
#: before the first timer on a loaded machine.
START_REAL_S = 8.0


@dataclass(frozen=True)
class WeekPlan:
    """What the simulated week runs (module doc)."""

    days: float = 7.0
    compression: float = 1000.0
    seed: int = 0
    observing: int = 2
    cycles: int = 4
    position_s: float = 200.0
    dicke_s: float = 60.0
    band_mhz: tuple[float, float] = (60.0, 70.0)
    calibrators: tuple[str, ...] = ("cold", "hot", "c10open", "c10short")
    #: Stop once this many observing runs completed (``None``: the whole ``days``).
    observing_runs: int | None = None
    #: Real seconds allowed for the daemon to serve before its first timer.
    start_real_s: float = START_REAL_S


@dataclass
class Week:
    """What a simulated week left: its completed observing runs and how long it took."""

    plan: WeekPlan
    observing_runs: list[Path]
    jobs: list[dict[str, Any]]
    real_s: float
    simulated_s: float
    alarms: list[str] = field(default_factory=list)


# ------------------------------------------------------------------ the site and schedules
def shortened_schedules(plan: WeekPlan) -> dict[str, str]:
    """The shipped observe, calibrate and common schedules with the plan's values."""
    texts = {n: (SCHEDULES / n).read_text() for n in ("observe.yaml", "calibrate.yaml",
                                                       "common.yaml")}
    lo, hi = (f"{1e6 * f:.6e}" for f in plan.band_mhz)
    changes = [
        ("common.yaml", r"calibrators: \[cold, hot, r25, [^]]*\]",
         f"calibrators: [{', '.join(plan.calibrators)}]"),
        ("common.yaml", r"dicke_seconds: 600", f"dicke_seconds: {plan.dicke_s:g}"),
        ("observe.yaml", r"night_cycles: 60", f"night_cycles: {plan.cycles}"),
        ("observe.yaml", r"position_seconds: 200", f"position_seconds: {plan.position_s:g}"),
        ("observe.yaml", r"\n  - wait: \{until_lst_h: \"\$\{start_lst_h\}\"\}", ""),
        ("calibrate.yaml", r"calibrate: \{f_lo_hz: 5\.0e\+7, f_hi_hz: 1\.3e\+8\}",
         f"calibrate: {{f_lo_hz: {lo}, f_hi_hz: {hi}}}"),
    ]
    for file, pattern, value in changes:
        texts[file], n = re.subn(pattern, value, texts[file])
        if n != 1:
            raise RuntimeError(f"schedules/{file} changed: {pattern!r} not found once")
    return texts


def write_site(directory: Path, plan: WeekPlan, first_lst_h: float) -> Path:
    """The site file (simulated devices, the band, four timers) and its schedules."""
    directory.mkdir(parents=True, exist_ok=True)
    for name, text in shortened_schedules(plan).items():
        (directory / name).write_text(text)
    lo, hi = (f"{1e6 * f:.6e}" for f in plan.band_mhz)
    timers = []
    for k in range(round(24.0 / SLOT_H)):
        lst = (first_lst_h + k * SLOT_H) % 24.0
        name, schedule = (("observe", "observe.yaml") if k < plan.observing
                          else ("calibrate", "calibrate.yaml"))
        timers.append(f"    - {{name: {name}-{k}, schedule: {schedule}, at_lst_h: {lst:.4f}}}")
    base = simulated_site(SimulationSettings()).to_yaml()
    extra = (f"calibration:\n  band_hz: [{lo}, {hi}]\n"
             "daemon:\n  missed: {policy: late, window_s: 86400}\n  timers:\n"
             + "\n".join(timers) + "\n")
    site = directory / "base-site.yaml"
    site.write_text(base + extra)
    return site


# ------------------------------------------------------------------ the week
def run_week(directory: Path, plan: WeekPlan, log_to: Path | None = None) -> Week:
    """``reachd --sim`` on the plan's timers for its days; the completed observing runs."""
    directory = Path(directory)
    lon = simulated_site(SimulationSettings()).longitude_deg
    now_lst = float(apparent_lst_h([time.time()], lon)[0])
    first = now_lst + plan.start_real_s * plan.compression / 3600.0 * 1.0027379
    site = write_site(directory, plan, first % 24.0)
    log_path = log_to or directory / "reachd.log"
    real0 = time.monotonic()
    with log_path.open("w") as log:
        process = subprocess.Popen(
            [sys.executable, "-c", REACHD, "--sim", "-v", "--site", str(site),
             "--compression", f"{plan.compression:g}", "--seed", str(plan.seed),
             "--state-dir", str(directory / "state"), "--runtime-dir", str(directory / "run"),
             "--site-out", str(directory / "site.yaml")],
            stdout=subprocess.PIPE, stderr=log, text=True,
            env={**os.environ, "NOTIFY_SOCKET": ""},
        )
    try:
        assert process.stdout is not None
        for line in process.stdout:
            if "serving" in line:
                break
        else:
            raise RuntimeError(f"reachd --sim did not start: see {log_path}")
        served = load_site(directory / "site.yaml")
        clock = CompressedClock(served.simulation["compression"], served.simulation["start"],
                                served.simulation["monotonic_origin"])
        start = clock.now()
        end = start + plan.days * DAY_S
        with DaemonClient(directory / "run" / SOCKET_FILE) as client:
            jobs = _wait(client, clock, end, plan.observing_runs)
        simulated = clock.now() - start
    finally:
        process.send_signal(signal.SIGTERM)
        process.wait(timeout=120)
        if process.stdout is not None:
            process.stdout.close()
    real = time.monotonic() - real0
    runs = [Path(j["run"]) for j in jobs
            if j["state"] == "completed" and j["name"] == "observe" and j.get("run")]
    alarms = [ln for ln in log_path.read_text().splitlines() if "alarm raised" in ln]
    return Week(plan, runs, jobs, real, simulated, alarms)


def _wait(client: DaemonClient, clock: CompressedClock, end: float,
          runs: int | None) -> list[dict[str, Any]]:
    """The daemon's jobs once the week's end has passed (enough observing runs, a failure)."""
    while True:
        jobs = list(client.request("queue")["jobs"])
        done = sum(j["state"] == "completed" and j["name"] == "observe" for j in jobs)
        failed = any(j["state"] == "failed" for j in jobs)  # the daemon waits for a person
        if failed or clock.now() >= end or (runs is not None and done >= runs):
            return jobs
        time.sleep(min(1.0, max(clock.real_seconds(end - clock.now()), 0.05)))


# ------------------------------------------------------------------ the season and its truth
def season_of(runs: list[Path], out: Path, lst_bin_h: float) -> Season:
    """``reach-cal season RUNS -o out`` as a user runs it, read back."""
    done = subprocess.run(
        [sys.executable, "-c", REACH_CAL, "season", *map(str, runs), "-o", str(out),
         "--lst-bin-h", f"{lst_bin_h:g}"], capture_output=True, text=True, check=False,
    )
    if done.returncode != 0:
        raise RuntimeError(f"reach-cal season failed: {done.stderr.strip()}")
    return read_season(out)


def true_sky_k(freq_hz: np.ndarray) -> np.ndarray:
    """The simulator's antenna temperature (its own model; the same at every LST)."""
    physics = ReceiverPhysics(ManualClock(), PhysicsConfig())
    return np.asarray(physics.sky_temperature_k(np.asarray(freq_hz, float), 0.0), float)


# ------------------------------------------------------------------ the statistics
@dataclass
class Sums:
    """Sums over seeds of the three statistics (module doc)."""

    z2: float = 0.0
    z_n: int = 0
    chi2: float = 0.0
    dof: int = 0
    cal_actual: float = 0.0
    cal_stated: float = 0.0
    run_z2: float = 0.0
    run_n: int = 0
    runs: int = 0
    #: Independent numbers in the runs' calibration errors (:func:`calibration_numbers`).
    cal_numbers: float = 0.0
    #: Variance the radiometer noise adds to ``cal_actual`` (its square and cross terms).
    cal_noise_var: float = 0.0
    bins: int = 0
    radiometer_share: list[float] = field(default_factory=list)

    @property
    def rms(self) -> float:
        """RMS of the season's ``(T_b - T_sky) / s_b``."""
        return math.sqrt(self.z2 / self.z_n) if self.z_n else math.nan

    @property
    def ratio_r(self) -> float:
        """Radiometer part: actual over stated variance (scatter of a run's cycles)."""
        return self.chi2 / self.dof if self.dof else math.nan

    @property
    def ratio_c(self) -> float:
        """Calibration part: actual over stated variance (runs' mean residuals)."""
        return self.cal_actual / self.cal_stated if self.cal_stated else math.nan

    @property
    def run_rms(self) -> float:
        """RMS of each run's mean residual over its whole stated error."""
        return math.sqrt(self.run_z2 / self.run_n) if self.run_n else math.nan


def add_season(sums: Sums, season: Season) -> None:
    """The season's ``z`` over its bins and channels with data."""
    used = ~season.flags
    z = (season.mean - true_sky_k(season.freq_hz)[None, :]) / season.std
    sums.z2 += float(np.sum(z[used] ** 2))
    sums.z_n += int(used.sum())
    sums.bins += int(np.any(used, axis=1).sum())
    share = season.std_radiometer[used] ** 2 / season.std[used] ** 2
    sums.radiometer_share.append(float(np.mean(share)))


def add_run(sums: Sums, run: RunSpectra) -> None:
    """One run's cycles: the radiometer scatter and the calibration residual (module doc)."""
    sky = true_sky_k(run.freq_hz)[None, :]
    w = np.where(run.flags, 0.0, 1.0 / run.std_radiometer**2)
    n = (w > 0).sum(axis=0)
    total = w.sum(axis=0)
    ok = n >= 2
    mean = np.sum(w * np.where(run.flags, 0.0, run.mean), axis=0) / np.where(ok, total, 1.0)
    scatter = np.sum(w * (np.where(run.flags, 0.0, run.mean) - mean) ** 2, axis=0)
    sums.chi2 += float(scatter[ok].sum())
    sums.dof += int((n[ok] - 1).sum())
    cal = np.sum(w * run.std_calibration, axis=0) / np.where(ok, total, 1.0)
    refl = np.sum(w * run.std_reflection, axis=0) / np.where(ok, total, 1.0)
    residual = (mean - sky[0])[ok]
    stated = (cal**2 + refl**2)[ok]
    sums.cal_actual += float(np.sum(residual**2 - 1.0 / total[ok]))
    sums.cal_stated += float(np.sum(stated))
    sums.run_z2 += float(np.sum(residual**2 / (stated + 1.0 / total[ok])))
    sums.run_n += int(ok.sum())
    sums.runs += 1
    sums.cal_numbers += calibration_numbers(run.path)
    noise = 1.0 / total[ok]
    sums.cal_noise_var += float(2.0 * np.sum(noise**2) + 4.0 * np.sum(stated * noise))


def calibration_numbers(path: str) -> float:
    """How many independent numbers a run's calibration error over its band holds.

    The error a solution leaves in the calibrated antenna is ``X (theta - theta_true)``,
    ``X`` the antenna's design rows (eq. 3.27), so its covariance over the channels is
    ``C = X Sigma X^T`` with ``Sigma`` the posterior's. With ``R`` its correlation matrix,
    ``sum_i z_i^2`` over ``n`` channels has the variance ``2 tr(R^2)`` (a Gaussian
    quadratic form), that of ``n_eff = n^2 / tr(R^2)`` independent terms. ``X`` is the
    mean of the run's calibrated cycles' rows (its antenna changes little over a night).
    """
    with open_run_file(path) as f:
        cycles = run_cycles(f, path)
        solution = read_solution_group(f[RUN_SOLUTION], path)
        if not isinstance(solution, Solution):
            raise TypeError(f"{path}: a per-channel solution; the week's runs fit polynomials")
        rows = [
            solution.design_rows(i.freq_hz, i.gamma_rec, i.source.gamma, i.source.q)
            for i in (cycle_inputs(cycles.by_number, json.loads(g.attrs["handover"]),
                                   band_hz(solution), path) for g in cycles.calibrated)
        ]
    x = np.mean(rows, axis=0)
    c = x @ solution.posterior.covariance @ x.T
    d = np.sqrt(np.diag(c))
    return float(d.size**2 / np.sum((c / np.outer(d, d)) ** 2))


def analyse(sums: Sums, week: Week, directory: Path, lst_bin_h: float) -> Season:
    """Add one week's season and runs to the sums."""
    season = season_of(week.observing_runs, directory / "season.h5", lst_bin_h)
    add_season(sums, season)
    for path in week.observing_runs:
        add_run(sums, read_calibrated_spectra(path / "run.h5"))
    return season


def _save(where: Path, week: Week) -> Week:
    """Note the week's outcome beside its runs (``--reuse`` reads it)."""
    note = {"runs": [str(p) for p in week.observing_runs], "real_s": week.real_s,
            "simulated_s": week.simulated_s, "alarms": week.alarms}
    (where / "week.json").write_text(json.dumps(note))
    return week


def _load(where: Path, plan: WeekPlan) -> Week | None:
    try:
        note = json.loads((where / "week.json").read_text())
    except OSError:
        return None
    return Week(plan, [Path(p) for p in note["runs"]], [], note["real_s"],
                note["simulated_s"], note["alarms"])


# ------------------------------------------------------------------ the command
def main(argv: list[str] | None = None) -> int:
    """Run the weeks, print the table; 1 when the RMS is outside 1 +- 0.1."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.season_week", description=__doc__
                                .split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=2, help="weeks, one simulator seed each")
    p.add_argument("--days", type=float, default=7.0, help="simulated days a week")
    p.add_argument("--compression", type=float, default=WeekPlan.compression)
    p.add_argument("--cycles", type=int, default=WeekPlan.cycles,
                   help="antenna cycles an observing run")
    p.add_argument("--observing", type=int, default=WeekPlan.observing,
                   help="of the four 6-h slots, how many observe (the LST window)")
    p.add_argument("--lst-bin-h", type=float, default=1.0)
    p.add_argument("--dir", type=Path, default=Path("/tmp/season_week"),
                   help="where the weeks' state and runs go")
    p.add_argument("--reuse", action="store_true",
                   help="analyse the weeks already in --dir again instead of running them")
    args = p.parse_args(argv)
    sums = Sums()
    print(f"{'seed':>4} {'real s':>7} {'sim d':>6} {'runs':>4} {'spectra':>7} {'bins':>4} "
          f"{'rms z':>6} {'var r':>6} {'var c':>6} {'share r':>7} {'alarms':>6}")
    for seed in range(args.seeds):
        plan = WeekPlan(days=args.days, compression=args.compression, seed=seed,
                        cycles=args.cycles, observing=args.observing)
        where = args.dir / f"seed{seed}"
        week = _load(where, plan) if args.reuse else None
        week = week or _save(where, run_week(where, plan))
        one = Sums()
        season = analyse(one, week, where, args.lst_bin_h)
        analyse(sums, week, where, args.lst_bin_h)
        print(f"{seed:>4} {week.real_s:>7.0f} {week.simulated_s / DAY_S:>6.2f} "
              f"{len(week.observing_runs):>4} {len(season.spectra):>7} {one.bins:>4} "
              f"{one.rms:>6.3f} {one.ratio_r:>6.3f} {one.ratio_c:>6.3f} "
              f"{one.radiometer_share[0]:>7.2f} {len(week.alarms):>6}", flush=True)
    ok = abs(sums.rms - 1.0) <= 0.1
    print(f"\nseason (T_b - T_sky) / s_b: RMS {sums.rms:.3f} over {sums.z_n} bin-channels of "
          f"{args.seeds} seeds (target 1 +- 0.1: {'PASS' if ok else 'FAIL'})")
    print(f"radiometer part, a run's cycles' scatter / stated: variance ratio "
          f"{sums.ratio_r:.3f} ({sums.dof} degrees of freedom)")
    print(f"calibration part, runs' mean residual / stated: variance ratio {sums.ratio_c:.3f} "
          f"({sums.runs} solutions, {sums.cal_numbers:.0f} independent numbers)")
    print(f"whole error of a run's mean: RMS z {sums.run_rms:.3f}")
    print(f"radiometer share of a bin's variance: mean {np.mean(sums.radiometer_share):.2f}; "
          f"var r, var c: actual over stated variance of each part, per seed")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
