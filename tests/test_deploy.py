"""``deploy/``: the systemd unit, udev rules, sysusers/tmpfiles files, example site, installer.

The files are checked for what the daemon and the hardware need of them (the ids of the
instruments, the unit's notify/watchdog/restart/sandbox settings, the example site that
must load and validate the shipped schedules), then used for real where the tools are
here: ``systemd-analyze verify`` and ``security`` (deploy/verify-unit.sh; .ci/run
installs Debian's systemd), ``install.sh`` into a staging root with the real
``systemd-sysusers`` and ``systemd-tmpfiles``, and the daemon's Python stack (numpy,
h5py, astropy, ctypes with a libusbtc08, a whole simulated run) under the seccomp filter
of the unit's ``MemoryDenyWriteExecute=yes``.
"""

import ctypes.util
import fcntl
import filecmp
import ipaddress
import os
import re
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from reach_receiver.cli import run_main
from reach_receiver.config.site import load_site

ROOT = Path(__file__).resolve().parents[1]
DEPLOY = ROOT / "deploy"
UNIT = DEPLOY / "reachd.service"
RULES = DEPLOY / "udev" / "99-reach.rules"
EXAMPLE_SITE = DEPLOY / "site.example.yaml"
INSTALL = DEPLOY / "install.sh"
VERIFY = DEPLOY / "verify-unit.sh"
#: Each file install.sh installs, and where.
INSTALLED = {
    "deploy/reachd.service": "/etc/systemd/system/reachd.service",
    "deploy/udev/99-reach.rules": "/etc/udev/rules.d/99-reach.rules",
    "deploy/sysusers.d/reach.conf": "/etc/sysusers.d/reach.conf",
    "deploy/tmpfiles.d/reach.conf": "/etc/tmpfiles.d/reach.conf",
    "deploy/sysctl.d/90-reach.conf": "/etc/sysctl.d/90-reach.conf",
    "deploy/modules-load.d/reach.conf": "/etc/modules-load.d/reach.conf",
    "deploy/site.example.yaml": "/etc/reach/site.yaml",
}
#: Files of deploy/ that are tools or documentation, not installed.
NOT_INSTALLED = {
    "README.md", "install.sh", "venvs.sh", "uninstall.sh", "build-wheelhouse.sh", "verify-unit.sh",
}


# -- the example site ----------------------------------------------------------------------


def test_example_site_loads_with_reach_settings():
    site = load_site(EXAMPLE_SITE)
    assert site.name == "REACH Karoo"
    assert (site.longitude_deg, site.latitude_deg) == (21.52, -30.97)
    devices = site.devices
    assert devices.teensy.port == "/dev/reach-teensy"
    match = re.fullmatch(r"TCPIP0::([^:]+)::5025::SOCKET", devices.vna.resource)
    assert match, devices.vna.resource
    assert ipaddress.ip_address(match.group(1)).is_private
    assert devices.tec.via == "teensy"
    assert devices.tc08.library == "/opt/picotech/lib/libusbtc08.so"
    spectrometer = devices.spectrometer
    assert (spectrometer.port, spectrometer.period_s) == (4660, 1.0)
    # Spectra only from the iTPM, on the spectrometer's network alone.
    assert ipaddress.ip_address(spectrometer.source).is_private
    assert ipaddress.ip_address(spectrometer.host).is_private
    assert site.references["test_load"].startswith("/etc/reach/")


def test_example_site_has_every_section_and_the_daemons_services_on_loopback():
    """Each section the site file takes is in the example, active or as a commented example."""
    from reach_receiver.config.site import SECTIONS

    text = EXAMPLE_SITE.read_text()
    for section in SECTIONS:
        if section == "simulation":  # written by reach-sim only
            continue
        assert re.search(rf"^(#   )?{section}:", text, re.M), section
    site = load_site(EXAMPLE_SITE)
    assert site.daemon.status_port == 8470
    assert site.daemon.resume is True
    assert site.monitoring.prometheus_port == 9818
    assert site.monitoring.cadence_s == 60
    # The tunnels the README gives reach exactly these ports.
    readme = (DEPLOY / "README.md").read_text()
    assert "-L 8470:127.0.0.1:8470 reach-backend" in readme
    assert "-L 9818:127.0.0.1:9818 reach-backend" in readme


