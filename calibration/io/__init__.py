"""The engine's files.

The HDF5 run and solution files, the receiver's run records and its channel grid (with
an S11 sweep carried onto it), EDGES laboratory runs in text, raw VNA exports with their
standards, the receiver path.
"""
