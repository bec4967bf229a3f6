"""The noise-wave solvers and what they return.

The radiometric solver (the default), the thesis's solver, per-frequency solvers, their
convergence, identifiability and the structure beyond the polynomial box, the solution
object, the noise floor, and one dispatch by name
(:func:`calibration.solve.solvers.solve`).
"""
