"""Figures of a calibration: each a function of the project's objects returning a Figure.

Built with matplotlib's object API and rendered with Agg (:mod:`.style`), never a display:

* :func:`noise_wave_parameters`, :func:`evidence_landscape` (:mod:`.parameters`): a solution;
* :func:`calibrated_sources` (:mod:`.sources`): calibrated spectra against their known
  temperatures and their radiometer noise;
* :func:`reflections` (:mod:`.reflections`): the sources' and the receiver's reflection
  coefficients on a Smith chart and in dB;
* :func:`dicke_powers`, :func:`flagged_channels`, :func:`temperatures` (:mod:`.run`): a run;
* :func:`held_out_residuals` (:mod:`.validation`): leave-one-out beside the in-sample fit;
* :func:`adaptive_course` (:mod:`.adaptive`): an adaptive calibration's predicted error
  against instrument time.

Importing this package imports matplotlib; the rest of the engine does not.
"""

from .adaptive import adaptive_course
from .parameters import evidence_landscape, noise_wave_parameters
from .reflections import reflections
from .run import dicke_powers, flagged_channels, temperatures
from .sources import calibrated_sources
from .style import save_png
from .validation import held_out_residuals

__all__ = [
    "adaptive_course",
    "calibrated_sources",
    "dicke_powers",
    "evidence_landscape",
    "flagged_channels",
    "held_out_residuals",
    "noise_wave_parameters",
    "reflections",
    "save_png",
    "temperatures",
]
