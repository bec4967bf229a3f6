"""The solver's BLAS runs on one thread, and the caller's thread counts come back after."""

from __future__ import annotations

import numpy as np
from threadpoolctl import ThreadpoolController

from calibration.core.blas_threads import one_blas_thread, with_one_blas_thread
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run
from calibration.solve.radiometric_solver import solve_radiometric


def blas_threads(controller: ThreadpoolController) -> list[int]:
    return [int(info["num_threads"]) for info in controller.select(user_api="blas").info()]


def test_one_thread_inside_and_the_callers_count_after():
    """With the caller at two threads (set here, so that the test means the same on any
    machine): one inside, two again after, also when the block raises."""
    controller = ThreadpoolController()
    assert blas_threads(controller), "numpy and scipy load OpenBLAS: something to limit"
    with controller.limit(limits=2, user_api="blas"):
        assert set(blas_threads(controller)) == {2}
        with one_blas_thread():
            assert set(blas_threads(controller)) == {1}
        assert set(blas_threads(controller)) == {2}
        try:
            with one_blas_thread():
                raise RuntimeError("a solve that fails")
        except RuntimeError:
            pass
        assert set(blas_threads(controller)) == {2}


def test_a_wrapped_function_runs_on_one_thread_and_keeps_its_result():
    controller = ThreadpoolController()
    seen: list[list[int]] = []

    @with_one_blas_thread
    def product(a: np.ndarray) -> np.ndarray:
        seen.append(blas_threads(controller))
        return a @ a.T

    a = np.random.default_rng(0).standard_normal((300, 300))
    with controller.limit(limits=2, user_api="blas"):
        np.testing.assert_allclose(product(a), a @ a.T, rtol=1e-12, atol=1e-9)
    assert len(seen) == 1
    assert set(seen[0]) == {1}
    assert product.__name__ == "product"


def test_the_radiometric_solver_is_limited():
    """The default solve is wrapped by :func:`with_one_blas_thread` (its wrapper's code,
    not merely some decorator; its speed is measured in benchmarks/speed.py) and solves
    as before: the same orders under either thread count."""
    run = simulate_run(SimulationConfig(channel_width_hz=ITPM_CHANNEL_WIDTH_HZ * 16), rng=3)
    limiter = with_one_blas_thread(lambda: None)
    assert solve_radiometric.__code__ is limiter.__code__
    limited = solve_radiometric(run.data)
    controller = ThreadpoolController()
    with controller.limit(limits=2, user_api="blas"):
        unlimited = solve_radiometric.__wrapped__(run.data)  # type: ignore[attr-defined]
    assert limited.metadata["best_orders"] == unlimited.metadata["best_orders"]
    np.testing.assert_allclose(limited.posterior.mean, unlimited.posterior.mean, rtol=1e-6)
