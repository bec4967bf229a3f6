"""Layers import only downwards, and README's layer table is the import graph's truth.

README.md's table (under "### Layers") gives each package of ``reach_receiver`` a rank; a
module may import only from packages of a lower rank, packages of one rank not from each
other, and the calibration engine nothing of the receiver side. Every import statement
counts, inside functions and ``TYPE_CHECKING`` blocks too.
"""

import ast
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ENGINE = "calibration"


def layer_table(readme: str) -> dict[str, int]:
    """Package -> rank, from the README table under '### Layers'."""
    section = readme.split("### Layers", 1)[1].split("\n#", 1)[0]
    ranks: dict[str, int] = {}
    for row in section.splitlines():
        cells = [c.strip() for c in row.strip().strip("|").split("|")]
        if len(cells) < 3 or not cells[0].isdigit():
            continue
        for package in re.findall(r"`([\w.]+)`", cells[2]):
            ranks[package] = int(cells[0])
    return ranks


def unit(module: str) -> str:
    """The package a module belongs to for layering: ``reach_receiver.<first>``."""
    parts = module.split(".")
    return parts[0] if parts[0] == ENGINE else ".".join(parts[:2])


def imports(root: Path) -> Iterator[tuple[str, str, str]]:
    """(importing module, imported module, file:line) for every import of ours under root."""
    for path in sorted([*root.glob("reach_receiver/**/*.py"), *root.glob(f"{ENGINE}/**/*.py")]):
        module = ".".join(path.relative_to(root).with_suffix("").parts)
        package = module.removesuffix(".__init__")
        if path.name != "__init__.py":
            package = module.rsplit(".", 1)[0]
        module = module.removesuffix(".__init__")
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    names = [".".join([*base, *([node.module] if node.module else [])])]
                else:
                    names = [node.module or ""]
            elif isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            else:
                continue
            for name in names:
                if name.split(".")[0] in ("reach_receiver", ENGINE):
                    yield module, name, f"{path.relative_to(root)}:{node.lineno}"


def violations(root: Path, ranks: dict[str, int]) -> list[str]:
    """Every import against the table: upward, sideways, engine to receiver, unlisted."""
    found = []
    for importer, imported, where in imports(root):
        a, b = unit(importer), unit(imported)
        if a == b or b == ENGINE or a == "reach_receiver" or b == "reach_receiver":
            continue
        if a == ENGINE:
            found.append(f"{where}: the engine imports {imported}")
        elif a not in ranks or b not in ranks:
            found.append(f"{where}: {a if a not in ranks else b} is not in README's table")
        elif ranks[b] >= ranks[a]:
            found.append(f"{where}: {a} (rank {ranks[a]}) imports {b} (rank {ranks[b]})")
    return found


def test_every_import_goes_down_the_readme_s_layer_table():
    ranks = layer_table((ROOT / "README.md").read_text())
    assert violations(ROOT, ranks) == []


def test_the_table_lists_exactly_the_packages_that_exist():
    ranks = layer_table((ROOT / "README.md").read_text())
    existing = {
        unit(".".join(p.relative_to(ROOT).with_suffix("").parts))
        for p in (ROOT / "reach_receiver").glob("*")
        if p.name != "__init__.py" and (p.suffix == ".py" or (p / "__init__.py").exists())
    }
    assert set(ranks) == existing


@pytest.mark.parametrize(
    ("module", "text", "expected"),
    [
        ("devices/bad.py", "from reach_receiver.frontend.layout import X\n", "imports"),
        ("store/bad.py", "from ..schedule import steps\n", "imports"),  # sideways
        ("frontend/bad.py", "def f():\n    import reach_receiver.run.session\n", "imports"),
        ("../calibration/bad.py", "from reach_receiver.store import RunStore\n", "engine"),
    ],
)
def test_the_check_catches_an_upward_import(tmp_path, module, text, expected):
    tree = tmp_path / "reach_receiver"
    for package in ("devices", "frontend", "store", "schedule", "run"):
        (tree / package).mkdir(parents=True)
        (tree / package / "__init__.py").write_text("")
    (tmp_path / ENGINE).mkdir()
    (tree / module).write_text(text)
    ranks = {
        "reach_receiver.devices": 2,
        "reach_receiver.frontend": 3,
        "reach_receiver.store": 5,
        "reach_receiver.schedule": 5,
        "reach_receiver.run": 6,
    }
    (found,) = violations(tmp_path, ranks)
    assert expected in found


