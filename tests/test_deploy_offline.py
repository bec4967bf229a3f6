"""``deploy/install.sh --wheelhouse``: install, upgrade, rollback, uninstall with no network.

Where the wheels come from. On site, the wheelhouse is built on a machine with internet
by ``deploy/build-wheelhouse.sh``, which downloads every dependency's wheel from the
package index. Here there is no network, no pip cache, and pip cannot rebuild wheels of
installed distributions; ``--system-site-packages`` would let the environment see this
interpreter's packages and hide a dependency missing from the wheelhouse. So the test
packs the distributions installed in this interpreter (the receiver's dependencies, and
setuptools, the build backend) back into wheels (:func:`repack`: each one's files as its
``RECORD`` lists them, its own metadata and tags; no byte code, no console scripts, which
pip regenerates). That directory stands in for the package index: build-wheelhouse.sh
runs against it unchanged, through pip's own settings (``PIP_NO_INDEX``,
``PIP_FIND_LINKS``), for a Debian 12 amd64 target, and install.sh installs from the
wheelhouse it builds, building the checkout there with the backend from it.

No network: every script runs in a network namespace of its own (``unshare --net``: a
loopback that is down, nothing else) where this machine allows it, and always with
``PIP_NO_INDEX=1``, no pip configuration file, and proxies on a closed port.

The sequence runs once (module fixture: 1-2 min on two cores, two environments of ~300 MB each):
install 0.1.0 into a staging root, upgrade to 0.1.1 (a copy of the checkout whose
version was raised) with ``--keep 2`` beside an old environment, which is pruned, an
upgrade from a wheelhouse lacking a dependency (refused, nothing changed), a rollback
to 0.1.0, a second rollback (refused: none older), uninstall, purge. Byte-compiling is
left out to save time (``PIP_NO_COMPILE=0``: pip reads that switch inverted).
"""

from __future__ import annotations

import base64
import hashlib
import importlib.metadata as metadata
import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path
from typing import Any

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]
OLD = "20000101T000000Z-0.0.9-old"  # an environment left by an earlier upgrade

pytestmark = pytest.mark.timeout(600)


def closure(name: str) -> dict[str, metadata.Distribution]:
    """The installed distribution ``name`` and everything it needs, by canonical name.

    Extras are followed: ``dask[distributed]`` brings ``dask`` and the requirements its
    metadata marks ``extra == "distributed"``.
    """
    found: dict[str, metadata.Distribution] = {}
    seen: set[tuple[str, frozenset[str]]] = set()
    todo: list[tuple[str, frozenset[str]]] = [(name, frozenset())]
    while todo:
        raw, extras = todo.pop()
        key = canonicalize_name(raw)
        if (key, extras) in seen:
            continue
        seen.add((key, extras))
        dist = found.setdefault(key, metadata.distribution(key))
        for line in dist.requires or []:
            requirement = Requirement(line)
            marker = requirement.marker
            if marker is None or any(marker.evaluate({"extra": e}) for e in ("", *extras)):
                todo.append((requirement.name, frozenset(requirement.extras)))
    return found


def repack(dist: metadata.Distribution, out: Path) -> Path:
    """The installed ``dist`` as a wheel in ``out``: its files, metadata and tags."""
    tags = [line.split(":", 1)[1].strip().split("-")
            for line in (dist.read_text("WHEEL") or "").splitlines() if line.startswith("Tag:")]
    assert tags, f"{dist.metadata['Name']} was not installed from a wheel"
    tag = "-".join(".".join(sorted({t[i] for t in tags})) for i in range(3))
    name = re.sub(r"[-_.]+", "_", dist.metadata["Name"])
    wheel = out / f"{name}-{dist.version}-{tag}.whl"
    record, info = [], ""
    with zipfile.ZipFile(wheel, "w", zipfile.ZIP_STORED) as archive:
        for file in dist.files or []:
            path = str(file)
            top = path.split("/")[0]
            if path.startswith("..") or "__pycache__" in path:  # scripts, man pages, byte code
                continue
            if top.endswith(".dist-info"):
                info = top
                if path.count("/") == 1 and file.name in (
                    "RECORD", "INSTALLER", "REQUESTED", "direct_url.json"
                ):
                    continue
            data = Path(str(dist.locate_file(file))).read_bytes()
            archive.writestr(path, data)
            digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=")
            record.append(f"{path},sha256={digest.decode()},{len(data)}")
        record.append(f"{info}/RECORD,,")
        archive.writestr(f"{info}/RECORD", "\n".join(record) + "\n")
    return wheel


