"""Finding and reading a site file, and its daemon section alone: what a client needs.

``reach-run status`` and the other requests to ``reachd`` need only where the daemon is
(the ``daemon`` section): this module reads that without the rest of the site's checks
(:mod:`.site`, which imports the front-end's tables, the devices' schemas and the
corrections). The file is found (:func:`find_site`), read bounded (a device or a FIFO
named as the site is refused before reading), parsed with lines, and its sections
checked by name (:class:`SectionReader`), for :func:`.site.load_site` too.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Mapping
from pathlib import Path

from reach_receiver.errors import ConfigError

from .daemon import DAEMON_KEYS, DaemonSettings, read_daemon
from .fields import Fields, closest, type_name
from .yaml_lines import LineDict, Problem, ProblemsError, load_yaml, with_lines

#: The site file of the deployed instrument, when neither ``--site`` nor ``$REACH_SITE``.
SYSTEM_SITE = Path("/etc/reach/site.yaml")
SITE_ENVIRONMENT = "REACH_SITE"

SECTIONS = (
    "site",
    "devices",
    "calibration",
    "references",
    "sources",
    "thermocouples",
    "daemon",
    "monitoring",
    "simulation",
)
#: The largest site file read: a site is a page of YAML.
MAX_SITE_BYTES = 1024 * 1024


class SiteError(ProblemsError):
    """A site file with mistakes, each ``file:line: key: message``."""


class SectionReader:
    """Reads one site document, collecting every problem."""

    def __init__(self, document: LineDict, file: str) -> None:
        self.document = document
        self.file = file
        self.problems: list[Problem] = []
        for key in document:
            if key not in SECTIONS:
                known = ", ".join(SECTIONS)
                message = f"unknown section '{key}'{closest(key, SECTIONS)} (known: {known})"
                self.report(document.line_of(key), str(key), message)

    def section(self, name: str, allowed: tuple[str, ...]) -> Fields:
        """A reader of one top-level section (empty when absent or not a mapping)."""
        value = self.document.get(name)
        line = self.document.line_of(name)
        if value is not None and not isinstance(value, LineDict):
            self.report(line, name, f"must be a mapping, not {type_name(value)}")
        if not isinstance(value, LineDict):
            value = LineDict(line=line)
        return Fields(value, file=self.file, key=name, allowed=allowed, problems=self.problems)

    def report(self, line: int, key: str, message: str) -> None:
        """One problem, ``file:line: key: message``."""
        self.problems.append(Problem(self.file, line, key, message))


def read_document(path: Path) -> object:
    """The YAML document of a site file, read bounded; :class:`SiteError` if it cannot be."""
    try:
        text = read_bounded(path)
    except (OSError, UnicodeDecodeError) as err:
        message = f"cannot read the site file: {getattr(err, 'strerror', None) or err}"
        raise SiteError([Problem(str(path), 1, "<file>", message)]) from err
    document, problems = load_yaml(text, str(path))
    if problems:
        raise SiteError(problems)
    return document


def load_daemon_settings(path: str | Path) -> DaemonSettings:
    """Only the ``daemon`` section of a site file: where a client finds ``reachd``.

    A client of the daemon (``reach-run status``) needs its directories, not the checks
    of the Touchstone references, which load numpy. Raises :class:`SiteError` as
    :func:`load_site` does for what it reads.
    """
    path = Path(path)
    document = with_lines(read_document(path))
    if not isinstance(document, LineDict):
        raise SiteError([Problem(str(path), 1, "<document>", "not a mapping")])
    reader = SectionReader(document, str(path))
    daemon = read_daemon(reader.section("daemon", DAEMON_KEYS), str(path), reader.problems)
    if reader.problems:
        raise SiteError(sorted(dict.fromkeys(reader.problems), key=lambda p: p.line))
    return daemon


def read_bounded(path: Path) -> str:
    """The text of a regular file of at most :data:`MAX_SITE_BYTES` (else ``OSError``).

    A device (``/dev/zero``), a FIFO or a huge file named as the site would fill memory
    or block forever: they are refused before reading.
    """
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise OSError(f"{path} is not a regular file")
    with os.fdopen(fd, "rb") as handle:
        data = handle.read(MAX_SITE_BYTES + 1)
    if len(data) > MAX_SITE_BYTES:
        raise OSError(f"larger than {MAX_SITE_BYTES} bytes: not a site file")
    return data.decode("utf-8")


def find_site(given: Path | None, environ: Mapping[str, str] = os.environ) -> Path:
    """The site file to use: ``given``, else ``$REACH_SITE``, else ``/etc/reach/site.yaml``.

    Raises
    ------
    ConfigError
        When the chosen file does not exist, naming where it was looked for.
    """
    if given is not None:
        return Path(given)
    if environ.get(SITE_ENVIRONMENT):
        return Path(environ[SITE_ENVIRONMENT])
    if SYSTEM_SITE.is_file():
        return SYSTEM_SITE
    raise ConfigError(
        f"no site file: give --site <file>, set ${SITE_ENVIRONMENT}, or install {SYSTEM_SITE}"
    )
