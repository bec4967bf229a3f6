"""Noise-wave calibration of a Dicke-switched 21-cm radiometer (REACH).

Pure numerics with its own file readers; usable without any hardware package::

    from calibration import read_run, solve_radiometric, noise_floor
    data, sources = read_run("run.h5")
    solution = solve_radiometric(data)              # evidence-chosen orders
    spectrum = solution.calibrate(data.freq_hz, data.gamma_rec, sources["ant"],
                                  data.channel_width_hz)

The engine is nine subpackages, each one concept, each importing only from those above
it in this list (``tests/test_layers.py`` holds the order, README's "Engine layers"):

* :mod:`calibration.core`: errors, names and constants, crash-safe files, BLAS threads.
* :mod:`calibration.rf`: Touchstone files, one- and two-port corrections, cal kits, cables.
* :mod:`calibration.model`: the forward model (thesis eqs. 3.9-3.27), data containers,
  simulation, source temperatures, the instruments' stated errors.
* :mod:`calibration.regression`: normal equations, conjugate Bayesian regression, priors.
* :mod:`calibration.choice`: model choice: order search, prior scales, model averaging.
* :mod:`calibration.solve`: the solvers, their solutions, the noise floor.
* :mod:`calibration.design`: adaptive calibration, the next calibrator by the antenna's
  predicted error.
* :mod:`calibration.checks` and :mod:`calibration.io`: what is checked in data and
  solutions (validation, consistency, RFI, the VNA's systematics); the files (HDF5 run
  and solution files, EDGES and raw VNA importers).
* :mod:`calibration.report`, then :mod:`calibration.cli` (``reach-cal``).

The names below are imported on first use (PEP 562), not with the package: a program
that needs one module of the engine (the daemon reading a site file, a CLI's ``--help``)
does not pay for importing all of it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .choice.model_fit import OrderChoice
    from .core.errors import (
        CalibrationError,
        DegenerateStandardsError,
        FileFormatError,
        IllPosedError,
        InvalidDataError,
    )
    from .design.adaptive import AdaptivePlanner, AdaptiveSettings, Candidate, Decision
    from .io.hdf5_io import read_run, write_run
    from .io.solution_file import read_solution, write_solution
    from .model.basis import PolynomialBasis
    from .model.data import CalibrationData, Integration, SourceData
    from .model.noise_waves import PARAMETERS
    from .model.simulate import SimulatedRun, SimulationConfig, simulate_run
    from .regression.conjugate import CoefficientPrior, LinearPosterior, ScalePrior
    from .rf.cal_kit import IDEAL_KIT, CalKit
    from .rf.one_port import OnePortTerms, correct_reflection, embed_reflection, solve_one_port
    from .solve.noise_floor import NoiseFloor, noise_floor
    from .solve.radiometric_solver import RadiometricPrior, solve_radiometric
    from .solve.solution import CalibratedSpectrum, Solution
    from .solve.thesis_solver import ThesisPrior, solve_thesis

#: Each public name and the module that defines it.
_WHERE = {
    "OrderChoice": "choice.model_fit",
    "CalibrationError": "core.errors",
    "DegenerateStandardsError": "core.errors",
    "FileFormatError": "core.errors",
    "IllPosedError": "core.errors",
    "InvalidDataError": "core.errors",
    "AdaptivePlanner": "design.adaptive",
    "AdaptiveSettings": "design.adaptive",
    "Candidate": "design.adaptive",
    "Decision": "design.adaptive",
    "read_run": "io.hdf5_io",
    "write_run": "io.hdf5_io",
    "read_solution": "io.solution_file",
    "write_solution": "io.solution_file",
    "PolynomialBasis": "model.basis",
    "CalibrationData": "model.data",
    "Integration": "model.data",
    "SourceData": "model.data",
    "PARAMETERS": "model.noise_waves",
    "SimulatedRun": "model.simulate",
    "SimulationConfig": "model.simulate",
    "simulate_run": "model.simulate",
    "CoefficientPrior": "regression.conjugate",
    "LinearPosterior": "regression.conjugate",
    "ScalePrior": "regression.conjugate",
    "IDEAL_KIT": "rf.cal_kit",
    "CalKit": "rf.cal_kit",
    "OnePortTerms": "rf.one_port",
    "correct_reflection": "rf.one_port",
    "embed_reflection": "rf.one_port",
    "solve_one_port": "rf.one_port",
    "NoiseFloor": "solve.noise_floor",
    "noise_floor": "solve.noise_floor",
    "RadiometricPrior": "solve.radiometric_solver",
    "solve_radiometric": "solve.radiometric_solver",
    "CalibratedSpectrum": "solve.solution",
    "Solution": "solve.solution",
    "ThesisPrior": "solve.thesis_solver",
    "solve_thesis": "solve.thesis_solver",
}

__all__ = [
    "IDEAL_KIT",
    "PARAMETERS",
    "AdaptivePlanner",
    "AdaptiveSettings",
    "CalKit",
    "CalibratedSpectrum",
    "CalibrationData",
    "CalibrationError",
    "Candidate",
    "CoefficientPrior",
    "Decision",
    "DegenerateStandardsError",
    "FileFormatError",
    "IllPosedError",
    "Integration",
    "InvalidDataError",
    "LinearPosterior",
    "NoiseFloor",
    "OnePortTerms",
    "OrderChoice",
    "PolynomialBasis",
    "RadiometricPrior",
    "ScalePrior",
    "SimulatedRun",
    "SimulationConfig",
    "Solution",
    "SourceData",
    "ThesisPrior",
    "correct_reflection",
    "embed_reflection",
    "noise_floor",
    "read_run",
    "read_solution",
    "simulate_run",
    "solve_one_port",
    "solve_radiometric",
    "solve_thesis",
    "write_run",
    "write_solution",
]


def __getattr__(name: str) -> Any:
    """Import the module that defines ``name`` on first use (PEP 562)."""
    if name not in _WHERE:
        raise AttributeError(f"module 'calibration' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_WHERE])
