"""Site files that once crashed the CLIs: a clock of compression 0, references that are not files.

Each is refused at its ``site.yaml:line: key``, by :func:`load_site` and by the real
``reach-run --site X --validate`` and ``reachd --check --site X`` command lines.
"""

import os

import pytest

from benchmarks.faults.site_files import DEVICES, S1P, S2P
from reach_receiver.cli import reachd_main, run_main
from reach_receiver.config.site import SiteError, load_site

SCHEDULE = os.path.join(os.path.dirname(__file__), "..", "schedules", "quick.yaml")


def site(tmp_path, text):
    path = tmp_path / "site.yaml"
    path.write_text(DEVICES + text)
    return path


def problem(path):
    """The one problem ``load_site`` reports for ``path``."""
    with pytest.raises(SiteError) as err:
        load_site(path)
    assert len(err.value.problems) == 1, str(err.value)
    return str(err.value.problems[0])


@pytest.mark.parametrize("value", ["0", "-5", ".nan", ".inf", "1.0e+12", "fast"])
def test_a_shared_clock_of_no_or_absurd_compression_is_refused_at_its_line(tmp_path, value):
    path = site(tmp_path, f"simulation: {{compression: {value}, start: 0, monotonic_origin: 0}}\n")
    assert problem(path).startswith(f"{path}:7: simulation.compression: must be")


def test_a_clock_with_a_negative_origin_or_missing_numbers_is_refused(tmp_path):
    path = site(tmp_path, "simulation: {compression: 10, start: 1, monotonic_origin: -1}\n")
    assert "simulation.monotonic_origin: must be in [0, inf), not -1" in problem(path)
    path = site(tmp_path, "simulation: {compression: 10}\n")
    assert "needs all of compression, start, monotonic_origin" in problem(path)


@pytest.fixture
def files(tmp_path):
    """Things a site might name as a Touchstone file."""
    os.mkfifo(tmp_path / "fifo.s1p")
    (tmp_path / "dir.s1p").mkdir()
    with open(tmp_path / "huge.s1p", "wb") as handle:
        handle.truncate(9 << 20)
    (tmp_path / "two.s2p").write_text(S2P)
    (tmp_path / "one.s1p").write_text(S1P)
    return tmp_path


@pytest.mark.parametrize(
    ("reference", "says"),
    [
        ("/etc/passwd", "/etc/passwd:1: cannot tell the number of ports"),
        ("/dev/zero", "/dev/zero is not a regular file"),
        ("fifo.s1p", "fifo.s1p is not a regular file"),
        ("dir.s1p", "dir.s1p is not a regular file"),
        ("huge.s1p", "huge.s1p is 9437184 bytes"),
        ("two.s2p", "a 2-port file, where a 1-port one is needed"),
    ],
)
def test_a_test_load_reference_must_be_a_bounded_one_port_touchstone_file(files, reference,
                                                                         says):
    path = site(files, f"references: {{test_load: {reference}}}\n")
    text = problem(path)
    assert text.startswith(f"{path}:7: references.test_load: ")
    assert says in text


def test_a_good_reference_is_taken_from_the_sites_directory_and_a_missing_one_accepted(files):
    found = load_site(site(files, "references: {test_load: one.s1p}\n"))
    assert found.references["test_load"] == str(files / "one.s1p")
    later = load_site(site(files, "references: {test_load: /etc/reach/not_yet.s1p}\n"))
    assert later.references["test_load"] == "/etc/reach/not_yet.s1p"


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("calibration: {mts: {sources: /dev/zero}}\n", "calibration.mts.sources: /dev/zero is"),
        ("calibration: {mts: {lna: one.s1p}}\n", "calibration.mts.lna: "),
        ("calibration: {cables: {hot: {s2p: dir.s1p, thermocouple: 1}}}\n",
         "calibration.cables.hot.s2p: "),
    ],
)
def test_the_corrections_two_ports_are_checked_too(files, text, says):
    assert says in problem(site(files, text))


@pytest.mark.parametrize("name", ["/dev/zero", "fifo.yaml", "big.yaml"])
def test_a_site_file_that_is_a_device_a_fifo_or_huge_is_refused_without_reading_it(
    tmp_path, name
):
    os.mkfifo(tmp_path / "fifo.yaml")
    (tmp_path / "big.yaml").write_text("#" * (2 << 20))
    path = name if name.startswith("/") else tmp_path / name
    assert "cannot read the site file" in problem(path)


def test_reach_run_and_reachd_refuse_these_sites_with_one_line_each(files, capsys):
    clock = site(files, "simulation: {compression: 0, start: 0, monotonic_origin: 0}\n")
    assert run_main(["--site", str(clock), "--validate", SCHEDULE]) == 2
    assert f"reach-run: {clock}:7: simulation.compression" in capsys.readouterr().err
    zero = files / "zero.yaml"
    zero.write_text(DEVICES + "references: {test_load: /dev/zero}\n")
    assert reachd_main(["--check", "--site", str(zero)]) == 2
    assert "references.test_load: /dev/zero is not a regular file" in capsys.readouterr().err
    assert reachd_main(["--check", "--site", "/dev/zero"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("reachd: /dev/zero:1: <file>: cannot read the site file")
    assert "Traceback" not in err
