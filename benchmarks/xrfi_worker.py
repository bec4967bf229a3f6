"""EDGES' xrfi on spectra from a file: run by :mod:`benchmarks.rfi` in another interpreter.

``python benchmarks/xrfi_worker.py IN.npz OUT.npz``: ``IN`` holds ``spectra`` and
``freqs_mhz`` ``(n, channels)``; ``OUT`` gets one boolean array per setting of
:data:`SETTINGS`. It imports only numpy and edges-analysis (``edges.filters.xrfi``), so it
runs in any interpreter that has edges-analysis 8.3.0, without this project installed.
"""

from __future__ import annotations

import sys
import warnings
from typing import Any

import numpy as np

#: name: (function, keyword arguments); the models are built in :func:`run`.
SETTINGS = ("iterative_default", "iterative_linlog", "sliding_window_b18")


def run(spectra: np.ndarray, freqs_mhz: np.ndarray) -> dict[str, np.ndarray]:
    """Flags of every spectrum under each of :data:`SETTINGS`."""
    from edges import modeling as mdl
    from edges.filters import xrfi

    out = {name: np.zeros(spectra.shape, bool) for name in SETTINGS}
    for i, (x, f) in enumerate(zip(spectra, freqs_mhz, strict=True)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            # documented defaults: Fourier(37 terms) data model, Fourier(15) std model,
            # threshold 5, at most 20 iterations, everything flagged if it does not converge
            out["iterative_default"][i] = xrfi.xrfi_iterative(x, freqs=f)[0]
            # the same with a sky's model: a 5-term LinLog foreground, the standard
            # deviation a running median (31 channels) of the squared residuals
            out["iterative_linlog"][i] = xrfi.xrfi_iterative(
                x, freqs=f,
                data_modeler=xrfi.LinearModeler(model=mdl.LinLog(n_terms=5)),
                std_modeler=xrfi.MedianFilterModeler(size=31),
            )[0]
            # Bowman et al. 2018's algorithm (the function's docstring): a 5-term LinLog
            # foreground, RMS in a window of 1/16 of the band, 2.5 sigma, positive only
            out["sliding_window_b18"][i] = xrfi.xrfi_iterative_sliding_window(
                x, freqs=f, model=mdl.LinLog(n_terms=5)
            )[0]
    return out


def main() -> None:
    """Read IN.npz, write OUT.npz."""
    source, target = sys.argv[1], sys.argv[2]
    data = np.load(source)
    flags: dict[str, Any] = run(data["spectra"], data["freqs_mhz"])
    np.savez(target, **flags)


if __name__ == "__main__":
    main()
