"""The engine's inputs: corrupted run and solution files, bad options, outputs over inputs.

Each trial runs the real ``reach-cal`` (``python -m calibration.cli``) in a directory of
its own holding copies of one small simulated run (made once per call with ``reach-cal
simulate``: six calibrators, 41 channels) and of its solutions, one of them changed in
one way, and judges the answer (:func:`~benchmarks.faults.core.judge_refusal`). Every
file of the directory is hashed before and after: an input changed or removed is
``lost``, whatever the exit code.
"""

from __future__ import annotations

import hashlib
import os
import shutil
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from .core import Answer, Trial, judge_refusal, python_command, run_command

CLASS = "engine"
CALIBRATORS = "cold,hot,r25,r100,c10open,c10short"
#: Two trials at once: each is mostly the engine's import (~2 s of one core).
WORKERS = 2
#: The quick subset: the faults once accepted or lost (a run file, a solution, options).
QUICK = (
    "solve RUN -o RUN",
    "solution posterior NaN everywhere",
    "solution grid: run channels 4x wider",
    "--orders 99,99,99,99,99",
    "summary --top -5",
    "simulate --channel-width-hz -1",
)

Change = Callable[[Path], None]


@dataclass(frozen=True)
class Fault:
    """One bad input: how the trial directory is changed, the command, the word it must say."""

    name: str
    argv: tuple[str, ...]
    says: str = ""
    change: Change | None = None


# ------------------------------------------------------------------ changing HDF5 files
def _edit(file: str, edit: Callable[[Any], None]) -> Change:
    def change(d: Path) -> None:
        with h5py.File(d / file, "r+") as f:
            edit(f)
    return change


def _replace(f: Any, name: str, value: Any) -> None:
    """Replace dataset ``name`` by ``value``, keeping its attributes."""
    attrs = dict(f[name].attrs)
    del f[name]
    f.create_dataset(name, data=value).attrs.update(attrs)


def dataset(file: str, name: str, value: Callable[[np.ndarray], Any]) -> Change:
    """Replace dataset ``name`` by ``value(old)``."""
    def edit(f: Any) -> None:
        _replace(f, name, value(f[name][()]))
    return _edit(file, edit)


def same_as(file: str, name: str, other: str) -> Change:
    """Dataset ``name`` made equal to dataset ``other``."""
    def edit(f: Any) -> None:
        _replace(f, name, f[other][()])
    return _edit(file, edit)


def attr(file: str, obj: str, name: str, value: Any) -> Change:
    """Set attribute ``name`` of ``obj`` (``None``: delete it)."""
    def edit(f: Any) -> None:
        if value is None:
            del f[obj].attrs[name]
        else:
            f[obj].attrs[name] = value
    return _edit(file, edit)


def delete(file: str, name: str) -> Change:
    def edit(f: Any) -> None:
        del f[name]
    return _edit(file, edit)


