"""The noise-wave model of the receiver and what it is fitted to.

The forward model (thesis eqs. 3.9-3.27), polynomial bases, the data containers,
simulated runs, the sources' reflections and noise temperatures, and the instruments'
stated errors.
"""
