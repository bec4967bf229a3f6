"""The TC-08 stand-in *shared library*: what lets a separate process read simulated temperatures.

:class:`~reach_receiver.sim.tc08.SimulatedTc08Library` serves a driver in the same
process. A dry run across processes (``reach-sim`` in one, ``reach-run`` in another) needs
something the driver can load the way it loads Pico's real ``libusbtc08``: this module
compiles ``native/usbtc08_standin.c`` into a ``libusbtc08.so`` in a directory of the
caller's choosing and keeps the file of nine temperatures beside it up to date. The
driver's own ctypes binding (:func:`~reach_receiver.transports.tc08_library.load_libusbtc08`)
then loads it unchanged, so the same code path as on site is exercised.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import threading
from collections.abc import Callable, Sequence
from pathlib import Path

from reach_receiver.clock import Clock
from reach_receiver.errors import ReceiverError

SOURCE = Path(__file__).with_name("native") / "usbtc08_standin.c"


def build_standin(directory: Path) -> Path:
    """Compile the stand-in library into ``directory``; return its path."""
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        raise ReceiverError("building the TC-08 stand-in needs a C compiler (cc or gcc)")
    directory.mkdir(parents=True, exist_ok=True)
    library = directory / "libusbtc08.so"
    command = [compiler, "-shared", "-fPIC", "-O2", "-o", str(library), str(SOURCE), "-ldl"]
    result = subprocess.run(command, capture_output=True, text=True, check=False)
    if result.returncode != 0:
        raise ReceiverError(f"building the TC-08 stand-in failed: {result.stderr.strip()}")
    return library


class Tc08StandIn:
    """Keeps ``<library>.values`` equal to the simulated thermocouple temperatures.

    Parameters
    ----------
    directory
        Where the library and its values file go.
    temperatures_c
        ``t -> 9 temperatures`` (cold junction, channels 1-8), degrees C.
    clock
        The simulation's clock.
    update_s
        Simulated seconds between rewrites of the values file.
    """

    def __init__(
        self,
        directory: Path,
        temperatures_c: Callable[[float], Sequence[float]],
        clock: Clock,
        update_s: float = 1.0,
    ) -> None:
        self.library = build_standin(Path(directory))
        self.values = self.library.with_name(self.library.name + ".values")
        self._temperatures_c = temperatures_c
        self._clock = clock
        self._update_s = update_s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._open: set[int] = set()
        self._unplugged = False
        # open_circuit (a test's thread) and the updating thread both write the file:
        # one at a time, or one's replace finds the other's temporary file gone.
        self._writing = threading.Lock()
        self.write()

    def write(self) -> None:
        """Rewrite the values file atomically with the temperatures now."""
        with self._writing:
            values = list(self._temperatures_c(self._clock.now()))
            for channel in self._open:
                values[channel] = math.nan
            text = "" if self._unplugged else " ".join(f"{v:.4f}" for v in values) + "\n"
            tmp = self.values.with_name(self.values.name + ".tmp")
            tmp.write_text(text)
            os.replace(tmp, self.values)

    def open_circuit(self, channel: int, is_open: bool = True) -> None:
        """A broken thermocouple: ``channel`` reads NaN (the driver flags it) until closed."""
        if is_open:
            self._open.add(channel)
        else:
            self._open.discard(channel)
        self.write()

    def unplug(self, unplugged: bool = True) -> None:
        """A unit that stops answering: every conversion fails (not responding) until plugged.

        The values file is left empty, which the stand-in library answers with
        ``USBTC08_ERROR_NOT_RESPONDING``, as a unit whose USB link dropped.
        """
        self._unplugged = unplugged
        self.write()

    def start(self) -> None:
        """Keep the file current from a background thread."""
        self._thread = threading.Thread(target=self._run, name="tc08-standin", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.write()
            self._clock.wait(self._stop, self._update_s)

    def close(self) -> None:
        """Stop updating (the files stay for inspection until their directory goes)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None
