"""Reflection measurements.

Touchstone files, short-open-load (one-port) and two-port corrections, calibration-kit
models and their file format, lossy coaxial cables.
"""
