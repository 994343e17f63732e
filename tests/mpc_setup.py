"""The quadcopter MPC set-up the MPC tests share: hover linearisation, the paper's target, the
cost weights, the Riccati terminal cost and its theta, and the paper 003 constraints."""

import numpy as np

from drake_abs.mpc.qp_mpc import riccati_terminal_cost, theta_from_cost
from drake_abs.tasks import quadcopter as qc

PRM = qc.QuadcopterParams()
A_H, B_H = qc.hover_linearization(PRM)
X_REF = np.r_[-6.0, -3.5, 0.0, np.zeros(9)]
U_REF = PRM.hover_input()
Q_D = np.r_[np.ones(6), 0.1 * np.ones(6)]
R_D = np.full(4, 0.01)
P_DARE, K_LQR = riccati_terminal_cost(A_H, B_H, np.diag(Q_D), np.diag(R_D))
THETA = theta_from_cost(Q_D, R_D, P_DARE)
X_MIN, X_MAX = qc.QuadcopterConstraints().state_bounds()
U_MIN, U_MAX = qc.QuadcopterConstraints().input_bounds()
