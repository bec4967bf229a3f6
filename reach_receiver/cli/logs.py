"""Logging and ``--version`` for the command-line tools.

Warnings go to standard error (everything from INFO with ``-v``); the receiver's and the
engine's loggers pass INFO on, so that a run's own log file (``run.log``) holds the
whole story whatever the terminal shows.
"""

from __future__ import annotations

import argparse
import logging
from importlib import metadata

STDERR_FORMAT = "%(asctime)s %(name)s: %(message)s"
_HANDLER_NAME = "reach-stderr"


def version() -> str:
    """The installed version of the project."""
    try:
        return metadata.version("reach-receiver")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


def add_version(parser: argparse.ArgumentParser) -> None:
    """``--version``: the program's name and the project's version."""
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")


def configure_logging(verbose: bool) -> None:
    """Standard error at WARNING (INFO when verbose); the packages' loggers at INFO.

    Idempotent: a second call replaces the first's handler (bound to the standard error
    of the moment, which tests and re-entrant callers swap).
    """
    root = logging.getLogger()
    for old in [h for h in root.handlers if h.get_name() == _HANDLER_NAME]:
        root.removeHandler(old)
    handler = logging.StreamHandler()
    handler.set_name(_HANDLER_NAME)
    handler.setLevel(logging.INFO if verbose else logging.WARNING)
    handler.setFormatter(logging.Formatter(STDERR_FORMAT))
    root.addHandler(handler)
    for name in ("reach_receiver", "calibration"):
        logging.getLogger(name).setLevel(logging.INFO)