def test_example_site_validates_every_shipped_schedule(capsys):
    for path in sorted((ROOT / "schedules").glob("*.yaml")):
        if path.name == "common.yaml":  # blocks and variables for the others to include
            continue
        assert run_main(["--site", str(EXAMPLE_SITE), "--validate", str(path)]) == 0, path
        assert "estimated duration" in capsys.readouterr().out


# -- udev ----------------------------------------------------------------------------------

_UDEV_TOKEN = re.compile(r'[A-Z_]+(\{[^}]+\})?(==|!=|\+=|-=|:=|=)"[^"]*"')


def config_lines(text: str) -> list[str]:
    """The lines of a udev, modules-load or similar file that are not comments."""
    return [line for line in text.splitlines() if line.strip() and not line.startswith("#")]


def rules_matching(*needles: str) -> list[str]:
    return [r for r in config_lines(RULES.read_text()) if all(n in r for n in needles)]


def test_udev_rules_are_well_formed():
    for rule in config_lines(RULES.read_text()):
        for token in rule.split(", "):
            assert _UDEV_TOKEN.fullmatch(token), f"{rule!r}: {token!r}"


def test_udev_teensy_gets_its_name_group_and_no_modemmanager():
    ids = ('ATTRS{idVendor}=="16c0"', 'ATTRS{idProduct}=="0483"')
    assert rules_matching(*ids, 'ENV{ID_MM_DEVICE_IGNORE}="1"')
    (tty,) = rules_matching(*ids, 'SUBSYSTEM=="tty"')
    for setting in ('SYMLINK+="reach-teensy"', 'GROUP="reach"', 'MODE="0660"'):
        assert setting in tty
    # The site file uses the name the rule makes.
    assert load_site(EXAMPLE_SITE).devices.teensy.port == "/dev/reach-teensy"
    bootloader = ('ATTRS{idVendor}=="16c0"', 'ATTRS{idProduct}=="0478"')
    assert rules_matching(*bootloader, 'ENV{ID_MM_DEVICE_IGNORE}="1"')


def test_udev_tc08_usb_node_for_group_reach():
    (tc08,) = rules_matching('ATTR{idVendor}=="0ce9"', 'ATTR{idProduct}=="1000"')
    for setting in ('SUBSYSTEM=="usb"', 'ENV{DEVTYPE}=="usb_device"', 'GROUP="reach"'):
        assert setting in tc08
    assert 'MODE="0660"' in tc08


def test_udev_tec_adapter_template_is_documented_and_well_formed():
    assert not rules_matching("reach-tec"), "the FTDI rule is a template, left commented"
    (template,) = [
        line
        for line in RULES.read_text().splitlines()
        if line.startswith("#SUBSYSTEM") and 'SYMLINK+="reach-tec"' in line
    ]
    for token in template[1:].split(", "):
        assert _UDEV_TOKEN.fullmatch(token), token
    assert 'ATTRS{idVendor}=="0403"' in template
    assert 'ENV{ID_MM_DEVICE_IGNORE}="1"' in template


# -- the unit ------------------------------------------------------------------------------


def unit_entries(path: Path) -> dict[str, dict[str, list[str]]]:
    """Sections -> keys -> values in order (systemd allows a key many times)."""
    sections: dict[str, dict[str, list[str]]] = {}
    current = None
    for raw in path.read_text().splitlines():
        line = raw.strip()
        if not line or line[0] in "#;":
            continue
        if line.startswith("["):
            current = sections.setdefault(line.strip("[]"), {})
            continue
        assert current is not None, line
        key, _, value = line.partition("=")
        current.setdefault(key, []).append(value)
    return sections


def seconds(value: str) -> float:
    units = {"s": 1, "sec": 1, "min": 60, "h": 3600}
    match = re.fullmatch(r"(\d+)\s*(s|sec|min|h)?", value)
    assert match, value
    return int(match.group(1)) * units[match.group(2) or "s"]