def truncate(file: str, size: int | None) -> Change:
    """Cut ``file`` to ``size`` bytes (``None``: to half)."""
    def change(d: Path) -> None:
        path = d / file
        os.truncate(path, path.stat().st_size // 2 if size is None else size)
    return change


def both(*changes: Change) -> Change:
    def change(d: Path) -> None:
        for c in changes:
            c(d)
    return change


def measured(file: str, source: str = "run.h5") -> Change:
    """``file``: a copy of the run without its simulation truth (real measurements)."""
    def change(d: Path) -> None:
        shutil.copy(d / source, d / file)
        with h5py.File(d / file, "r+") as f:
            del f["simulation_truth"]
    return change


def write(file: str, data: bytes) -> Change:
    def change(d: Path) -> None:
        (d / file).write_bytes(data)
    return change


def link(file: str, target: str, hard: bool = False) -> Change:
    def change(d: Path) -> None:
        (os.link if hard else os.symlink)(d / target if hard else target, d / file)
    return change


def mkdir(name: str) -> Change:
    def change(d: Path) -> None:
        (d / name).mkdir()
    return change


def coarser(file: str, factor: int) -> Change:
    """Every ``factor``-th channel of the run, its channels ``factor`` times wider."""
    def edit(f: Any) -> None:
        for group in ("observation_data", "observation_metadata/temperatures"):
            for name in list(f[group]):
                _replace(f[group], name, f[group][name][()][..., ::factor])
        meta = f["observation_metadata"]
        meta.attrs["channel_width_hz"] = meta.attrs["channel_width_hz"] * factor
    return _edit(file, edit)


# ------------------------------------------------------------------ the faults
OBS = "observation_data"
TEMPS = "observation_metadata/temperatures"
META = "observation_metadata"
SPECTRA = f"{OBS}/hot_spectra"
POST = "posterior"
SOLVE = ("solve", "run.h5", "-o", "out.h5")
APPLY = ("apply", "sol.h5", "run.h5")
SUMMARY = ("summary", "sol.h5")
NAN = float("nan")


def _run_faults() -> list[Fault]:
    """Run files corrupted in one way each, read by ``solve`` (and ``apply``)."""
    r = "run.h5"
    nan = lambda v: np.full_like(v, np.nan)  # noqa: E731
    return [
        Fault("run truncated to half", SOLVE, "HDF5", truncate(r, None)),
        Fault("run truncated to 0 bytes", SOLVE, "HDF5", truncate(r, 0)),
        Fault("run truncated to 100 bytes", SOLVE, "HDF5", truncate(r, 100)),
        Fault("run is text", SOLVE, "HDF5", write(r, b"frequencies,power\n1,2\n")),
        Fault("run is a directory", ("solve", "d", "-o", "out.h5"), "regular", mkdir("d")),
        Fault("run missing", ("solve", "none.h5", "-o", "out.h5"), "no such file"),
        Fault("run is /dev/zero", ("solve", "/dev/zero", "-o", "out.h5"), "regular"),
        Fault("run is a solution", ("solve", "sol.h5", "-o", "out.h5"), "solution"),
        Fault("run format_version 2.0", SOLVE, "version", attr(r, "/", "format_version", "2.0")),
        Fault("run without observation_data", SOLVE, "missing", delete(r, OBS)),
        Fault("run without frequencies", SOLVE, "frequencies", delete(r, f"{OBS}/frequencies")),
        Fault("run without lna_s11", SOLVE, "lna_s11", delete(r, f"{OBS}/lna_s11")),
        Fault("run without hot_spectra", SOLVE, "hot_spectra", delete(r, SPECTRA)),
        Fault("run without hot_ns_spectra", SOLVE, "hot_ns", delete(r, f"{OBS}/hot_ns_spectra")),
        Fault("run without hot_s11", SOLVE, "hot", delete(r, f"{OBS}/hot_s11")),
        Fault("run without temperatures", SOLVE, "temperatures", delete(r, TEMPS)),
        Fault("run without channel width", SOLVE, "channel_width",
              attr(r, META, "channel_width_hz", None)),
        Fault("run channel width 0", SOLVE, "width", attr(r, META, "channel_width_hz", 0.0)),
        Fault("run channel width -1", SOLVE, "width", attr(r, META, "channel_width_hz", -1.0)),
        Fault("run channel width NaN", SOLVE, "width", attr(r, META, "channel_width_hz", NAN)),
        Fault("run channel width text", SOLVE, "width",
              attr(r, META, "channel_width_hz", "wide")),
        Fault("run frequencies NaN", SOLVE, "freq", dataset(r, f"{OBS}/frequencies", nan)),
        Fault("run frequencies reversed", SOLVE, "freq",
              dataset(r, f"{OBS}/frequencies", lambda v: v[::-1])),
        Fault("run frequencies negative", SOLVE, "freq",
              dataset(r, f"{OBS}/frequencies", lambda v: -v)),
        Fault("run frequencies one short", SOLVE, "",
              dataset(r, f"{OBS}/frequencies", lambda v: v[:-1])),
        Fault("run frequencies as text", SOLVE, "dtype",
              dataset(r, f"{OBS}/frequencies", lambda v: np.array([b"x"] * v.size))),
        Fault("run spectra NaN", SOLVE, "finite", dataset(r, SPECTRA, nan)),
        Fault("run spectra inf", SOLVE, "finite",
              dataset(r, SPECTRA, lambda v: np.full_like(v, np.inf))),
        Fault("run spectra zero", SOLVE, "", dataset(r, SPECTRA, np.zeros_like)),
        Fault("run spectra one short", SOLVE, "", dataset(r, SPECTRA, lambda v: v[:-1])),
        Fault("run spectra 3-D", SOLVE, "shape", dataset(r, SPECTRA, lambda v: v[None, None])),
        Fault("run spectra empty 2-D", SOLVE, "shape", dataset(r, SPECTRA, lambda v: v[:0, None])),
        Fault("run ns spectra equal load", SOLVE, "",
              same_as(r, f"{OBS}/hot_ns_spectra", f"{OBS}/hot_load_spectra")),
        Fault("run s11 NaN", SOLVE, "", dataset(r, f"{OBS}/hot_s11", nan)),
        Fault("run s11 above 1", SOLVE, "", dataset(r, f"{OBS}/hot_s11", lambda v: v * 0 + 3)),
        Fault("run lna_s11 NaN", SOLVE, "", dataset(r, f"{OBS}/lna_s11", nan)),
        Fault("run lna_s11 one short", SOLVE, "", dataset(r, f"{OBS}/lna_s11", lambda v: v[:-1])),
        Fault("run temperature NaN", SOLVE, "", dataset(r, f"{TEMPS}/hot", nan)),
        Fault("run temperature negative", SOLVE, "", dataset(r, f"{TEMPS}/hot", lambda v: -v)),
        Fault("run temperature std NaN", SOLVE, "", attr(r, f"{TEMPS}/hot", "std_k", NAN)),
        Fault("run temperature std -1", SOLVE, "", attr(r, f"{TEMPS}/hot", "std_k", -1.0)),
        Fault("run integration 0 s", SOLVE, "integration",
              attr(r, SPECTRA, "integration_s_source", 0.0)),
        Fault("run integration NaN", SOLVE, "integration",
              attr(r, SPECTRA, "integration_s_source", NAN)),
        Fault("run integration text", SOLVE, "integration",
              attr(r, SPECTRA, "integration_s_load", "long")),
        Fault("run calibrator without data", SOLVE, "no data",
              attr(r, META, "calibrators", ["hot", "ghost"])),
        Fault("run one calibrator", SOLVE, "", attr(r, META, "calibrators", ["hot"])),
        Fault("run metadata not JSON", SOLVE, "metadata", attr(r, "/", "metadata", "{oops")),
        Fault("run q_variance negative", SOLVE, "",
              lambda d: _add(d / r, f"{OBS}/hot_q_variance", -np.ones(41))),
        Fault("run s11_std NaN", SOLVE, "",
              lambda d: _add(d / r, f"{OBS}/hot_s11_std", np.full(41, np.nan))),
        Fault("run reflection correlation NaN", SOLVE, "",
              attr(r, META, "reflection_correlation_channels", NAN)),
        Fault("run truth orders negative", ("summary", "sol.h5", "--run", "run.h5"), "orders",
              dataset(r, "simulation_truth/orders", lambda v: -v)),
        Fault("run truth coefficients NaN", ("summary", "sol.h5", "--run", "run.h5"), "",
              dataset(r, "simulation_truth/coefficients", nan)),
        Fault("apply to a run with NaN ant spectra", APPLY, "",
              dataset(r, f"{OBS}/ant_spectra", nan)),
    ]


def _add(path: Path, name: str, value: np.ndarray) -> None:
    with h5py.File(path, "r+") as f:
        f.create_dataset(name, data=value)


def _solution_faults() -> list[Fault]:
    """Solution files changed in one way each, read by ``apply`` or ``summary``."""
    s = "sol.h5"
    nan = lambda v: np.full_like(v, np.nan)  # noqa: E731
    return [
        Fault("solution posterior NaN everywhere", APPLY, "posterior",
              both(dataset(s, f"{POST}/mean", nan), dataset(s, f"{POST}/scale", nan))),
        Fault("solution mean inf", APPLY, "posterior",
              dataset(s, f"{POST}/mean", lambda v: v + np.inf)),
        Fault("solution scale NaN", SUMMARY, "posterior", dataset(s, f"{POST}/scale", nan)),
        Fault("solution negative variance", APPLY, "covariance",
              dataset(s, f"{POST}/scale", lambda v: -np.abs(v))),
        Fault("solution noise variance NaN", APPLY, "noise", attr(s, POST, "noise_variance", NAN)),
        Fault("solution noise variance -1", APPLY, "noise", attr(s, POST, "noise_variance", -1.0)),
        Fault("solution dof 0", APPLY, "dof", attr(s, POST, "dof", 0.0)),
        Fault("solution log evidence NaN", SUMMARY, "log_evidence",
              attr(s, POST, "log_evidence", NAN)),
        Fault("solution n_rows text", SUMMARY, "n_rows", attr(s, POST, "n_rows", "many")),
        Fault("solution orders negative", APPLY, "orders",
              dataset(s, f"{POST}/orders", lambda v: -v)),
        Fault("solution orders absurd", SUMMARY, "orders",
              dataset(s, f"{POST}/orders", lambda v: v * 0 + 10**9)),
        Fault("solution orders float", SUMMARY, "orders",
              dataset(s, f"{POST}/orders", lambda v: v + 0.5)),
        Fault("solution orders four", SUMMARY, "orders",
              dataset(s, f"{POST}/orders", lambda v: v[:4])),
        Fault("solution evidence orders negative", SUMMARY, "orders",
              dataset(s, "evidence/orders", lambda v: -v)),
        Fault("solution evidence NaN", SUMMARY, "evidence",
              dataset(s, "evidence/log_evidence", nan)),
        Fault("solution best_orders negative", SUMMARY, "best_orders",
              attr(s, "/", "metadata", '{"best_orders": [-1, -2, 3, 4, 5]}')),
        Fault("solution best_orders text", SUMMARY, "best_orders",
              attr(s, "/", "metadata", '{"best_orders": "high"}')),
        Fault("solution model weights garbage", SUMMARY, "model_weights",
              attr(s, "/", "metadata", '{"averaged": true, "model_weights": [1, 2]}')),
        Fault("solution metadata a list", SUMMARY, "metadata", attr(s, "/", "metadata", "[1]")),
        Fault("solution basis kind unknown", APPLY, "basis", attr(s, "basis", "kind", "cubic")),
        Fault("solution basis band reversed", APPLY, "basis",
              attr(s, "basis", "f_lo_hz", 200e6)),
        Fault("solution measurement model unknown", SUMMARY, "measurement_model",
              attr(s, "/", "measurement_model", "psychic")),
        Fault("solution kind unknown", SUMMARY, "solution_kind",
              attr(s, "/", "solution_kind", "neural")),
        Fault("solution without posterior", APPLY, "posterior", delete(s, POST)),
        Fault("solution truncated", APPLY, "HDF5", truncate(s, None)),
        Fault("solution is a run", ("apply", "run.h5", "run.h5"), "run"),
        Fault("solution component missing", SUMMARY, "components",
              delete(s, f"{POST}/components/0")),
        Fault("solution weights NaN", SUMMARY, "weights",
              dataset(s, f"{POST}/components/weights", nan)),
        Fault("solution weights negative", SUMMARY, "weights",
              dataset(s, f"{POST}/components/weights", lambda v: -v)),
        Fault("solution grid: run channels 4x wider", APPLY, "channels", coarser("run.h5", 4)),
        Fault("solution grid: run channels shifted", APPLY, "grid", both(
            attr(s, "basis", "f_lo_hz", 49e6), attr(s, "basis", "f_hi_hz", 131e6),
            dataset("run.h5", f"{OBS}/frequencies", lambda v: v + 0.3e6))),
        Fault("per-channel solution mean NaN", ("apply", "chan.h5", "run.h5"), "NaN",
              dataset("chan.h5", "channels/mean", nan)),
        Fault("per-channel solution negative variance", ("summary", "chan.h5"), "negative",
              dataset("chan.h5", "channels/covariance", lambda v: -np.abs(v))),
        Fault("per-channel frequencies reversed", ("summary", "chan.h5"), "increasing",
              dataset("chan.h5", "channels/frequencies", lambda v: v[::-1])),
    ]


def _option_faults() -> list[Fault]:
    """Numeric and other options out of range, for every command."""
    sim = ("simulate", "-o", "new.h5")
    val = ("validate", "run.h5", "--leave-one-out")
    edges = ("import", "edges", "lab", "-o", "new.h5", "--temperatures")
    return [
        Fault("--orders 99,99,99,99,99", (*SOLVE, "--orders", "99,99,99,99,99"), "16"),
        Fault("--orders negative", (*SOLVE, "--orders", "-1,2,3,4,5"), "orders"),
        Fault("--orders three", (*SOLVE, "--orders", "1,2,3"), "orders"),
        Fault("--max-orders 0", (*SOLVE, "--max-orders", "0,0,0,0,0"), "max-orders"),
        Fault("--max-orders 99", (*SOLVE, "--max-orders", "99,9,9,9,9"), "max-orders"),
        Fault("--band reversed", (*SOLVE, "--band", "130,50"), "band"),
        Fault("--band NaN", (*SOLVE, "--band", "nan,100"), "band"),
        Fault("--band to inf", (*SOLVE, "--band", "50,inf"), "band"),
        Fault("--band outside the run", (*SOLVE, "--band", "300,400"), ""),
        Fault("--mask-band everything", (*SOLVE, "--mask-band", "0,1000"), ""),
        Fault("--smooth-s11 0", (*SOLVE, "--smooth-s11", "0"), "smooth"),
        Fault("--smooth-s11 -1", (*SOLVE, "--smooth-s11", "-1"), "smooth"),
        Fault("--smooth-s11 2", (*SOLVE, "--smooth-s11", "2"), "smooth"),
        Fault("--exclude-inconsistent 0", (*SOLVE, "--exclude-inconsistent", "0"), "exclude"),
        Fault("--alpha 1", (*SOLVE, "--alpha", "1"), "alpha"),
        Fault("--calibrators unknown", (*SOLVE, "--calibrators", "ghost"), "ghost"),
        Fault("--method unknown", (*SOLVE, "--method", "magic"), "method"),
        Fault("simulate --channel-width-hz -1", (*sim, "--channel-width-hz", "-1"), "width"),
        Fault("simulate --channel-width-hz 0", (*sim, "--channel-width-hz", "0"), "width"),
        Fault("simulate --channel-width-hz NaN", (*sim, "--channel-width-hz", "nan"), "width"),
        Fault("simulate --channel-width-hz 1e-3", (*sim, "--channel-width-hz", "1e-3"), "channel"),
        Fault("simulate --channel-width-hz 1e9", (*sim, "--channel-width-hz", "1e9"), "channel"),
        Fault("simulate --integration-s 0", (*sim, "--integration-s", "0"), "integration"),
        Fault("simulate --integration-s inf", (*sim, "--integration-s", "inf"), "integration"),
        Fault("simulate --band reversed", (*sim, "--band", "130", "50"), "band"),
        Fault("simulate --band negative", (*sim, "--band", "-10", "50"), "band"),
        Fault("simulate --vna-sigma -1", (*sim, "--vna-sigma", "-1"), "vna-sigma"),
        Fault("simulate --seed -1", (*sim, "--seed", "-1"), "seed"),
        Fault("simulate --calibrators unknown", (*sim, "--calibrators", "ghost"), "ghost"),
        Fault("apply --vna-accuracy -1", (*APPLY, "--vna-accuracy", "-1"), "vna-accuracy"),
        Fault("apply --vna-accuracy 1", (*APPLY, "--vna-accuracy", "1"), "vna-accuracy"),
        Fault("apply --vna-accuracy 1e9", (*APPLY, "--vna-accuracy", "1000000000"),
              "vna-accuracy"),
        Fault("apply --vna-correlation-mhz 0", (*APPLY, "--vna-correlation-mhz", "0"),
              "correlation"),
        Fault("apply --seed -1", (*APPLY, "--seed", "-1"), "seed"),
        Fault("apply --source unknown", (*APPLY, "--source", "ghost"), "ghost"),
        Fault("summary --top -5", (*SUMMARY, "--top", "-5"), "top"),
        Fault("summary --top 0", (*SUMMARY, "--top", "0"), "top"),
        Fault("validate without a method", ("validate", "run.h5"), "leave-one-out"),
        Fault("validate -o .txt", (*val, "-o", "report.txt"), ".json"),
        Fault("import edges --integration-s -1",
              (*edges, "amb=300", "--integration-s", "-1"), "integration"),
        Fault("import edges temperature -5 K", (*edges, "amb=-5"), "kelvin"),
        Fault("import edges temperature NaN", (*edges, "amb=nan"), "kelvin"),
        Fault("import edges --band reversed",
              (*edges, "amb=300", "--band", "190", "50"), "band"),
    ]


def _output_faults() -> list[Fault]:
    """Outputs that would replace an input or measurements."""
    return [
        Fault("solve RUN -o RUN", ("solve", "run.h5", "-o", "run.h5"), "input"),
        Fault("solve RUN -o ./RUN", ("solve", "run.h5", "-o", "./run.h5"), "input"),
        Fault("solve RUN -o a symbolic link to RUN", ("solve", "run.h5", "-o", "l.h5"), "input",
              link("l.h5", "run.h5")),
        Fault("solve RUN -o a hard link to RUN", ("solve", "run.h5", "-o", "h.h5"), "input",
              link("h.h5", "run.h5", hard=True)),
        Fault("solve -o another measured run", ("solve", "run.h5", "-o", "m.h5"), "measurements",
              measured("m.h5")),
        Fault("solve -o a receiver run", ("solve", "run.h5", "-o", "m.h5"), "measurements",
              both(measured("m.h5"), attr("m.h5", "/", "format", "reach-receiver-run"))),
        Fault("solve -o a receiver part", ("solve", "run.h5", "-o", "m.h5"), "measurements",
              both(measured("m.h5"), attr("m.h5", "/", "format", "reach-receiver-part"))),
        Fault("solve -o a text file", ("solve", "run.h5", "-o", "notes.txt"), "not an HDF5",
              write("notes.txt", b"field notes\n")),
        Fault("solve -o a directory", ("solve", "run.h5", "-o", "d"), "directory", mkdir("d")),
        Fault("apply -o RUN", (*APPLY, "-o", "run.h5"), "input"),
        Fault("apply -o SOLUTION", (*APPLY, "-o", "sol.h5"), "input"),
        Fault("apply --csv RUN", (*APPLY, "--csv", "run.h5"), "input"),
        Fault("apply -o X --csv X", (*APPLY, "-o", "x.h5", "--csv", "x.h5"), "same file"),
        Fault("apply -o a measured run", (*APPLY, "-o", "m.h5"), "measurements",
              measured("m.h5")),
        Fault("apply --csv a measured run", (*APPLY, "--csv", "m.csv"), "measurements",
              measured("m.csv")),
        Fault("simulate -o a measured run", ("simulate", "-o", "m.h5"), "measurements",
              measured("m.h5")),
        Fault("validate -o a measured run", ("validate", "run.h5", "--leave-one-out", "-o",
              "m.csv"), "measurements", measured("m.csv")),
        Fault("report -o RUN", ("report", "sol.h5", "--run", "run.h5", "-o", "run.h5"),
              "input"),
        Fault("import edges -o a measured run", ("import", "edges", ".", "-o", "m.h5",
              "--temperatures", "amb=300"), "measurements", measured("m.h5")),
        Fault("import vna -o its input directory", ("import", "vna", "lab", "-o", "lab",
              "--devices", "lna"), "input", mkdir("lab")),
    ]


def faults() -> list[Fault]:
    """Every engine fault, in the table's order."""
    return [*_run_faults(), *_solution_faults(), *_option_faults(), *_output_faults()]


# ------------------------------------------------------------------ running them
def reach_cal(*args: str, cwd: Path) -> Answer:
    """The real ``reach-cal``, run in ``cwd``."""
    return run_command(python_command("calibration.cli", *args), cwd=cwd)


def make_base(workdir: Path, per_channel: bool) -> Path:
    """The simulated run and its solutions every trial starts from."""
    base = workdir / "base"
    base.mkdir(parents=True)
    steps = [
        ("simulate", "-o", "run.h5", "--channel-width-hz", "2e6", "--calibrators", CALIBRATORS),
        ("solve", "run.h5", "-o", "sol.h5", "--max-orders", "5,5,5,5,5"),
    ]
    if per_channel:
        steps.append(("solve", "run.h5", "-o", "chan.h5", "--method", "least-squares"))
    for step in steps:
        answer = reach_cal(*step, cwd=base)
        if answer.code != 0:
            raise RuntimeError(f"reach-cal {' '.join(step)} failed: {answer.stderr[-500:]}")
    return base


def hashes(directory: Path) -> dict[str, str]:
    """The SHA-256 of every regular file under ``directory`` (links by their target)."""
    out = {}
    for path in sorted(directory.rglob("*")):
        if path.is_file():
            out[str(path.relative_to(directory))] = hashlib.sha256(path.read_bytes()).hexdigest()
    return out


def try_fault(fault: Fault, base: Path, directory: Path) -> Trial:
    """Run one fault in ``directory`` (a copy of ``base``) and judge it."""
    shutil.copytree(base, directory)
    if fault.change is not None:
        fault.change(directory)
    before = hashes(directory)
    answer = reach_cal(*fault.argv, cwd=directory)
    after = hashes(directory)
    intact = all(after.get(name) == digest for name, digest in before.items())
    return judge_refusal(fault.name, answer, intact=intact, says=fault.says)


def trials(workdir: Path, quick: bool) -> Iterator[Trial]:
    """Every engine fault (or the :data:`QUICK` subset) tried on fresh copies of one run."""
    chosen = [f for f in faults() if f.name in QUICK or not quick]
    base = make_base(workdir, per_channel=any("chan.h5" in f.argv for f in chosen))
    with ThreadPoolExecutor(WORKERS) as pool:
        runs = [
            pool.submit(try_fault, fault, base, workdir / f"trial{i:03d}")
            for i, fault in enumerate(chosen)
        ]
        for run in runs:
            yield run.result()
