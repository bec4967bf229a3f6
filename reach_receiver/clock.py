"""Clocks: where the daemon and the simulators read the time and wait.

Everything that waits or stamps a measurement takes a :class:`Clock`, so the same code
runs against the wall clock on site and against a compressed clock in dry runs and
tests: a 2-minute integration then takes milliseconds of real time but carries the
radiometer noise of 2 minutes (the simulators read the simulated duration, not the
real one).
"""

from __future__ import annotations

import threading
import time
from typing import Protocol

#: The longest a :class:`StopEvent`'s ``wait`` sleeps before it looks at the flag again.
WAIT_SLICE_S = 0.25


class StopEvent(threading.Event):
    """A :class:`threading.Event` that a signal handler may set: its lock is reentrant.

    Python runs a signal handler in the main thread between two bytecodes, possibly while
    that thread holds the lock of the very event the handler sets (entering or leaving
    ``wait``). ``threading.Event``'s lock is not reentrant, so its ``set`` then waits for
    ever on the thread it interrupted (a daemon stopped by SIGTERM hung so in a test).
    Here the handler re-enters the lock it already holds, sets the flag and returns. A
    handler that strikes inside ``wait`` after the flag was checked but before the waiter
    registered notifies no one; ``wait`` therefore sleeps in slices of
    :data:`WAIT_SLICE_S` and re-checks the flag, so that it sees it within one slice.
    """

    def __init__(self) -> None:
        super().__init__()
        self._signal_safe = threading.Condition(threading.RLock())
        self._set = False

    def is_set(self) -> bool:
        """Whether the event is set."""
        return self._set

    def set(self) -> None:
        """Set the event and wake every waiter."""
        with self._signal_safe:
            self._set = True
            self._signal_safe.notify_all()

    def clear(self) -> None:
        """Clear the event."""
        with self._signal_safe:
            self._set = False

    def wait(self, timeout: float | None = None) -> bool:
        """Wait up to ``timeout`` seconds (``None``: for ever); whether it is set."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._signal_safe:
            while not self._set:
                left = WAIT_SLICE_S if deadline is None else deadline - time.monotonic()
                if left <= 0:
                    break
                self._signal_safe.wait(min(left, WAIT_SLICE_S))
            return self._set


class Clock(Protocol):
    """What a clock offers: the current time and a way to wait."""

    def now(self) -> float:
        """Seconds since the Unix epoch, in this clock's time."""
        ...

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of this clock's time."""
        ...

    def wait(self, event: threading.Event, seconds: float) -> bool:
        """Wait up to ``seconds`` of this clock's time for ``event``; whether it is set."""
        ...


class SystemClock:
    """The wall clock."""

    def now(self) -> float:
        """Seconds since the Unix epoch."""
        return time.time()

    def sleep(self, seconds: float) -> None:
        """Wait for real."""
        if seconds > 0:
            time.sleep(seconds)

    def wait(self, event: threading.Event, seconds: float) -> bool:
        """Wait for real, until ``event`` is set or ``seconds`` have passed."""
        return event.wait(max(seconds, 0.0))


class CompressedClock:
    """Simulated time running ``factor`` times faster than real time.

    ``now() = t0 + factor * (monotonic() - m0)``; ``sleep(s)`` waits ``s / factor``
    real seconds. All threads that share one instance see the same simulated time, so a
    simulator streaming spectra and a driver integrating them agree on it.

    Parameters
    ----------
    factor
        Simulated seconds per real second (1 is real time).
    start
        Simulated epoch of the moment the clock is made; the wall clock's by default.
    monotonic_origin
        The ``time.monotonic()`` reading at which simulated time was ``start``; now by
        default. The monotonic clock is system-wide on Linux, so another process given
        the same ``(factor, start, monotonic_origin)`` keeps exactly the same simulated
        time: that is how ``reach-run`` follows a ``reach-sim`` running in its own process.
    """

    def __init__(
        self,
        factor: float = 1.0,
        start: float | None = None,
        monotonic_origin: float | None = None,
    ) -> None:
        if not factor > 0:
            raise ValueError(f"time compression factor must be positive, got {factor}")
        self.factor = float(factor)
        self._t0 = time.time() if start is None else float(start)
        self._m0 = time.monotonic() if monotonic_origin is None else float(monotonic_origin)

    @property
    def parameters(self) -> dict[str, float]:
        """What another process needs to share this clock (see ``monotonic_origin``)."""
        return {"compression": self.factor, "start": self._t0, "monotonic_origin": self._m0}

    def now(self) -> float:
        """Simulated seconds since the Unix epoch."""
        return self._t0 + self.factor * (time.monotonic() - self._m0)

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of simulated time."""
        if seconds > 0:
            time.sleep(seconds / self.factor)

    def wait(self, event: threading.Event, seconds: float) -> bool:
        """Wait up to ``seconds`` of simulated time for ``event``."""
        return event.wait(max(seconds, 0.0) / self.factor)

    def real_seconds(self, simulated_s: float) -> float:
        """Real seconds that ``simulated_s`` of this clock's time take."""
        return simulated_s / self.factor


class ManualClock:
    """A clock that moves only when told to: for state-machine tests.

    ``sleep`` advances the time at once (nothing really waits), so code under test that
    sleeps runs instantly and deterministically.
    """

    def __init__(self, start: float = 1.7e9) -> None:
        self._t = float(start)
        self._lock = threading.Lock()

    def now(self) -> float:
        """The current manual time."""
        with self._lock:
            return self._t

    def sleep(self, seconds: float) -> None:
        """Advance the time by ``seconds`` immediately."""
        self.advance(max(seconds, 0.0))

    def wait(self, event: threading.Event, seconds: float) -> bool:
        """Advance by ``seconds`` unless ``event`` is already set; whether it is set."""
        if not event.is_set():
            self.advance(max(seconds, 0.0))
        return event.is_set()

    def advance(self, seconds: float) -> None:
        """Move the clock forward."""
        if seconds < 0:
            raise ValueError("a clock does not run backwards")
        with self._lock:
            self._t += seconds
