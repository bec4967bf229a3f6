"""SIGKILL at random moments: every measurement whose add returned survives, merges recover."""

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from reach_receiver.store import merge_run, read_run_file
from reach_receiver.store.parts import list_parts

ROOT = Path(__file__).resolve().parents[1]

#: Adds S11s and full-size Dicke cycles forever; prints the count after each add returns.
WRITER = """
import sys
from pathlib import Path
import numpy as np
from reach_receiver.store import RunStore

store = RunStore(Path(sys.argv[1]), name="crash", schedule_files=[("s.yaml", "x: 1")],
                 site_yaml="site: {}", metadata={}, channel_width_hz=400e6 / 32768)
store.open()
rng = np.random.default_rng(int(sys.argv[2]))
pos = ("source", "load", "ns")
for i in range(1, 100_000):
    if i % 3:
        f = np.linspace(40e6, 180e6, 1401)
        store.add_s11(f"s{i}", f, rng.normal(size=f.size) * 0.1 + 0j, timestamp=float(i),
                      settings={"i": i}, calibrated=True)
    else:
        store.add_dicke(f"d{i}", spectra={p: rng.random((2, 16384)) for p in pos},
                        timestamps={p: [float(i)] for p in pos},
                        integration_s={p: 1.0 for p in pos}, n_spectra={p: 1 for p in pos},
                        temperature_k=300.0, switch_states={}, counters={}, timestamp=float(i))
    print(i, flush=True)
"""

MERGER = "import sys; from reach_receiver.store import merge_run; merge_run(sys.argv[1])"


def _start(code: str, *args: str) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, "-c", code, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env=env,
    )


def _kill(proc: subprocess.Popen) -> tuple[str, str]:
    proc.send_signal(signal.SIGKILL)
    out, err = proc.communicate(timeout=10)
    assert proc.returncode == -signal.SIGKILL, err
    return out, err


def _assert_complete(run_dir: Path, returned: int) -> None:
    """``run.h5`` merges, reads, and holds every measurement 1..returned in full."""
    contents = read_run_file(merge_run(run_dir))
    assert contents.status == "interrupted"
    names = [m.name for m in contents.measurements]
    assert len(names) >= returned
    assert names[:returned] == [f"{'d' if i % 3 == 0 else 's'}{i}" for i in range(1, returned + 1)]
    with h5py.File(run_dir / "run.h5") as f:
        for m in contents.measurements:
            key = "source/spectrum" if m.kind == "dicke" else "s11"
            assert np.all(np.isfinite(f[m.group][key][()])), m.group
    assert not list((run_dir / "parts").iterdir())


@pytest.mark.parametrize("seed", range(4))
def test_sigkill_during_writes_keeps_every_returned_measurement(tmp_path, seed):
    rng = random.Random(seed)
    run_dir = tmp_path / "run"
    proc = _start(WRITER, str(run_dir), str(seed))
    try:
        target = rng.randint(1, 25)
        returned = 0
        while returned < target:
            line = proc.stdout.readline()
            assert line, proc.stderr.read()
            returned = int(line)
        time.sleep(rng.uniform(0.0, 0.02))  # land anywhere inside the following writes
    finally:
        out, _ = _kill(proc)
    lines = out.split()
    returned = int(lines[-1]) if lines else returned
    _assert_complete(run_dir, returned)


@pytest.mark.parametrize("delay_s", [0.0, 0.003, 0.03])
def test_sigkill_during_merge_leaves_a_mergeable_run(tmp_path, delay_s):
    run_dir = tmp_path / "run"
    writer = _start(WRITER, str(run_dir), "9")
    try:
        while (line := writer.stdout.readline()) and int(line) < 60:
            pass
    finally:
        _kill(writer)
    n_parts = len(list_parts(run_dir))
    merger = _start(MERGER, str(run_dir))
    try:
        deadline = time.monotonic() + 10
        while not any(p.name.endswith(".tmp") for p in run_dir.iterdir()):
            assert merger.poll() is None, merger.stderr.read()
            assert time.monotonic() < deadline, "the merge never started its temporary"
            time.sleep(0.0005)
        time.sleep(delay_s)
    finally:
        _kill(merger)
    remaining = len(list_parts(run_dir))
    if not (run_dir / "run.h5").exists():
        assert remaining == n_parts  # killed before the replace: nothing lost
    if delay_s == 0.0:
        assert remaining == n_parts
        assert not (run_dir / "run.h5").exists()
    _assert_complete(run_dir, 60)
    assert not [p for p in run_dir.iterdir() if p.name.endswith(".tmp")]
