"""Bayesian linear regression of the polynomial noise-wave model.

Weighted normal equations, the conjugate posterior, evidence and predictive, a
coefficient prior whose width the data set, and the VNA's error in the design rows
(errors in variables).
"""
