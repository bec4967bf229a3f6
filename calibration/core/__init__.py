"""The engine's foundation, used by every other part.

Its errors, the names and constants a site file or command line is checked against,
crash-safe file replacement, BLAS threads, and the one sidereal time (astropy's, offline)
that the receiver's schedules and records and the engine's seasons share.
"""
