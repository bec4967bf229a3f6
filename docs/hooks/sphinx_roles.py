"""MkDocs hook: the docstrings' Sphinx roles as cross-references.

The engine's and the receiver's docstrings name other objects the Sphinx way
(``:func:`~calibration.solve.delay_terms.extend```), which mkdocstrings' numpy parser
leaves as text: ``:func:`` before a code span. This hook turns each into an optional
autorefs link: a link where the name is documented on the site, the plain code span
where it is not (a relative ``.session``, a private helper), so a role never breaks a
strict build and never shows its markup.
"""

from __future__ import annotations

import re
from typing import Any

#: ``:role:`` then the code span mkdocstrings made of the role's target; the target may
#: be ``~name`` (show the last part) or ``title <name>``.
ROLE = re.compile(
    r":(?:mod|func|class|meth|attr|data|exc|obj|const|py:\w+):"
    r"<code>(?P<tilde>~?)(?:(?P<title>[^<]*?)\s*&lt;(?P<target>[\w.]+)&gt;|(?P<name>[\w.]+))</code>"
)


def _link(match: re.Match[str]) -> str:
    target = match["target"] or match["name"]
    shown = match["title"] or target
    if match["tilde"]:
        shown = shown.rsplit(".", 1)[-1]
    if target.startswith("."):  # relative to the module: no site-wide identifier
        return f"<code>{shown.lstrip('.')}</code>"
    return f'<autoref identifier="{target}" optional><code>{shown}</code></autoref>'


def on_page_content(html: str, **_: Any) -> str:
    """Every Sphinx role in a rendered page as an optional cross-reference."""
    return ROLE.sub(_link, html)
