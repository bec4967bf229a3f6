"""Simulated receiver: one physical model behind instruments that speak the real protocols."""