def engine_table(readme: str) -> dict[str, int]:
    """Engine subpackage -> rank, from the README table under '### Engine layers'."""
    section = readme.split("### Engine layers", 1)[1].split("\n#", 1)[0]
    ranks: dict[str, int] = {}
    for row in section.splitlines():
        cells = [c.strip() for c in row.strip().strip("|").split("|")]
        if len(cells) >= 2 and cells[0].isdigit():
            ranks[cells[1].strip("`")] = int(cells[0])
    return ranks


def engine_unit(module: str) -> str:
    """The engine subpackage a module belongs to: ``calibration.<first>``."""
    return ".".join(module.split(".")[:2])


def engine_violations(root: Path, ranks: dict[str, int]) -> list[str]:
    """Every import inside the engine against its table: upward, sideways, unlisted."""
    found = []
    for importer, imported, where in imports(root):
        if not (importer.startswith(f"{ENGINE}.") and imported.startswith(f"{ENGINE}.")):
            continue
        a, b = engine_unit(importer), engine_unit(imported)
        if a == b:
            continue
        if a not in ranks or b not in ranks:
            found.append(f"{where}: {a if a not in ranks else b} is not in README's engine table")
        elif ranks[b] >= ranks[a]:
            found.append(f"{where}: {a} (rank {ranks[a]}) imports {b} (rank {ranks[b]})")
    return found


def test_the_engine_s_imports_go_down_its_table():
    ranks = engine_table((ROOT / "README.md").read_text())
    assert engine_violations(ROOT, ranks) == []


def test_the_engine_table_lists_exactly_its_subpackages():
    ranks = engine_table((ROOT / "README.md").read_text())
    existing = {f"{ENGINE}.{p.name}" for p in (ROOT / ENGINE).iterdir()
                if (p / "__init__.py").exists()}
    assert set(ranks) == existing
    assert not [p.name for p in (ROOT / ENGINE).glob("*.py") if p.name != "__init__.py"]


def test_an_engine_subpackage_s_init_imports_nothing():
    """A subpackage's ``__init__`` is its docstring: importing one part costs no other.

    ``calibration.cli``, the top, holds ``reach-cal``'s entry point (``calibration.cli:main``).
    """
    for init in (ROOT / ENGINE).glob("*/__init__.py"):
        if init.parent.name == "cli":
            continue
        body = ast.parse(init.read_text()).body
        assert ast.get_docstring(ast.parse(init.read_text())), init
        assert not [n for n in body if isinstance(n, (ast.Import, ast.ImportFrom))], init


@pytest.mark.parametrize(
    ("module", "text"),
    [
        ("rf/bad.py", "from ..solve.solution import Solution\n"),  # upward
        ("io/bad.py", "def f():\n    from calibration.checks import rfi\n"),  # sideways
    ],
)
def test_the_engine_check_catches_an_upward_or_sideways_import(tmp_path, module, text):
    for package in ("rf", "solve", "checks", "io"):
        (tmp_path / ENGINE / package).mkdir(parents=True)
        (tmp_path / ENGINE / package / "__init__.py").write_text('"""x."""\n')
    (tmp_path / ENGINE / module).write_text(text)
    ranks = {f"{ENGINE}.rf": 1, f"{ENGINE}.solve": 5, f"{ENGINE}.checks": 6, f"{ENGINE}.io": 6}
    (found,) = engine_violations(tmp_path, ranks)
    assert "imports" in found
