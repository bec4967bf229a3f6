"""REACH receiver control: drivers, front-end model, scheduler, store and daemon.

The calibration engine lives in the separate package :mod:`calibration`, which does not
import this one.
"""

__version__ = "0.1.0"
