"""Site files: each mistake an operator (or a damaged disk) can put in ``site.yaml``.

Each trial writes a site file (a good one changed in one way, or a file that is not a site
at all) and the files it names, in a directory of its own, and gives it to the real
``reach-run --site SITE --validate`` (which checks the site, then compiles a shipped
schedule against it) or ``reachd --check --site SITE``; the answer is judged by
:func:`~benchmarks.faults.core.judge_refusal`, with every file of the directory hashed
before and after.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from .core import Trial, judge_refusal, run_command
from .engine import hashes

CLASS = "site files"
SCHEDULE = Path(__file__).resolve().parents[2] / "schedules" / "quick.yaml"
WORKERS = 2
DEVICES = """\
devices:
  teensy: {port: /dev/ttyACM0}
  vna: {resource: "TCPIP0::10.0.0.2::5025::SOCKET"}
  tec: {via: teensy}
  tc08: {}
  spectrometer: {port: 4660, period_s: 30.0}
"""
#: A one-port and a two-port Touchstone file, as a site names them.
S1P = "# Hz S RI R 50\n50e6 0.01 0.0\n100e6 0.02 0.01\n"
S2P = "# Hz S RI R 50\n50e6 0.01 0 0.9 0 0.9 0 0.01 0\n100e6 0.02 0 0.9 0 0.9 0 0.02 0\n"

Prepare = Callable[[Path], None]


@dataclass(frozen=True)
class SiteFault:
    """A site file's text after the devices (or a preparation), the CLI and the word it says.

    ``site`` is the file given to the CLI (``site.yaml`` unless the fault is the file
    itself); ``prepare`` makes what the site names.
    """

    name: str
    text: str | None
    says: str = ""
    prepare: Prepare | None = None
    site: str = "site.yaml"
    reachd: bool = False
    quick: bool = False


def _file(name: str, data: str | bytes) -> Prepare:
    def prepare(d: Path) -> None:
        raw = data.encode() if isinstance(data, str) else data
        (d / name).write_bytes(raw)
    return prepare


def _fifo(name: str) -> Prepare:
    def prepare(d: Path) -> None:
        os.mkfifo(d / name)
    return prepare


def _dir(name: str) -> Prepare:
    def prepare(d: Path) -> None:
        (d / name).mkdir()
    return prepare


def _sparse(name: str, size: int) -> Prepare:
    def prepare(d: Path) -> None:
        with open(d / name, "wb") as handle:
            handle.truncate(size)
    return prepare


def _ref(path: str) -> str:
    return f"references: {{test_load: {path}}}\n"


CLOCK = "simulation: {{compression: {}, start: 1700000000.0, monotonic_origin: 100.0}}\n"
BOMB = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{c}: &{c} [{', '.join(['*' + p] * 10)}]\n"
    for p, c in zip("abcdefgh", "bcdefghi", strict=True)
)


def faults() -> list[SiteFault]:
    """Every site-file fault, in the table's order."""
    f = SiteFault
    return [
        f("compression 0", CLOCK.format(0), "compression", quick=True),
        f("compression -5", CLOCK.format(-5), "compression"),
        f("compression NaN", CLOCK.format(".nan"), "compression"),
        f("compression inf", CLOCK.format(".inf"), "compression"),
        f("compression text", CLOCK.format("fast"), "compression"),
        f("compression 1e12", CLOCK.format("1.0e+12"), "compression"),
        f("compression 0 (reachd --check)", CLOCK.format(0), "compression", reachd=True),
        f("clock without start", "simulation: {compression: 10}\n", "needs all"),
        f("clock start text", "simulation: {compression: 10, start: noon, monotonic_origin: 1}\n",
          "start"),
        f("clock origin -1", "simulation: {compression: 10, start: 1, monotonic_origin: -1}\n",
          "monotonic_origin"),
        f("test load /etc/passwd", _ref("/etc/passwd"), "test_load", quick=True),
        f("test load /dev/zero", _ref("/dev/zero"), "regular file", quick=True),
        f("test load /dev/zero (reachd --check)", _ref("/dev/zero"), "regular file",
          reachd=True),
        f("test load /dev/urandom", _ref("/dev/urandom"), "regular file"),
        f("test load a FIFO", _ref("ref.s1p"), "regular file", _fifo("ref.s1p")),
        f("test load a directory", _ref("ref.s1p"), "regular file", _dir("ref.s1p")),
        f("test load of 9 MB", _ref("ref.s1p"), "bytes", _sparse("ref.s1p", 9 << 20)),
        f("test load binary", _ref("ref.s1p"), "test_load", _file("ref.s1p", os.urandom(4096))),
        f("test load empty", _ref("ref.s1p"), "test_load", _file("ref.s1p", b"")),
        f("test load a two-port", _ref("ref.s2p"), "port", _file("ref.s2p", S2P)),
        f("test load NaN values", _ref("ref.s1p"), "test_load",
          _file("ref.s1p", S1P.replace("0.02 0.01", "nan nan"))),
        f("test load a number", _ref("42"), "test_load"),
        f("test load empty text", _ref('""'), "test_load"),
        f("test load a list", _ref("[a.s1p, b.s1p]"), "test_load"),
        f("unknown reference", "references: {antenna: a.s1p}\n", "antenna"),
        f("mts sources /dev/zero", "calibration: {mts: {sources: /dev/zero}}\n", "regular file"),
        f("mts lna /etc/passwd", "calibration: {mts: {lna: /etc/passwd}}\n", "mts.lna"),
        f("cable s2p a directory",
          "calibration: {cables: {hot: {s2p: c.s2p, thermocouple: 1}}}\n", "regular file",
          _dir("c.s2p")),
        f("cable s2p a one-port",
          "calibration: {cables: {hot: {s2p: c.s1p, thermocouple: 1}}}\n", "port",
          _file("c.s1p", S1P)),
        f("site is /dev/zero (reachd --check)", None, "regular file", site="/dev/zero",
          reachd=True, quick=True),
        f("site is /dev/zero", None, "regular file", site="/dev/zero"),
        f("site is a FIFO", None, "regular file", _fifo("fifo.yaml"), site="fifo.yaml"),
        f("site is a directory", None, "regular file", _dir("d.yaml"), site="d.yaml"),
        f("site missing", None, "no such file", site="none.yaml"),
        f("site of 2 MB", None, "bytes", _file("big.yaml", "#" * (2 << 20)), site="big.yaml"),
        f("site binary", None, "site", _file("bin.yaml", b"\xff\xfe\x00" * 100),
          site="bin.yaml"),
        f("site empty", None, "mapping", _file("empty.yaml", ""), site="empty.yaml"),
        f("site a list", None, "mapping", _file("list.yaml", "- a\n- b\n"), site="list.yaml"),
        f("site syntax error", "site: {name: [unclosed\n", "site.yaml"),
        f("site duplicate key", "site: {name: a}\nsite: {name: b}\n", "site"),
        f("site alias bomb", BOMB, "site.yaml"),
        f("site nested 10000 deep", "x: " + "[" * 10000 + "]" * 10000 + "\n", "site.yaml"),
        f("unknown section", "sight: {name: x}\n", "sight"),
        f("latitude 100", "site: {latitude_deg: 100}\n", "latitude"),
        f("longitude text", "site: {longitude_deg: east}\n", "longitude"),
        f("longitude NaN", "site: {longitude_deg: .nan}\n", "longitude"),
        f("devices missing", "", "devices", site="bare.yaml",
          prepare=_file("bare.yaml", "site: {name: x}\n")),
        f("spectrometer port 70000", "", "port", site="d.yaml",
          prepare=_file("d.yaml", DEVICES.replace("port: 4660", "port: 70000"))),
        f("spectrometer period 0", "", "period", site="d.yaml",
          prepare=_file("d.yaml", DEVICES.replace("period_s: 30.0", "period_s: 0"))),
        f("teensy port a number", "", "port", site="d.yaml",
          prepare=_file("d.yaml", DEVICES.replace("/dev/ttyACM0", "5"))),
        f("tec serial without port", "", "port", site="d.yaml",
          prepare=_file("d.yaml", DEVICES.replace("via: teensy", "via: serial"))),
        f("band reversed", "calibration: {band_hz: [130.0e+6, 50.0e+6]}\n", "band_hz"),
        f("band NaN", "calibration: {band_hz: [.nan, 1.0e+8]}\n", "band_hz"),
        f("solver unknown", "calibration: {solver: magic}\n", "solver"),
        f("cable velocity 2",
          "calibration: {cables: {hot: {length_m: 1, velocity_factor: 2, loss_db_per_m: 0.1, "
          "thermocouple: 1}}}\n", "velocity_factor"),
        f("source ms1 9", "sources: {hot: {ms1: 9}}\n", "ms1"),
        f("thermocouple port 9", "thermocouples: {hot: 9}\n", "thermocouples"),
        f("daemon resume maybe", "daemon: {resume: maybe}\n", "resume"),
        f("monitoring cadence -1", "monitoring: {cadence_s: -1}\n", "cadence"),
    ]


