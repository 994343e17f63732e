"""Concrete systems the experiments use: the point mass and the translating box as linear
complementarity systems, and the 12-state quadcopter of the differentiable-MPC experiments.

Drake-free.
"""
