"""Noise-wave calibration of a Dicke-switched 21-cm radiometer (REACH).

Pure numerics with its own file readers; usable without any hardware package::

    from calibration import simulate_run, solve_radiometric, noise_floor
    run = simulate_run(rng=1)
    solution = solve_radiometric(run.data)          # evidence-chosen orders
    spectrum = solution.calibrate(run.data.freq_hz, run.data.gamma_rec, run.validation,
                                  run.data.channel_width_hz)

Modules: :mod:`~calibration.noise_waves` (forward model, thesis eqs. 3.9-3.27),
:mod:`~calibration.data` (containers and checks), :mod:`~calibration.simulate`,
:mod:`~calibration.thesis_solver` (EXCALIBRATE, the published baseline),
:mod:`~calibration.radiometric_solver` (the default, floor-reaching solver),
:mod:`~calibration.noise_floor` (Cramer-Rao floor), :mod:`~calibration.order_search`,
:mod:`~calibration.one_port` (short-open-load VNA calibration) with
:mod:`~calibration.cal_kit` (Keysight-style calibration-kit models).

The names below are imported on first use (PEP 562), not with the package: a program
that needs one module of the engine (the daemon reading a site file, a CLI's ``--help``)
does not pay for importing all of it.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .basis import PolynomialBasis
    from .cal_kit import IDEAL_KIT, CalKit
    from .conjugate import CoefficientPrior, LinearPosterior, ScalePrior
    from .data import CalibrationData, Integration, SourceData
    from .errors import (
        CalibrationError,
        DegenerateStandardsError,
        FileFormatError,
        IllPosedError,
        InvalidDataError,
    )
    from .model_fit import OrderChoice
    from .noise_floor import NoiseFloor, noise_floor
    from .noise_waves import PARAMETERS
    from .one_port import OnePortTerms, correct_reflection, embed_reflection, solve_one_port
    from .radiometric_solver import RadiometricPrior, solve_radiometric
    from .simulate import SimulatedRun, SimulationConfig, simulate_run
    from .solution import CalibratedSpectrum, Solution
    from .thesis_solver import ThesisPrior, solve_thesis

#: Each public name and the module that defines it.
_WHERE = {
    "PolynomialBasis": "basis",
    "IDEAL_KIT": "cal_kit",
    "CalKit": "cal_kit",
    "CoefficientPrior": "conjugate",
    "LinearPosterior": "conjugate",
    "ScalePrior": "conjugate",
    "CalibrationData": "data",
    "Integration": "data",
    "SourceData": "data",
    "CalibrationError": "errors",
    "DegenerateStandardsError": "errors",
    "FileFormatError": "errors",
    "IllPosedError": "errors",
    "InvalidDataError": "errors",
    "OrderChoice": "model_fit",
    "NoiseFloor": "noise_floor",
    "noise_floor": "noise_floor",
    "PARAMETERS": "noise_waves",
    "OnePortTerms": "one_port",
    "correct_reflection": "one_port",
    "embed_reflection": "one_port",
    "solve_one_port": "one_port",
    "RadiometricPrior": "radiometric_solver",
    "solve_radiometric": "radiometric_solver",
    "SimulatedRun": "simulate",
    "SimulationConfig": "simulate",
    "simulate_run": "simulate",
    "CalibratedSpectrum": "solution",
    "Solution": "solution",
    "ThesisPrior": "thesis_solver",
    "solve_thesis": "thesis_solver",
}

__all__ = [
    "IDEAL_KIT",
    "PARAMETERS",
    "CalKit",
    "CalibratedSpectrum",
    "CalibrationData",
    "CalibrationError",
    "CoefficientPrior",
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
    "simulate_run",
    "solve_one_port",
    "solve_radiometric",
    "solve_thesis",
]


class _Package(types.ModuleType):
    """The package, whose public names win over its submodules of the same name.

    Importing ``calibration.noise_floor`` (the module) sets the package's attribute
    ``noise_floor``; the public name is the function :func:`noise_floor.noise_floor`, as
    it was when the package imported everything up front.
    """

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, types.ModuleType) and _WHERE.get(name) == name:
            value = getattr(value, name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package


def __getattr__(name: str) -> Any:
    """Import the module that defines ``name`` on first use (PEP 562)."""
    if name not in _WHERE:
        raise AttributeError(f"module 'calibration' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_WHERE])