def test_unit_notify_watchdog_restart_and_stop():
    unit = unit_entries(UNIT)
    service = unit["Service"]
    one = {key: values[-1] for key, values in service.items()}
    assert one["Type"] == "notify"
    assert one["NotifyAccess"] == "main"
    assert 0 < seconds(one["WatchdogSec"]) <= 300
    assert one["Restart"] == "on-failure"  # also restarts after a watchdog timeout
    assert seconds(one["RestartSec"]) > 0
    assert "StartLimitBurst" in unit["Unit"]
    assert "StartLimitIntervalSec" in unit["Unit"]
    assert one["KillSignal"] == "SIGTERM"
    assert seconds(one["TimeoutStopSec"]) >= 60  # a cooperative stop makes the front-end safe
    # SIGHUP stops reachd, so a reload must not send it.
    assert "ExecReload" not in service
    assert unit["Install"]["WantedBy"] == ["multi-user.target"]


def test_unit_user_directories_and_command():
    service = {key: values[-1] for key, values in unit_entries(UNIT)["Service"].items()}
    assert (service["User"], service["Group"]) == ("reach", "reach")
    assert service["RuntimeDirectory"] == "reach"
    assert service["StateDirectory"] == "reach"
    command = service["ExecStart"].split()
    assert command[0] == "/opt/reach/venv/bin/reachd"
    assert command[1:] == ["--site", "/etc/reach/site.yaml"]
    assert "REACH_SITE=/etc/reach/site.yaml" in unit_entries(UNIT)["Service"]["Environment"]
    # The user the unit runs as is the one sysusers creates, at home in the state directory.
    sysusers = (DEPLOY / "sysusers.d" / "reach.conf").read_text()
    assert re.search(r'^u\s+reach\s+-\s+"[^"]+"\s+/var/lib/reach\s*$', sysusers, re.M)


#: A figure drawn and saved as calibration.report.figures does (Agg, no pyplot), in a new process.
DRAW = """
import sys
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
fig = Figure(figsize=(4, 2))
FigureCanvasAgg(fig)
fig.add_subplot().plot([1, 2, 3], label="a line")
fig.legend()
fig.savefig(sys.argv[1], format="png")
"""


def test_unit_gives_matplotlib_a_cache_directory_and_it_draws_silently(tmp_path):
    service = unit_entries(UNIT)["Service"]
    assert service["CacheDirectory"] == ["reach"]
    environment = dict(e.partition("=")[::2] for e in service["Environment"])
    assert environment["MPLCONFIGDIR"] == "%C/reach/matplotlib"  # %C: /var/cache
    # As systemd starts the service: the cache directory made, MPLCONFIGDIR inside it,
    # and a home that cannot be written (its parent is a file).
    (tmp_path / "cache" / "reach").mkdir(parents=True)
    (tmp_path / "file").touch()
    base = {k: v for k, v in os.environ.items() if not k.startswith(("XDG_", "MPL"))}
    base["HOME"] = str(tmp_path / "file" / "home")
    unit_env = {**base, "MPLCONFIGDIR": environment["MPLCONFIGDIR"].replace(
        "%C", str(tmp_path / "cache"))}

    def draw(env: dict[str, str]) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-W", "error", "-c", DRAW, str(tmp_path / "figure.png")],
            capture_output=True, text=True, timeout=120, check=False, env=env, cwd=ROOT,
        )

    drawn = draw(unit_env)  # the first start: the font cache is built
    assert drawn.returncode == 0, drawn.stderr
    assert drawn.stderr == ""  # no warning, logged or raised
    assert list((tmp_path / "cache" / "reach" / "matplotlib").glob("fontlist-*.json"))
    assert (tmp_path / "figure.png").stat().st_size > 1000
    # Without the setting, the same home makes matplotlib warn (what the setting avoids).
    unset = draw(base)
    assert unset.returncode == 0, unset.stderr
    assert "MPLCONFIGDIR" in unset.stderr


