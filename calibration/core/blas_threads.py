"""BLAS on one thread inside the solver, whose linear algebra is many small calls.

The radiometric solver's model search makes thousands of BLAS and LAPACK calls on vectors
and matrices of tens of elements: L-BFGS-B's updates in the fit of the prior widths
(:mod:`calibration.choice.scale_fit`), the batched eigendecompositions of the evidence grid
(:mod:`calibration.regression.shrinkage`), the conjugate solves of every model. OpenBLAS, as the
numpy and scipy wheels ship it (one copy each), runs each call on every core, and
waking and joining its threads costs more than the work. Measured on an idle 2-core
machine (no other load, no steal time) for the default solve of 12 calibrators x 6554
channels: 0.258 s (median of 10) with OpenBLAS's two threads, 0.129 s on one; profiled,
L-BFGS-B's Fortran took 75 ms a solve and ten eigendecompositions 60 ms with two threads,
both negligible on one. ``python -m benchmarks.speed`` times the solve with the threads
as installed and pinned, side by side.

:func:`one_blas_thread` limits every loaded BLAS to one thread for the duration of a
``with`` block, through threadpoolctl (the library scikit-learn uses for the same
purpose), and restores the previous counts after it. The limit is per process: BLAS calls
of other threads during a solve also run on one thread, and two solves overlapping in
time may leave the second's tail on the restored count: slower, not wrong.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from functools import cache, wraps
from typing import Any, ParamSpec, TypeVar

from threadpoolctl import ThreadpoolController  # type: ignore[import-untyped]

P = ParamSpec("P")
R = TypeVar("R")


@cache
def _controller() -> ThreadpoolController:
    """The loaded BLAS libraries, found once (a scan of the process's libraries, a few ms).

    Created at the first solve, when numpy's and scipy's OpenBLAS are both loaded (the
    engine imports scipy at import time).
    """
    return ThreadpoolController()


def one_blas_thread() -> AbstractContextManager[Any]:
    """A context in which every BLAS the process has loaded runs on one thread."""
    return _controller().limit(limits=1, user_api="blas")


def with_one_blas_thread(function: Callable[P, R]) -> Callable[P, R]:
    """``function`` run inside :func:`one_blas_thread` (about 20 us a call)."""

    @wraps(function)
    def limited(*args: P.args, **kwargs: P.kwargs) -> R:
        with one_blas_thread():
            return function(*args, **kwargs)

    return limited
