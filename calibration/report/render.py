"""The report's summary as Markdown and as HTML, from one list of table sections.

A :class:`Section` is a titled table; both renderers write the same cells, so the two
files cannot disagree. Cell text is escaped for its format (``|`` in Markdown; ``<``,
``>``, ``&`` in HTML).
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = ["Section", "render_html", "render_markdown"]

_CSS = """
body { font-family: system-ui, sans-serif; max-width: 1200px; margin: 1.5em auto;
       padding: 0 1em; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left;
         vertical-align: top; }
th { background: #f2f2f2; }
img { max-width: 100%; margin: 0.5em 0 1.5em; border: 1px solid #eee; }
"""


@dataclass(frozen=True)
class Section:
    """A titled table: column names and rows of cell text."""

    title: str
    columns: tuple[str, ...]
    rows: Sequence[tuple[str, ...]]


def _md_cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def render_markdown(title: str, sections: Sequence[Section], images: Sequence[str]) -> str:
    """The summary as Markdown: one table per section, then the figures."""
    lines = [f"# {title}", ""]
    for section in sections:
        lines += [f"## {section.title}", ""]
        lines.append("| " + " | ".join(map(_md_cell, section.columns)) + " |")
        lines.append("|" + "---|" * len(section.columns))
        for row in section.rows or [("(none)",) + ("",) * (len(section.columns) - 1)]:
            lines.append("| " + " | ".join(map(_md_cell, row)) + " |")
        lines.append("")
    if images:
        lines += ["## Figures", ""]
        lines += [f"![{name}]({name})\n" for name in images]
    return "\n".join(lines)


def render_html(title: str, sections: Sequence[Section], images: Sequence[str]) -> str:
    """The summary as one self-contained HTML page linking the figures beside it."""
    esc = html.escape
    parts = [
        "<!DOCTYPE html>",
        f'<html lang="en"><head><meta charset="utf-8"><title>{esc(title)}</title>',
        f"<style>{_CSS}</style></head><body>",
        f"<h1>{esc(title)}</h1>",
    ]
    for section in sections:
        parts.append(f"<h2>{esc(section.title)}</h2><table>")
        parts.append("<tr>" + "".join(f"<th>{esc(c)}</th>" for c in section.columns) + "</tr>")
        for row in section.rows:
            parts.append("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in row) + "</tr>")
        parts.append("</table>")
    if images:
        parts.append("<h2>Figures</h2>")
        parts += [f'<img src="{esc(name)}" alt="{esc(name)}">' for name in images]
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"
