"""The documentation's code runs and its tables agree with README's.

The astronomer's guide is a notebook-style walk-through: its ```python blocks, run in
order in one namespace in a fresh directory, must run as written and end with a
calibration whose actual error its error bars and the noise floor account for. The
architecture page repeats README's two layer tables (which tests/test_layers.py checks
against the imports): they must be the same tables.
"""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
#: A ```python block and the ```text block that may follow it: what it prints.
BLOCK = re.compile(
    r"^```python\n(?P<code>.*?)^```\n(?:\s*^```text\n(?P<output>.*?)^```)?",
    re.DOTALL | re.MULTILINE,
)
NUMBER = re.compile(r"-?\d+(?:\.(\d+))?")


def python_blocks(page: Path) -> list[tuple[str, str | None]]:
    """The page's ```python blocks in order, each with the output shown after it (or None)."""
    return [(m["code"], m["output"]) for m in BLOCK.finditer(page.read_text())]


def same_output(shown: str, printed: str) -> str | None:
    """Why ``printed`` is not the ``shown`` output, or None.

    The words and integers must match exactly; each decimal number to 2 % or 5 units of
    its last printed digit, whichever is wider: the run is seeded, and a BLAS or platform
    moves only the last digits (a changed solver moves more, and the page must say so).
    """
    want, got = shown.strip().splitlines(), printed.strip().splitlines()
    if len(want) != len(got):
        return f"{len(got)} lines printed, {len(want)} shown"
    for w, g in zip(want, got, strict=True):
        if NUMBER.sub("#", w).split() != NUMBER.sub("#", g).split():
            return f"printed {g!r}, shown {w!r}"
        for mw, mg in zip(NUMBER.finditer(w), NUMBER.finditer(g), strict=True):
            a, b = float(mw[0]), float(mg[0])
            if mw[1] is None:  # an integer: a count, an order
                if mw[0] != mg[0]:
                    return f"printed {g!r}, shown {w!r}: {mg[0]} is not {mw[0]}"
                continue
            if abs(a - b) > max(5 * 10.0 ** -len(mw[1]), 0.02 * abs(a)):
                return f"printed {g!r}, shown {w!r}: {mg[0]} is not {mw[0]}"
    return None


def table_under(text: str, heading: str) -> list[str]:
    """The markdown table's rows directly under ``heading`` (its first table)."""
    lines = text.splitlines()
    start = lines.index(heading)
    rows: list[str] = []
    for line in lines[start + 1 :]:
        if line.startswith("#"):
            break
        if line.startswith("|"):
            rows.append(line.strip())
        elif rows:
            break
    return rows


def test_astronomers_guide_runs(tmp_path, monkeypatch):
    blocks = python_blocks(DOCS / "astronomers-guide.md")
    assert len(blocks) >= 6, "the walk-through lost its code blocks"
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, Any] = {"__name__": "__docs__"}
    printed = ""
    for number, (block, shown) in enumerate(blocks, 1):
        code = compile(block, f"astronomers-guide.md, python block {number}", "exec")
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            exec(code, namespace)
        printed += out.getvalue()
        if shown is not None:
            wrong = same_output(shown, out.getvalue())
            assert wrong is None, f"python block {number}'s output: {wrong}"
        else:
            assert not out.getvalue(), f"python block {number} prints, and the page shows none"
    # The walk-through's own claims, on its own numbers: a file was written and read,
    # the antenna calibrated near its simulated temperature, the error bars hold the
    # actual error and sit near the floor. The tolerances are a single run's scatter
    # (one seed, ~400 channels): actual/floor is 0.95 in the median over 50 runs
    # (benchmarks.accuracy); the statistics over many truths are tests/test_coverage.py's.
    assert (tmp_path / "run.h5").is_file()
    assert (tmp_path / "solution.h5").is_file()
    assert "12 calibrators" in printed
    spectrum: Any = namespace["spectrum"]
    true_t = np.asarray(namespace["true_t"])
    floor, predicted, actual = (float(namespace[k]) for k in ("floor", "predicted", "actual"))
    assert np.all(np.isfinite(spectrum.mean))
    assert np.all(spectrum.std > 0)
    # The error of the calibration alone (true_t shares the antenna's measured Q), in
    # units of its predicted sd: correlated over the band, so one run's RMS scatters by
    # tens of per cent; a factor of two either way is an error model that is wrong.
    z = (spectrum.mean - true_t) / spectrum.std_calibration
    assert 0.5 < float(np.sqrt(np.mean(z**2))) < 2.0
    assert 0.8 < predicted / floor < 1.5, "the error bars are not at the noise floor"
    assert 0.5 < actual / floor < 2.0
    assert "noise floor" in printed
    assert "x the floor" in printed


@pytest.mark.parametrize(
    "heading", ["### Layers", "### Engine layers"], ids=["receiver", "engine"]
)
def test_architecture_tables_are_readmes(heading):
    readme = table_under((ROOT / "README.md").read_text(), heading)
    page = table_under((DOCS / "architecture.md").read_text(), heading[1:])
    assert readme, f"README has no table under {heading!r}"
    assert page == readme, f"docs/architecture.md's {heading[1:]!r} table differs from README's"


def test_every_page_is_in_the_nav():
    nav = (ROOT / "mkdocs.yml").read_text()
    pages = sorted(p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md"))
    missing = [p for p in pages if p not in nav]
    assert not missing, f"pages not in mkdocs.yml's nav: {missing}"


def test_api_page_lists_the_public_names():
    import calibration

    page = (DOCS / "api" / "calibration.md").read_text()
    missing = [name for name in calibration.__all__ if f"`{name}`" not in page]
    assert not missing, f"docs/api/calibration.md does not list {missing}"


def test_readme_links_to_pages_that_exist():
    # README is read on the forge, outside the site: mkdocs --strict does not see its links.
    readme = (ROOT / "README.md").read_text()
    links = re.findall(r"\]\((docs/[^)#]+)", readme)
    assert len(links) >= 7, "README lost its table of contents"
    missing = [link for link in links if not (ROOT / link).is_file()]
    assert not missing, f"README links to missing files: {missing}"


@pytest.mark.parametrize(
    ("shown", "printed", "same"),
    [
        ("s^2: 1.003", "s^2: 1.004", True),
        ("s^2: 1.003", "s^2: 1.103", False),
        ("orders (4, 3, 4)", "orders (4, 3, 5)", False),
        ("warnings: none", "warnings: ['the fit did not converge']", False),
        ("1141.04 +- 0.092", "1140.11 +- 0.093", True),
        ("a\nb", "a", False),
    ],
)
def test_output_comparison(shown, printed, same):
    assert (same_output(shown, printed) is None) == same
