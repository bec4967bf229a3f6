"""Adaptive calibration: which calibrator to measure next, and for how long.

The antenna's predicted calibration error from the current posterior and its change when
a calibrator gets more time (:mod:`.information`), the planner that chooses by it and
stops at a target or a budget (:mod:`.adaptive`), each calibrator's contribution and the
times a target needs (:mod:`.contributions`), and a simulated receiver that averages
repeated measurements as the hand-over does (:mod:`.simulated`).
"""
