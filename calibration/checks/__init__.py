"""What is checked in data and solutions.

Leave-one-out validation, calibrator consistency, the VNA's data-sheet systematics, RFI
flags, data preparation (band masks, smoothing) and Celsius-looking temperatures.
"""
