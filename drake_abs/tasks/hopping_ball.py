"""The hopping ball: the 2-D point mass of Zhang et al. 2023, Figure 1a, under a spring policy,
the task of the gradient-variance experiments (Figure 3), the bias-return experiment's small
task (Figure 5) and the variance benchmark.

The ball (:func:`~drake_abs.tasks.point_mass.point_mass_lcs`, 1 kg, h = :data:`TIME_STEP`,
inelastic hard contact with the ground) is driven by a linear policy ``u = K x + k`` of its state
x = (p_x, p_y, v_x, v_y) (m, m/s), plus Gaussian action noise ``sigma xi_t`` (N). At
:func:`spring_theta` the policy is a vertical spring ``u_y = -k_s (p_y - y_eq)`` (k_s =
:data:`SPRING`, y_eq = :data:`Y_EQ`). Dropped from :data:`X0` (0.3 m, moving sideways at 0.5
m/s) the ball hops: the spring lifts it off the ground and it lands again about every 0.6 s, so
the number of impacts grows with the horizon. The reward of :func:`hopping_ball` tracks p_y =
:data:`Y_GOAL`.
"""

from __future__ import annotations

import numpy as np

from drake_abs.contact.lcs import GradientMode, LcsStepper
from drake_abs.contact.smoothing import Smoothing
from drake_abs.engine.protocols import Reward
from drake_abs.policy.estimators import PolicyObjective
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.tasks.point_mass import point_mass_lcs

__all__ = ["SPRING", "TIME_STEP", "X0", "Y_EQ", "Y_GOAL", "hopping_ball", "spring_theta"]

#: The time step h, s.
TIME_STEP = 0.01
#: The spring policy's stiffness k_s, N/m.
SPRING = 100.0
#: The spring policy's rest height y_eq, m.
Y_EQ = 0.1
#: The initial state (p_x, p_y, v_x, v_y), in m and m/s.
X0 = (0.0, 0.3, 0.5, 0.0)
#: The height p_y the reward tracks, m.
Y_GOAL = 0.2


def hopping_ball(
    smoothing: Smoothing,
    mode: GradientMode = "frozen",
    horizon: int = 200,
    sigma: float = 1.0,
    *,
    reward: Reward | None = None,
    x0=X0,
) -> PolicyObjective:
    """The hopping ball's objective: the ball under ``smoothing`` (gradient ``mode``), a linear
    policy of the state (10 parameters: K (2 x 4) row-major, then k (2)), ``horizon`` steps of
    :data:`TIME_STEP`, action noise ``sigma`` (N) on both axes, from ``x0`` (4,).

    ``reward`` (default: ``-(p_y - Y_GOAL)^2`` per step) replaces the tracking reward."""
    if reward is None:
        reward = QuadraticReward(
            Q=np.diag([0.0, 1.0, 0.0, 0.0]),
            R=np.zeros((2, 2)),
            x_goal=np.array([0.0, Y_GOAL, 0.0, 0.0]),
        )
    stepper = LcsStepper(point_mass_lcs(2, time_step=TIME_STEP), smoothing, mode)
    return PolicyObjective(stepper, LinearPolicy(4, 2), reward, np.array(x0), horizon, sigma)


def spring_theta() -> np.ndarray:
    """(10,) theta of the spring policy ``u = (0, -k_s (p_y - y_eq))``: K row-major (2 x 4),
    then k (2)."""
    theta = np.zeros(10)
    theta[4 + 1] = -SPRING
    theta[9] = SPRING * Y_EQ
    return theta
