"""Suite-wide settings.

One BLAS thread per test process: the suite runs in two worker processes on two cores
(pyproject's ``-n 2``), and numerical tests that each started a BLAS thread per core
would take the cores from the hardware-in-the-loop tests running beside them, whose
simulated clocks run at up to 3000x real time. Set before any worker imports numpy
(workers inherit this environment); a value set by the caller is kept.
"""

import os

for variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(variable, "1")
