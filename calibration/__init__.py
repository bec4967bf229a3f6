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
"""

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