def test_unit_sandbox_keeps_the_instruments_reachable():
    service = unit_entries(UNIT)["Service"]
    one = {key: values[-1] for key, values in service.items()}
    for key, value in {
        "NoNewPrivileges": "yes",
        "ProtectSystem": "strict",
        "ProtectHome": "yes",
        "PrivateTmp": "yes",
        "ProtectKernelTunables": "yes",
        "ProtectKernelModules": "yes",
        "ProtectControlGroups": "yes",
        "LockPersonality": "yes",
        "MemoryDenyWriteExecute": "yes",
        "RestrictRealtime": "yes",
        "SystemCallArchitectures": "native",
        "DevicePolicy": "closed",
    }.items():
        assert one.get(key) == value, key
    assert one.get("PrivateDevices", "no") == "no"  # hot-plugged ttys and USB nodes
    assert set(service["DeviceAllow"]) == {
        "char-ttyACM rw",
        "char-ttyUSB rw",
        "char-usb_device rw",
    }
    families = set(one["RestrictAddressFamilies"].split())
    assert {"AF_UNIX", "AF_INET", "AF_INET6", "AF_NETLINK"} <= families
    # The device majors named in DeviceAllow exist only once their drivers are loaded.
    modules = config_lines((DEPLOY / "modules-load.d" / "reach.conf").read_text())
    assert {"cdc_acm", "ftdi_sio"} <= set(modules)


