"""Benchmarks of the calibration engine (run them with ``python -m benchmarks.run_all``)."""