def entry_point(name: str, *args: str) -> list[str]:
    """A console script of :mod:`reach_receiver.cli` (``run_main``...) run by this Python."""
    code = f"import sys; from reach_receiver.cli import {name}; sys.exit({name}(sys.argv[1:]))"
    return [sys.executable, "-c", code, *args]


def _command(fault: SiteFault) -> list[str]:
    if fault.reachd:
        return entry_point("reachd_main", "--check", "--site", fault.site)
    return entry_point("run_main", "--site", fault.site, "--validate", str(SCHEDULE))


def try_fault(fault: SiteFault, directory: Path) -> Trial:
    """Write the fault's files in ``directory``, run the CLI on them, judge the answer."""
    directory.mkdir(parents=True)
    if fault.text is not None:
        (directory / "site.yaml").write_text(DEVICES + fault.text)
    if fault.prepare is not None:
        fault.prepare(directory)
    before = hashes(directory)
    answer = run_command(_command(fault), cwd=directory, env={"REACH_SITE": ""})
    intact = hashes(directory) == before
    return judge_refusal(fault.name, answer, intact=intact, says=fault.says)


def trials(workdir: Path, quick: bool) -> Iterator[Trial]:
    """Every site-file fault (the quick subset: the file kinds that once crashed)."""
    chosen = [f for f in faults() if f.quick or not quick]
    with ThreadPoolExecutor(WORKERS) as pool:
        runs = [
            pool.submit(try_fault, fault, workdir / f"site{i:03d}")
            for i, fault in enumerate(chosen)
        ]
        for run in runs:
            yield run.result()
