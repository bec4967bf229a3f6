"""The engine's files.

The HDF5 run and solution files, the receiver's run records, EDGES laboratory runs in
text, raw VNA exports with their standards, the receiver path.
"""
