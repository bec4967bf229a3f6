"""The receiver side's commands: ``reach-run``, ``reachd`` and ``reach-sim``.

Each is a thin layer over the packages below it: ``reach-run`` over the run layer
(:mod:`reach_receiver.run`), ``reach-sim`` over the simulated receiver
(:mod:`reach_receiver.sim`). Failures an operator can act on print one line without a
traceback and exit non-zero (2 for invalid input, 1 for a run that did not complete).
"""

from .reachd import reachd_main
from .run import run_main
from .sim import sim_main

__all__ = ["reachd_main", "run_main", "sim_main"]
