"""Model choice.

Polynomial orders by evidence, the order box the data support, prior scales per
parameter, checks of model size beyond the in-sample fit, and Bayesian model averaging
with its mixture intervals.
"""
