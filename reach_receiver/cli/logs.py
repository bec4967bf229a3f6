"""Logging and ``--version`` for the command-line tools.

On a terminal (or a pipe, a file) warnings go to standard error with their time, and
everything from INFO with ``-v``; on a terminal a line wider than 80 columns is
wrapped. Under systemd, where standard error is the journal's stream, each line starts
with its syslog priority instead (``<3>`` error, ``<4>`` warning, ``<6>`` info, ``<7>``
debug: sd-daemon(3)) and carries no time of its own (the journal stamps it), so that
``journalctl -u reachd -p warning`` shows the warnings and errors alone; INFO is the
default there (the service's state changes, its jobs, who asked for what), DEBUG with
``-v``. Lines printed outside the log there get a priority too: ``<6>`` on standard
output, ``<3>`` on standard error (what a command writes there outside its log is what
went wrong).

The receiver's and the engine's loggers pass INFO on whatever the stream shows, so that
a run's own log file (``run.log``) holds the whole story.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import textwrap
from typing import Any, TextIO

STDERR_FORMAT = "%(asctime)s %(name)s: %(message)s"
JOURNAL_FORMAT = "%(name)s: %(message)s"
_HANDLER_NAME = "reach-stderr"


class _StandardError(logging.StreamHandler):
    """A handler that writes to the standard error of the moment, not of its creation.

    A handler bound to the stream it was made with writes into a closed file once a caller
    swaps ``sys.stderr`` back (a test's capture, a re-entrant caller), and every later
    record ends in Python's "--- Logging error ---" traceback.
    """

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    @stream.setter
    def stream(self, value: TextIO) -> None:
        pass
#: The width of an operator's terminal (wrapped log lines on a terminal).
WIDTH = 80

#: Syslog priorities of the logging levels (sd-daemon(3)).
PRIORITIES = {
    logging.CRITICAL: 2,
    logging.ERROR: 3,
    logging.WARNING: 4,
    logging.INFO: 6,
    logging.DEBUG: 7,
}


def version() -> str:
    """The installed version of the project (importlib.metadata: read only when asked)."""
    from importlib import metadata

    try:
        return metadata.version("reach-receiver")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


def add_version(parser: argparse.ArgumentParser) -> None:
    """``--version``: the program's name and the project's version."""
    parser.add_argument("--version", action=_Version, nargs=0,
                        help="show program's version number and exit")


class _Version(argparse.Action):
    """``--version`` on standard output, the version read only when it is asked for.

    Every command's start would otherwise pay for importlib.metadata's email parser.
    """

    def __call__(self, parser: argparse.ArgumentParser, *_: Any) -> None:
        print(f"{parser.prog} {version()}")
        parser.exit()


def is_journal(stream: TextIO) -> bool:
    """Whether ``stream`` is the journal's stream that systemd gave this process.

    systemd sets ``JOURNAL_STREAM`` to ``device:inode`` of that stream (systemd.exec(5));
    the variable alone is not enough (a child whose output a service redirected inherits
    it), so the stream itself is compared.
    """
    value = os.environ.get("JOURNAL_STREAM", "")
    try:
        device, inode = (int(part) for part in value.split(":"))
        info = os.fstat(stream.fileno())
    except (ValueError, OSError, AttributeError):  # unset, malformed, no descriptor
        return False
    return (info.st_dev, info.st_ino) == (device, inode)


def priority(level: int) -> int:
    """The syslog priority of a logging level (a level between two takes the lower's)."""
    for threshold in sorted(PRIORITIES, reverse=True):
        if level >= threshold:
            return PRIORITIES[threshold]
    return PRIORITIES[logging.DEBUG]


class JournalFormatter(logging.Formatter):
    """``<N>name: message``, every line of it (a traceback's too) with the priority.

    The journal reads a priority at the start of each line it is given, so a record of
    several lines carries it on each.
    """

    def __init__(self) -> None:
        super().__init__(JOURNAL_FORMAT)

    def format(self, record: logging.LogRecord) -> str:
        """The record, each of its lines prefixed with its priority."""
        prefix = f"<{priority(record.levelno)}>"
        return "\n".join(prefix + line for line in super().format(record).splitlines())


class TerminalFormatter(logging.Formatter):
    """Each record with its time and logger; on a terminal, within :data:`WIDTH` columns.

    An operator over a slow link reads in an 80-column terminal, where a longer line
    would break anywhere: it is wrapped between words instead, the rest indented. In a
    pipe or a file a record stays one line, for ``grep``.
    """

    def __init__(self, wrap: bool) -> None:
        super().__init__(STDERR_FORMAT)
        self.wrap = wrap

    def format(self, record: logging.LogRecord) -> str:
        """The record, wrapped on a terminal."""
        text = super().format(record)
        if not self.wrap:
            return text
        return "\n".join(
            wrapped
            for line in text.splitlines()
            for wrapped in textwrap.wrap(
                line, WIDTH, subsequent_indent="    ", break_long_words=False,
                break_on_hyphens=False,
            ) or [line]
        )


def _isatty(stream: TextIO) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):  # no such method, or closed
        return False


class PrefixedLines:
    """A text stream whose every line starts with a syslog priority.

    Lines that already carry one (a log record's) pass unchanged; any other gets
    ``priority``. The rest of the stream's interface is the wrapped stream's.
    """

    def __init__(self, stream: TextIO, default: int) -> None:
        self.stream = stream
        self.default = default
        self._at_start = True

    def write(self, text: str) -> int:
        """Write ``text``, a priority before each line that has none."""
        out = []
        for piece in text.splitlines(keepends=True):
            if self._at_start and not _has_priority(piece):
                out.append(f"<{self.default}>")
            out.append(piece)
            self._at_start = piece.endswith("\n")
        return self.stream.write("".join(out))

    def __getattr__(self, name: str) -> Any:
        return getattr(self.stream, name)


def _has_priority(line: str) -> bool:
    return len(line) >= 3 and line[0] == "<" and line[1].isdigit() and line[2] == ">"


def configure_logging(verbose: bool) -> None:
    """Standard error at WARNING (INFO when verbose); the journal at INFO (DEBUG).

    The packages' loggers pass INFO on (DEBUG when verbose under the journal).
    Idempotent: a second call replaces the first's handler (bound to the standard error
    of the moment, which tests and re-entrant callers swap).
    """
    root = logging.getLogger()
    for old in [h for h in root.handlers if h.get_name() == _HANDLER_NAME]:
        root.removeHandler(old)
    journal = is_journal(sys.stderr)
    if journal:
        _prefix_printed_lines()
    handler = _StandardError()
    handler.set_name(_HANDLER_NAME)
    if journal:
        handler.setLevel(logging.DEBUG if verbose else logging.INFO)
        handler.setFormatter(JournalFormatter())
    else:
        handler.setLevel(logging.INFO if verbose else logging.WARNING)
        handler.setFormatter(TerminalFormatter(_isatty(sys.stderr)))
    root.addHandler(handler)
    for name in ("reach_receiver", "calibration"):
        logging.getLogger(name).setLevel(logging.DEBUG if journal and verbose else logging.INFO)
    logging.captureWarnings(journal)  # a Python warning as a log record, with its priority


def _prefix_printed_lines() -> None:
    """Under the journal, ``print`` gets a priority too: ``<6>`` out, ``<3>`` on stderr."""
    if not isinstance(sys.stderr, PrefixedLines):
        sys.stderr = PrefixedLines(sys.stderr, PRIORITIES[logging.ERROR])
    if is_journal(sys.stdout) and not isinstance(sys.stdout, PrefixedLines):
        sys.stdout = PrefixedLines(sys.stdout, PRIORITIES[logging.INFO])
