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

from collections.abc import Sequence


def reachd_main(argv: Sequence[str] | None = None) -> int:
    """``reachd`` (:mod:`.reachd`)."""
    from .reachd import reachd_main as main

    return main(argv)


def run_main(argv: Sequence[str] | None = None) -> int:
    """``reach-run`` (:mod:`.run`)."""
    from .run import run_main as main

    return main(argv)


def sim_main(argv: Sequence[str] | None = None) -> int:
    """``reach-sim`` (:mod:`.sim`)."""
    from .sim import sim_main as main

    return main(argv)


__all__ = ["reachd_main", "run_main", "sim_main"]
