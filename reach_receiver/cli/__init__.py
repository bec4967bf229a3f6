"""The receiver side's commands: ``reach-run``, ``reachd`` and ``reach-sim``.

Each is a thin layer over the packages below it: ``reach-run`` over the run layer
(:mod:`reach_receiver.run`), ``reach-sim`` over the simulated receiver
(:mod:`reach_receiver.sim`). Failures an operator can act on print one line without a
traceback and exit non-zero (2 for invalid input, 1 for a run that did not complete).

The entry points import their command's module when called, not with the package: one
command does not pay for the others' imports (``reachd`` commands the front-end safe
before it imports the run layer).
"""

from __future__ import annotations

import importlib
import os
import signal
import sys
from collections.abc import Sequence

#: Exit status of a command stopped by SIGINT before it could say more (128 + 2).
INTERRUPTED = 128 + signal.SIGINT


def _main(program: str, module: str, function: str, argv: Sequence[str] | None) -> int:
    """Import a command's module and run it; a Ctrl-C while it loads is one line.

    Not a traceback: the command had done nothing yet. (A run's own Ctrl-C is the run
    layer's: the front-end safe, the run file closed.)
    """
    try:
        main = getattr(importlib.import_module(module, __name__), function)
        return int(main(argv))
    except KeyboardInterrupt:
        print(f"{program}: interrupted", file=sys.stderr)
        return INTERRUPTED
    except BrokenPipeError:
        # The reader went away (``reach-run metrics X | head``): stop quietly, and keep
        # Python from reporting the pipe again when it flushes at exit.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1


#: Stop signals that reached ``reachd`` before it had its daemon's handlers: kept, not
#: raised. A SIGINT raised as KeyboardInterrupt while it imports can land in a finalizer
#: or a library's own ``except BaseException``, where Python drops it, and the daemon then
#: started and served as if never told to stop (a fault-suite trial, under load).
#: :mod:`.reachd` reads them at each step of its start and stops at the first it sees.
EARLY_STOPS: list[int] = []
_STOPS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _keep_stop(signum: int, frame: object) -> None:
    del frame
    EARLY_STOPS.append(signum)


def reachd_main(argv: Sequence[str] | None = None) -> int:
    """``reachd`` (:mod:`.reachd`), its stop signals kept from the first moment."""
    previous = {s: signal.signal(s, _keep_stop) for s in _STOPS}
    try:
        return _main("reachd", ".reachd", "reachd_main", argv)
    finally:  # in-process callers (tests) get their own handlers back
        for s, handler in previous.items():
            signal.signal(s, handler)


def run_main(argv: Sequence[str] | None = None) -> int:
    """``reach-run`` (:mod:`.commands`, which dispatches to :mod:`.run` and the others)."""
    return _main("reach-run", ".commands", "main", argv)


def sim_main(argv: Sequence[str] | None = None) -> int:
    """``reach-sim`` (:mod:`.sim`)."""
    return _main("reach-sim", ".sim", "sim_main", argv)


__all__ = ["reachd_main", "run_main", "sim_main"]
