"""The cheap commands start without the engine: numpy, astropy, matplotlib, calibration.

Not a timing test (the machine's load decides the time); what decides the start is what
a command imports, which is held here: each command runs in a fresh interpreter and its
``sys.modules`` is read after it answered. ``python -m benchmarks.cli_start`` prints the
times.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("numpy", "astropy", "matplotlib", "h5py", "scipy", "calibration")
#: The engine's table of names the site file checks its solver against: no imports (the
#: subpackage's ``__init__`` is a docstring).
LIGHT = ("calibration", "calibration.core", "calibration.core.constants")
PROBE = """\
import contextlib, io, json, sys
from {module} import {main}
with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
    try:
        code = {main}({argv!r})
    except SystemExit as stop:
        code = stop.code
heavy = sorted(m for m in sys.modules if m.split(".")[0] in {heavy!r} and m not in {light!r})
print(json.dumps({{"code": code, "heavy": heavy}}))
"""


def imported(module: str, main: str, argv: list[str]) -> dict:
    code = PROBE.format(module=module, main=main, argv=argv, heavy=HEAVY, light=LIGHT)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@pytest.mark.parametrize(("main", "argv"), [
    ("run_main", ["--version"]),
    ("run_main", ["--help"]),
    ("run_main", []),
    ("run_main", ["stauts"]),
    ("run_main", ["status", "--help"]),
    ("run_main", ["metrics", "--help"]),
    ("run_main", ["run", "--help"]),
    ("run_main", ["completion", "bash"]),
    ("reachd_main", ["--help"]),
    ("reachd_main", ["--version"]),
    ("sim_main", ["--help"]),
])
def test_help_and_version_import_nothing_heavy(main, argv):
    found = imported("reach_receiver.cli", main, argv)
    assert found["code"] in (0, 2, None)
    assert found["heavy"] == []


#: reach-cal's parsers: the package, its constants and errors, and the cli's parser modules
#: (with the kit file's format, text that import's --help prints).
CAL_PARSER = ("calibration.core.errors", "calibration.cli", "calibration.cli.main",
              "calibration.cli.args", "calibration.cli.import_parser",
              "calibration.cli.season_parser", "calibration.cli.design_parser", "calibration.rf",
              "calibration.rf.kit_format")


@pytest.mark.parametrize("argv", [
    ["--help"], ["--version"], [], ["solve", "--help"], ["simulate", "--help"],
    ["validate", "--help"], ["report", "--help"], ["import", "edges", "--help"],
    ["import", "vna", "--help"], ["solve", "run.h5"], ["season", "--help"],
    ["export", "--help"], ["season", "run.h5"], ["plan", "--help"],
])
def test_reach_cal_parses_before_it_imports_the_engine(argv):
    code = PROBE.format(module="calibration.cli", main="main", argv=argv, heavy=HEAVY,
                        light=LIGHT + CAL_PARSER)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout)
    assert found["code"] in (0, 2)
    assert found["heavy"] == []


def test_status_against_a_site_with_references_imports_nothing_heavy(tmp_path):
    """The site's Touchstone references are not read (numpy) to find the daemon."""
    reference = tmp_path / "ref.s1p"
    reference.write_text("# Hz S RI R 50\n1e6 0.1 0.0\n")
    site = tmp_path / "site.yaml"
    site.write_text(f"references: {{test_load: {reference}}}\n"
                    f"daemon: {{runtime_dir: {tmp_path / 'run'}}}\n")
    found = imported("reach_receiver.cli", "run_main", ["status", "--site", str(site)])
    assert found["code"] == 1  # no daemon answers there
    assert found["heavy"] == []


def test_constants_are_the_engines_own():
    """calibration.core.constants stands in for the engine's names; they must not drift apart."""
    from calibration.choice.model_fit import OrderChoice
    from calibration.cli import import_parser
    from calibration.core.constants import ORDER_CEILING
    from calibration.io.edges_text import INTEGRATION_PER_POSITION_S, UT141C
    from calibration.rf.cal_kit import STANDARD_NAMES

    assert OrderChoice.ceiling == ORDER_CEILING
    assert import_parser.STANDARD_NAMES == STANDARD_NAMES
    assert import_parser.INTEGRATION_PER_POSITION_S == INTEGRATION_PER_POSITION_S
    assert "length" in UT141C