def test_unit_verifies_with_systemd_analyze():
    assert shutil.which("systemd-analyze"), "needs Debian's systemd (.ci/run installs it)"
    result = subprocess.run(
        ["bash", str(VERIFY)], capture_output=True, text=True, timeout=120, check=False
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "no warnings" in result.stdout
    assert "Overall exposure level for reachd.service" in result.stdout


def test_unit_verification_fails_on_a_warning(tmp_path):
    assert shutil.which("systemd-analyze"), "needs Debian's systemd (.ci/run installs it)"
    broken = tmp_path / "reachd.service"
    broken.write_text(UNIT.read_text().replace("[Service]\n", "[Service]\nWatchdogSecs=60s\n"))
    result = subprocess.run(
        ["bash", str(VERIFY), str(broken)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode != 0
    assert "Unknown key" in result.stdout + result.stderr


# -- install.sh ----------------------------------------------------------------------------


def test_install_script_parses():
    subprocess.run(["bash", "-n", str(INSTALL)], check=True)


def install(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["bash", str(INSTALL), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def test_install_dry_run_into_a_prefix_names_every_file_and_changes_nothing(tmp_path):
    stage = tmp_path / "stage"
    result = install("--dry-run", "--prefix", str(stage))
    assert result.returncode == 0, result.stdout + result.stderr
    out = result.stdout
    for source, destination in INSTALLED.items():
        assert f"{source} -> {stage}{destination}" in out, source
    shipped = {
        str(p.relative_to(ROOT))
        for p in DEPLOY.rglob("*")
        if p.is_file() and p.name not in NOT_INSTALLED
    }
    assert shipped == set(INSTALLED), "a file of deploy/ that install.sh does not install"
    # A new environment of its own, switched to by renaming a link over /opt/reach/venv.
    assert re.search(rf"-m venv {stage}/opt/reach/venvs/\d{{8}}T\d{{6}}Z-[^/\s]+\n", out)
    assert f"-m pip install --disable-pip-version-check --quiet {ROOT}" in out
    assert f"mv -T {stage}/opt/reach/.venv.new {stage}/opt/reach/venv" in out
    assert f"systemd-sysusers --root={stage}" in out
    assert f"systemd-tmpfiles --root={stage} --create" in out
    # A staging root only: nothing acts on the running system.
    assert "udevadm" not in out
    assert "daemon-reload" not in out
    assert not stage.exists()


def test_install_dry_run_on_the_live_system_lists_its_steps():
    result = install("--dry-run")
    assert result.returncode == 0, result.stdout + result.stderr
    out = result.stdout
    for step in (
        "systemd-sysusers /etc/sysusers.d/reach.conf",
        "systemd-tmpfiles --create /etc/tmpfiles.d/reach.conf",
        "udevadm control --reload",
        "udevadm trigger",
        "systemctl daemon-reload",
        "/opt/reach/venv/bin/reachd --check --site /etc/reach/site.yaml",
        "systemctl try-restart reachd",
        "systemctl enable --now reachd",
    ):
        assert step in out, step
    # The running daemon is restarted only once the new environment is checked and in place.
    assert out.index("would check") < out.index("mv -T") < out.index("try-restart")


def test_uninstall_dry_run_on_the_live_system_lists_its_steps():
    result = install("--uninstall", "--dry-run")
    assert result.returncode == 0, result.stdout + result.stderr
    out = result.stdout
    for step in (
        "systemctl disable --now reachd",
        "rm -f /etc/systemd/system/reachd.service",
        "rm -rf /opt/reach",
        "systemctl daemon-reload",
    ):
        assert step in out, step
    # Without --purge nothing of the data, the site file or the user is touched.
    removals = [line for line in out.splitlines() if "would run" in line]
    assert not [line for line in removals if "/var/lib/reach" in line or "/etc/reach" in line]
    assert "userdel" not in out


def test_install_refuses_mixed_or_bad_options(tmp_path):
    for args, message in (
        (["--purge"], "--purge goes with --uninstall"),
        (["--keep", "0"], "--keep takes a whole number"),
        (["--wheelhouse", str(tmp_path / "missing")], "no such directory"),
        (["--wheelhouse", str(tmp_path)], "holds no wheels"),
        (["--rollback", "--wheelhouse", str(tmp_path)], "--wheelhouse goes with an install"),
        (["--wheelhouse"], "--wheelhouse needs a value"),
    ):
        result = install("--dry-run", *args)
        assert result.returncode == 2, args
        assert result.stderr.startswith("install.sh: "), args
        assert message in result.stderr, (args, result.stderr)
        assert len(result.stderr.splitlines()) == 1


def test_install_rejects_unknown_arguments():
    result = install("--prefx", "/tmp/x")
    assert result.returncode == 2
    assert "unknown argument" in result.stderr


def test_install_into_a_staging_root(tmp_path):
    missing = [t for t in ("systemd-sysusers", "systemd-tmpfiles") if shutil.which(t) is None]
    assert not missing, f"needs {', '.join(missing)}: Debian's systemd (.ci/run installs it)"
    assert os.geteuid() == 0, "systemd-tmpfiles gives /etc/reach to root:reach: run as root"
    stage = tmp_path / "stage"
    result = install("--skip-venv", "--prefix", str(stage))
    assert result.returncode == 0, result.stdout + result.stderr
    for source, destination in INSTALLED.items():
        assert filecmp.cmp(ROOT / source, stage / destination.lstrip("/"), shallow=False)
    users = {
        line.split(":")[0]: line.split(":")
        for line in (stage / "etc/passwd").read_text().splitlines()
    }
    groups = {
        line.split(":")[0]: line.split(":")
        for line in (stage / "etc/group").read_text().splitlines()
    }
    uid, gid = int(users["reach"][2]), int(groups["reach"][2])
    assert users["reach"][5] == "/var/lib/reach"
    etc_reach = (stage / "etc/reach").stat()
    assert (stat.S_IMODE(etc_reach.st_mode), etc_reach.st_uid, etc_reach.st_gid) == (0o750, 0, gid)
    state = (stage / "var/lib/reach").stat()
    assert (stat.S_IMODE(state.st_mode), state.st_uid, state.st_gid) == (0o750, uid, gid)
    site = stage / "etc/reach/site.yaml"
    assert (stat.S_IMODE(site.stat().st_mode), site.stat().st_gid) == (0o640, gid)
    assert load_site(site).devices == load_site(EXAMPLE_SITE).devices
    # --skip-venv: the Python environments (and the schedules kept with them) untouched;
    # tests/test_deploy_offline.py installs them.
    assert [p.name for p in (stage / "opt/reach").iterdir()] == [".install.lock"]

    # Again, after the operator edited the site file: it is kept, the rest is unchanged.
    site.write_text(site.read_text() + "# edited on site\n")
    again = install("--skip-venv", "--prefix", str(stage))
    assert again.returncode == 0, again.stdout + again.stderr
    assert site.read_text().endswith("# edited on site\n")
    assert f"unchanged {stage}/etc/systemd/system/reachd.service" in again.stdout
    passwd = (stage / "etc/passwd").read_text().splitlines()
    assert [line for line in passwd if line.startswith("reach:")] == [":".join(users["reach"])]


# -- MemoryDenyWriteExecute=yes ------------------------------------------------------------

#: Installs the seccomp filter that systemd 252 installs for MemoryDenyWriteExecute=yes
#: (src/shared/seccomp-util.c: refuse mmap with PROT_WRITE|PROT_EXEC, mprotect and
#: pkey_mprotect adding PROT_EXEC, shmat with SHM_EXEC; EPERM), then runs argv[1:].
WX_EXEC = r"""
import ctypes, ctypes.util, errno, os, sys

PROT_WRITE, PROT_EXEC, SHM_EXEC = 0x2, 0x4, 0o100000
SCMP_ACT_ALLOW, SCMP_ACT_ERRNO = 0x7FFF0000, 0x00050000
SCMP_CMP_MASKED_EQ = 7


class ArgCmp(ctypes.Structure):
    _fields_ = [("arg", ctypes.c_uint), ("op", ctypes.c_int),
                ("datum_a", ctypes.c_uint64), ("datum_b", ctypes.c_uint64)]


seccomp = ctypes.CDLL(ctypes.util.find_library("seccomp"))
seccomp.seccomp_init.restype = ctypes.c_void_p
seccomp.seccomp_init.argtypes = [ctypes.c_uint32]
seccomp.seccomp_syscall_resolve_name.argtypes = [ctypes.c_char_p]
seccomp.seccomp_rule_add_array.argtypes = [
    ctypes.c_void_p, ctypes.c_uint32, ctypes.c_int, ctypes.c_uint, ctypes.POINTER(ArgCmp)]
seccomp.seccomp_load.argtypes = [ctypes.c_void_p]
context = seccomp.seccomp_init(SCMP_ACT_ALLOW)
for name, mask, value in (
    ("mmap", PROT_WRITE | PROT_EXEC, PROT_WRITE | PROT_EXEC),
    ("mprotect", PROT_EXEC, PROT_EXEC),
    ("pkey_mprotect", PROT_EXEC, PROT_EXEC),
    ("shmat", SHM_EXEC, SHM_EXEC),
):
    number = seccomp.seccomp_syscall_resolve_name(name.encode())
    rule = ArgCmp(2, SCMP_CMP_MASKED_EQ, mask, value)
    action = SCMP_ACT_ERRNO | errno.EPERM
    assert seccomp.seccomp_rule_add_array(context, action, number, 1, ctypes.byref(rule)) == 0
assert ctypes.CDLL(None).prctl(38, 1, 0, 0, 0) == 0  # PR_SET_NO_NEW_PRIVS, as systemd does
assert seccomp.seccomp_load(context) == 0
os.execv(sys.argv[1], sys.argv[1:])
"""

#: The daemon's libraries under the filter; first, that the filter is really there.
STACK_CHECK = r"""
import mmap, sys, tempfile, time
from pathlib import Path
try:
    mmap.mmap(-1, 4096, prot=mmap.PROT_READ | mmap.PROT_WRITE | mmap.PROT_EXEC)
    sys.exit("W+X memory was allowed: the filter is not in place")
except OSError:
    pass
import ctypes
import h5py, numpy, pyvisa, scipy.linalg, serial, usb.core, yaml
from calibration.core.sidereal import apparent_lst_h
from reach_receiver.sim.tc08_standin import build_standin
from reach_receiver.transports.tc08_library import load_libusbtc08

assert ctypes.CFUNCTYPE(ctypes.c_int)(lambda: 7)() == 7  # a libffi closure
a = numpy.random.default_rng(1).normal(size=(100, 100))
scipy.linalg.cho_factor(a @ a.T + 100 * numpy.eye(100))
with tempfile.TemporaryDirectory() as directory:
    with h5py.File(Path(directory) / "x.h5", "w") as f:
        f["x"] = numpy.arange(3)
    load_libusbtc08(str(build_standin(Path(directory) / "tc08")))
assert 0 <= apparent_lst_h(numpy.array([time.time()]), 21.52)[0] < 24
print("stack ok")
"""


@pytest.fixture
def wx_exec(tmp_path):
    assert ctypes.util.find_library("seccomp"), "needs libseccomp (Debian's systemd brings it)"
    assert shutil.which("cc") or shutil.which("gcc"), "needs a C compiler (the TC-08 stand-in)"
    script = tmp_path / "wx_exec.py"
    script.write_text(WX_EXEC)
    return [sys.executable, str(script)]


def test_python_stack_and_libusbtc08_load_without_wx_memory(wx_exec):
    result = subprocess.run(
        [*wx_exec, sys.executable, "-c", STACK_CHECK],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "stack ok" in result.stdout


def test_a_library_with_an_executable_stack_is_refused(wx_exec, tmp_path):
    """Why install.sh tries the site's real libusbtc08 under the setting."""
    source = tmp_path / "f.c"
    source.write_text("int f(void) { return 3; }\n")
    library = tmp_path / "libexecstack.so"
    compiler = shutil.which("cc") or "gcc"
    subprocess.run(
        [compiler, "-shared", "-fPIC", "-Wl,-z,execstack", "-o", str(library), str(source)],
        check=True,
    )
    load = f"import ctypes; ctypes.CDLL({str(library)!r})"
    plain = subprocess.run(
        [sys.executable, "-c", load], capture_output=True, text=True, check=False
    )
    assert plain.returncode == 0, plain.stderr
    filtered = subprocess.run(
        [*wx_exec, sys.executable, "-c", load], capture_output=True, text=True, check=False
    )
    assert filtered.returncode != 0
    assert "executable stack" in filtered.stderr


def test_a_simulated_run_completes_without_wx_memory(wx_exec, tmp_path):
    """The quick schedule end to end: pty serial, TCP VNA, UDP spectra, TC-08, HDF5, engine."""
    code = (
        "import sys; from reach_receiver.cli import run_main; "
        f"sys.exit(run_main(['--sim', '-q', '--out', {str(tmp_path)!r}, "
        f"{str(ROOT / 'schedules' / 'quick.yaml')!r}]))"
    )
    result = subprocess.run(
        [*wx_exec, sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
        cwd=ROOT,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "check test load: PASS" in result.stdout + result.stderr
    (run,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert (run / "run.h5").is_file()


def test_install_adopts_the_environment_of_the_previous_layout(tmp_path):
    """/opt/reach/venv was a directory before environments were versioned: it is moved
    among them (so it can be rolled back to) before the link takes its place."""
    stage = tmp_path / "stage"
    (stage / "opt/reach/venv/bin").mkdir(parents=True)
    result = install("--dry-run", "--root", str(stage))
    assert result.returncode == 0, result.stdout + result.stderr
    out = result.stdout
    legacy = rf"{stage}/opt/reach/venvs/\d{{8}}T\d{{6}}Z-legacy"
    moved = re.search(rf"would run: mv -T {stage}/opt/reach/venv {legacy}\n", out)
    assert moved, out
    assert out.index(moved.group(0)) < out.index(f"mv -T {stage}/opt/reach/.venv.new")
    assert (stage / "opt/reach/venv/bin").is_dir()  # a dry run


def test_rollback_without_environments_is_refused(tmp_path):
    result = install("--rollback", "--root", str(tmp_path))
    assert result.returncode == 1
    assert result.stderr.startswith("install.sh: ")
    assert "is not a link to an environment" in result.stderr
    assert len(result.stderr.splitlines()) == 1


def test_install_help_names_every_option():
    result = install("--help")
    assert result.returncode == 0
    for option in ("--wheelhouse DIR", "--rollback", "--uninstall", "--purge", "--dry-run",
                   "--root DIR", "--no-restart", "--keep N", "--skip-venv"):
        assert option in result.stdout, option
    assert result.stdout.rstrip().endswith("deploy/README.md tells the whole procedure.")
    assert "set -euo" not in result.stdout


def test_one_install_at_a_time(tmp_path):
    """A second install.sh on the same root is refused while the first holds the lock."""
    lock = tmp_path / "opt/reach/.install.lock"
    lock.parent.mkdir(parents=True)
    with lock.open("w") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        result = install("--rollback", "--root", str(tmp_path))
    assert result.returncode == 1
    assert result.stderr.startswith("install.sh: another install.sh is working on")
    assert len(result.stderr.splitlines()) == 1