def offline_env(tmp: Path) -> dict[str, str]:
    """This environment with pip cut off from any index and the network."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("PIP_") and k.lower() not in ("no_proxy", "all_proxy")}
    env.update(
        PIP_CONFIG_FILE=os.devnull,
        PIP_NO_INDEX="1",
        PIP_NO_COMPILE="0",
        PIP_DISABLE_PIP_VERSION_CHECK="1",
        https_proxy="http://127.0.0.1:9",
        http_proxy="http://127.0.0.1:9",
        HTTPS_PROXY="http://127.0.0.1:9",
        HTTP_PROXY="http://127.0.0.1:9",
        PYTHON=sys.executable,
        TMPDIR=str(tmp),
    )
    return env


def isolated() -> list[str]:
    """``unshare --net`` where this machine lets the test make a network namespace."""
    probe = subprocess.run(["unshare", "--net", "true"], capture_output=True, check=False)
    return ["unshare", "--net"] if probe.returncode == 0 else []


def copy_checkout(destination: Path, version: str | None = None) -> Path:
    """The checkout's files (tracked and new) copied to ``destination``, version changed."""
    listed = subprocess.run(
        ["git", "-C", str(ROOT), "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        capture_output=True, check=True,
    ).stdout.decode().split("\0")
    for name in filter(None, listed):
        source = ROOT / name
        if source.is_file():
            (destination / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, destination / name)
    if version is not None:
        pyproject = destination / "pyproject.toml"
        text = re.sub(r'(?m)^version = ".*"$', f'version = "{version}"', pyproject.read_text())
        pyproject.write_text(text)
    return destination


def accounts(stage: Path) -> dict[str, bool]:
    """Whether the staging root has the user and the group reach."""
    def has(file: str) -> bool:
        return bool(re.search(r"^reach:", (stage / "etc" / file).read_text(), re.M))
    return {"user": has("passwd"), "group": has("group")}


def reachd_version(stage: Path) -> str:
    """What the unit's command (through the link) says its version is."""
    reachd = stage / "opt/reach/venv/bin/reachd"
    return subprocess.run([str(reachd), "--version"], capture_output=True, text=True,
                          check=True, timeout=60).stdout.strip()


@pytest.fixture(scope="module")
def deployed(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The whole sequence, each step's result and what the staging root held after it."""
    for tool in ("systemd-sysusers", "systemd-tmpfiles", "git"):
        assert shutil.which(tool), f"needs {tool} (.ci/run installs Debian's systemd)"
    assert os.geteuid() == 0, "systemd-tmpfiles gives /etc/reach to root:reach: run as root"
    setuptools = tuple(int(part) for part in metadata.version("setuptools").split(".")[:2])
    assert setuptools >= (70, 1), "needs setuptools 70.1 (the build backend packed here): " \
        "pip install -e '.[test]'"
    base = tmp_path_factory.mktemp("offline")
    (base / "tmp").mkdir()
    env = offline_env(base / "tmp")
    prefix = isolated()

    def script(path: Path, *args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([*prefix, "bash", str(path), *args], capture_output=True,
                              text=True, env=env, timeout=300, check=False, cwd=base)

    index = base / "index"  # the stand-in for the package index
    index.mkdir()
    for dist in [*closure("reach-receiver").values(), metadata.distribution("setuptools")]:
        if canonicalize_name(dist.metadata["Name"]) != "reach-receiver":
            repack(dist, index)
    v1 = copy_checkout(base / "v1")
    v2 = copy_checkout(base / "v2", version="0.1.1")
    wheelhouse = base / "wheelhouse"
    stage = base / "stage"
    steps: dict[str, Any] = {"stage": stage, "wheelhouse": wheelhouse, "prefix": prefix}

    env["PIP_FIND_LINKS"] = str(index)
    steps["build"] = script(v1 / "deploy/build-wheelhouse.sh", "--python-version",
                            f"{sys.version_info.major}.{sys.version_info.minor}",
                            "--platform", "manylinux_2_36_x86_64", str(wheelhouse))
    del env["PIP_FIND_LINKS"]  # from here on, the wheelhouse alone
    assert steps["build"].returncode == 0, steps["build"].stdout + steps["build"].stderr

    steps["install"] = script(v1 / "deploy/install.sh", "--wheelhouse", str(wheelhouse),
                              "--root", str(stage))
    assert steps["install"].returncode == 0, steps["install"].stdout + steps["install"].stderr
    venv = stage / "opt/reach/venv"
    steps["installed"] = {
        "pyvenv.cfg": (venv / "pyvenv.cfg").read_text(),
        "imported from": subprocess.run(
            [str(venv / "bin/python"), "-c", "import numpy, scipy, astropy, reach_receiver; "
             "print(numpy.__file__, scipy.__file__, astropy.__file__, reach_receiver.__file__)"],
            capture_output=True, text=True, check=True, timeout=120, cwd="/",
        ).stdout.split(),
        "version": reachd_version(stage),
        "unit": (stage / "etc/systemd/system/reachd.service").read_text(),
        "reach-run": os.readlink(stage / "usr/local/bin/reach-run"),
        "link": os.readlink(stage / "opt/reach/venv"),
        "schedules": sorted(p.name for p in (stage / "opt/reach/schedules").iterdir()),
        "INSTALLED": (stage / "opt/reach/INSTALLED").read_text(),
    }
    # An environment of an earlier upgrade, for --keep to remove.
    (stage / "opt/reach/venvs" / OLD / "bin").mkdir(parents=True)
    # The data and the site file of months of observing, which no step but purge touches.
    runs = stage / "var/lib/reach/runs/20261101T000000Z-observe"
    runs.mkdir(parents=True)
    (runs / "run.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(100))
    site = stage / "etc/reach/site.yaml"
    site.write_text(site.read_text() + "# edited on site\n")

    steps["upgrade"] = script(v2 / "deploy/install.sh", "--wheelhouse", str(wheelhouse),
                              "--root", str(stage), "--keep", "2")
    assert steps["upgrade"].returncode == 0, steps["upgrade"].stdout + steps["upgrade"].stderr
    steps["upgraded"] = {
        "version": reachd_version(stage),
        "link": os.readlink(stage / "opt/reach/venv"),
        "venvs": sorted(p.name for p in (stage / "opt/reach/venvs").iterdir()),
    }

    # A wheelhouse that lacks a dependency: the upgrade stops before changing anything.
    partial = base / "partial"
    partial.mkdir()
    for wheel in wheelhouse.glob("*.whl"):
        if not wheel.name.startswith("pyusb-"):
            os.link(wheel, partial / wheel.name)
    steps["broken"] = script(v1 / "deploy/install.sh", "--wheelhouse", str(partial),
                             "--root", str(stage))
    steps["after broken"] = {
        "link": os.readlink(stage / "opt/reach/venv"),
        "venvs": sorted(p.name for p in (stage / "opt/reach/venvs").iterdir()),
    }

    steps["rollback"] = script(v2 / "deploy/install.sh", "--rollback", "--root", str(stage))
    steps["rolled back"] = {"version": reachd_version(stage),
                            "link": os.readlink(stage / "opt/reach/venv")}
    steps["rollback again"] = script(v2 / "deploy/install.sh", "--rollback", "--root", str(stage))

    steps["uninstall"] = script(v2 / "deploy/install.sh", "--uninstall", "--root", str(stage))
    steps["uninstalled"] = {p.relative_to(stage).as_posix() for p in stage.rglob("*")}
    steps["site after uninstall"] = site.read_text()
    steps["accounts after uninstall"] = accounts(stage)
    steps["purge"] = script(v2 / "deploy/install.sh", "--uninstall", "--purge",
                            "--root", str(stage))
    steps["purged"] = {p.relative_to(stage).as_posix() for p in stage.rglob("*")}
    steps["accounts after purge"] = accounts(stage)
    steps["wheels"] = sorted(p.name for p in wheelhouse.glob("*.whl"))
    # About 1 GB of wheels, environments and copies: not left for pytest's kept temp dirs.
    shutil.rmtree(base)
    return steps


def test_the_network_is_really_cut_off():
    env = offline_env(Path("/tmp"))
    result = subprocess.run(
        [*isolated(), sys.executable, "-m", "pip", "download", "--no-deps", "-d",
         os.devnull, "--index-url", "https://pypi.org/simple", "six"],
        capture_output=True, text=True, env=env, timeout=120, check=False,
    )
    assert result.returncode != 0


def test_wheelhouse_holds_every_dependency_and_the_build_backend(deployed):
    wheels = {canonicalize_name(name.split("-")[0]) for name in deployed["wheels"]}
    needed = set(closure("reach-receiver")) - {"reach-receiver"}
    assert needed <= wheels
    assert "setuptools" in wheels  # pyproject's build-system.requires: the checkout is built there
    assert "reach-receiver" not in wheels  # the checkout is, not a wheel of one commit
    # Binary wheels only, each for CPython of this version on glibc 2.36 or older.
    for wheel in deployed["wheels"]:
        _python, abi, platform = wheel[:-4].split("-")[-3:]
        assert platform == "any" or re.fullmatch(r"(manylinux[_0-9]*_x86_64\.?)+", platform), wheel
        assert abi in ("none", "abi3", f"cp{sys.version_info.major}{sys.version_info.minor}"), wheel


def test_install_from_the_wheelhouse_without_network(deployed):
    out = deployed["install"].stdout
    installed = deployed["installed"]
    assert installed["version"] == "reachd 0.1.0"
    assert re.fullmatch(r"venvs/\d{8}T\d{6}Z-0\.1\.0-nogit", installed["link"])
    assert f"from: the wheelhouse {deployed['wheelhouse']}" in installed["INSTALLED"]
    shipped = sorted(p.name for p in (ROOT / "schedules").glob("*.yaml"))
    assert installed["schedules"] == shipped
    # Checked before the switch: dependencies, the command, every module, the site file.
    for check in ("No broken requirements found.", "reachd 0.1.0", "modules import"):
        assert out.index(check) < out.index("switching"), check
    assert "site.example.yaml reads" in out
    # The unit's command and the operators' commands go through the link.
    assert "ExecStart=/opt/reach/venv/bin/reachd " in installed["unit"]
    assert installed["reach-run"] == "/opt/reach/venv/bin/reach-run"
    assert "systemctl try-restart reachd" in out  # not run in a staging root: said


def test_the_environment_holds_its_own_dependencies(deployed):
    """From the wheelhouse, not from this interpreter's site-packages."""
    installed = deployed["installed"]
    assert "include-system-site-packages = false" in installed["pyvenv.cfg"]
    reach = str(deployed["stage"] / "opt/reach") + "/"
    assert len(installed["imported from"]) == 4
    assert all(path.startswith(reach) for path in installed["imported from"])


def test_upgrade_is_a_new_environment_and_prunes_the_oldest(deployed):
    upgraded, installed = deployed["upgraded"], deployed["installed"]
    assert upgraded["version"] == "reachd 0.1.1"
    assert re.fullmatch(r"venvs/\d{8}T\d{6}Z-0\.1\.1-nogit", upgraded["link"])
    # --keep 2: the new one and the one before it; the older one removed.
    assert upgraded["venvs"] == sorted([installed["link"][6:], upgraded["link"][6:]])
    assert OLD not in upgraded["venvs"]
    assert "kept the existing" in deployed["upgrade"].stdout  # the site file


def test_an_upgrade_that_cannot_complete_changes_nothing(deployed):
    broken = deployed["broken"]
    assert broken.returncode == 1
    message = broken.stderr.strip().splitlines()[-1]
    assert message.startswith("install.sh: the new environment failed")
    assert "build-wheelhouse.sh" in message
    assert "pyusb" in broken.stdout + broken.stderr  # pip names what is missing
    assert "switching" not in broken.stdout
    assert deployed["after broken"]["link"] == deployed["upgraded"]["link"]
    assert deployed["after broken"]["venvs"] == deployed["upgraded"]["venvs"]


def test_rollback_switches_to_the_previous_environment(deployed):
    assert deployed["rollback"].returncode == 0, deployed["rollback"].stderr
    assert deployed["rolled back"] == {
        "version": "reachd 0.1.0", "link": deployed["installed"]["link"]}
    again = deployed["rollback again"]
    assert again.returncode == 1
    assert again.stderr.startswith("install.sh: no environment older than")
    assert len(again.stderr.splitlines()) == 1


def test_uninstall_keeps_the_data_the_site_file_and_the_user(deployed):
    assert deployed["uninstall"].returncode == 0, deployed["uninstall"].stderr
    left = deployed["uninstalled"]
    assert not [p for p in left if p.startswith("opt/")]
    assert "etc/systemd/system/reachd.service" not in left
    assert not [p for p in left if p.startswith("usr/local/bin/")]
    assert "var/lib/reach/runs/20261101T000000Z-observe/run.h5" in left
    assert "etc/reach/site.yaml" in left
    assert deployed["site after uninstall"].endswith("# edited on site\n")
    assert deployed["accounts after uninstall"] == {"user": True, "group": True}
    # --purge: those too.
    assert deployed["purge"].returncode == 0, deployed["purge"].stderr
    assert "etc/reach/site.yaml" not in deployed["purged"]
    assert not [p for p in deployed["purged"] if p.startswith("var/lib/reach")]
    assert deployed["accounts after purge"] == {"user": False, "group": False}
