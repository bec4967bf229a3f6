"""The run layer: one schedule run from compilation to a closed run file.

:class:`~.session.RunSession` owns a run: compile -> instruments -> store -> runner ->
close, with a cooperative stop that always ends in the safe state and a closed run
file. The standard step kinds (:mod:`.steps`) each declare their executor beside their
parser, timing and interlock effect; :mod:`.measure` holds the measurement procedures
they share; :mod:`.instruments` builds the drivers from a site file. ``reach-run`` and
the daemon are two faces of this layer.
"""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

from reach_receiver.config.site import SiteConfig
from reach_receiver.schedule import compile as _compile
from reach_receiver.schedule.steps import Schedule

from .steps import STANDARD_KINDS


def compile_schedule(
    path: Path, *, site: SiteConfig | None = None, start_utc: datetime | None = None
) -> Schedule:
    """Compile a schedule file with the standard step kinds (see the language's own)."""
    return _compile.compile_schedule(path, kinds=STANDARD_KINDS, site=site, start_utc=start_utc)


def compile_text(
    text: str,
    file: str = "<string>",
    *,
    site: SiteConfig | None = None,
    start_utc: datetime | None = None,
) -> Schedule:
    """Compile schedule text with the standard step kinds (see the language's own)."""
    return _compile.compile_text(text, file, kinds=STANDARD_KINDS, site=site, start_utc=start_utc)


__all__ = ["STANDARD_KINDS", "compile_schedule", "compile_text"]
