"""Differentiable QP-MPC (OSQP, with KKT Jacobians of the first input), least-squares system
identification, and gray-box tuning of the MPC's cost parameters in closed loop.

Drake-free.
"""
