"""The ball throw (Zhang et al. 2023, section 8.3): learn the angle of a throw so that the ball
ends up at a goal, with contact before the goal.

A ball (:class:`~drake_abs.tasks.box_lcs.TranslatingBox`: it translates, slides and does not
roll; default radius 5 cm, 1 kg, Coulomb friction 0.4, h = 0.01 s) is thrown from ``height`` (its
centre, m) at a fixed ``speed`` (m/s); it lands inelastically, slides and stops. The policy is
the throwing angle theta (rad above the horizontal); exploration is Gaussian on the angle,
``a = theta + sigma xi``. The return is ``-(p_x(T) - goal)^2`` (m^2) at the end of the horizon.

The throw fits the closed-loop engine as H steps: the state (p_x, p_z, v_x, v_z, held) carries a
``held`` flag, 1 until the ball is released. :class:`ThrowPolicy` outputs ``theta * held``;
:class:`ThrowStepper` releases the ball at the first step with velocity ``speed (cos u, sin u)``
and from then on steps the ball's LCS, ignoring the input. So the exploration noise of later
steps has no effect, and a likelihood-ratio score reduces to the first step's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from drake_abs.contact.lcs import GradientMode, LcsStepper
from drake_abs.contact.smoothing import Smoothing
from drake_abs.contact.step import Step
from drake_abs.policy.estimators import PolicyObjective
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.tasks.box_lcs import TranslatingBox

__all__ = ["ThrowPolicy", "ThrowStepper", "throw_objective"]


@dataclass(frozen=True)
class ThrowPolicy:
    """``u = theta_0 * held``: the throwing angle while the ball is held, 0 afterwards.

    State (5,): (p_x, p_z, v_x, v_z, held); one parameter, the angle (rad)."""

    nx: int = 5
    nu: int = 1
    n_params: int = 1

    def act(self, theta, x) -> np.ndarray:
        return np.asarray(theta, float)[0] * np.asarray(x, float)[:, 4:5]

    def jacobians(self, theta, x) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(x, float)
        du_dx = np.zeros((len(x), 1, 5))
        du_dx[:, 0, 4] = np.asarray(theta, float)[0]
        return du_dx, x[:, None, 4:5].copy()

    def vjp(self, theta, x, g_u) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(x, float)
        g_u = np.asarray(g_u, float)
        g_x = np.zeros((len(x), 5))
        g_x[:, 4] = g_u[:, 0] * np.asarray(theta, float)[0]
        return g_x, g_u * x[:, 4:5]


@dataclass(frozen=True)
class ThrowStepper:
    """Releases a held ball at angle u with ``speed`` (m/s), then steps the ball's LCS.

    State (M, 5) = (p_x, p_z, v_x, v_z, held); input (M, 1) = the angle, read only while held.
    The release step moves nothing else: p+ = p, v+ = speed (cos u, sin u), held+ = 0."""

    ball: LcsStepper
    speed: float

    parameter_names: ClassVar[tuple[str, ...]] = ()

    def step(
        self, x: np.ndarray, u: np.ndarray, *, jacobians: bool = True, parameters: bool = False
    ) -> Step:
        if parameters:
            raise ValueError("parameters=True: ThrowStepper names no model parameters")
        M = x.shape[0]
        held = x[:, 4] > 0.5
        x_next = np.zeros((M, 5))
        conv = np.ones(M, dtype=bool)
        nc = self.ball.lcs.dims[2]
        impulse, mu, iterations = np.zeros((M, nc)), np.zeros((M, nc)), np.zeros(M, np.int64)
        dx_dx = np.zeros((M, 5, 5)) if jacobians else None
        dx_du = np.zeros((M, 5, 1)) if jacobians else None
        a = u[held, 0]
        x_next[held, :2] = x[held, :2]
        x_next[held, 2] = self.speed * np.cos(a)
        x_next[held, 3] = self.speed * np.sin(a)
        free = ~held
        if free.any():
            r = self.ball.step(x[free, :4], np.zeros((int(free.sum()), 1)), jacobians=jacobians)
            x_next[free, :4] = r.x_next
            conv[free] = r.converged
            impulse[free], mu[free], iterations[free] = r.impulse, r.mu, r.iterations
            if jacobians:
                dx_dx[free, :4, :4] = r.dx_dx
        if jacobians and held.any():
            dx_dx[held, 0, 0] = dx_dx[held, 1, 1] = 1.0
            dx_du[held, 2, 0] = -self.speed * np.sin(a)
            dx_du[held, 3, 0] = self.speed * np.cos(a)
        return Step(x_next, conv, iterations, impulse, mu, dx_dx=dx_dx, dx_du=dx_du)


def throw_objective(
    smoothing: Smoothing | None = None,
    gradient: GradientMode = "frozen",
    *,
    height: float = 1.0,
    speed: float = 3.0,
    radius: float = 0.05,
    mass: float = 1.0,
    friction: float = 0.4,
    time_step: float = 0.01,
    horizon: int = 150,
    goal: float = 1.5,
    sigma: float = 0.05,
) -> PolicyObjective:
    """The throw as a :class:`~drake_abs.policy.estimators.PolicyObjective`: the ball's model
    under ``smoothing`` (default: the ball's own, exact) with ``gradient`` mode, thrown from
    ``height`` (m) at ``speed`` (m/s), ``horizon`` steps of ``time_step`` (s), the return
    ``-(p_x(T) - goal)^2`` (m^2), exploration ``sigma`` (rad) on the angle."""
    ball = TranslatingBox(mass=mass, half_height=radius, friction=friction, time_step=time_step)
    stepper = ThrowStepper(ball.stepper(smoothing, gradient), speed)
    reward = QuadraticReward(
        Q=np.zeros((5, 5)), R=np.zeros((1, 1)), x_goal=np.array([goal, 0, 0, 0, 0]),
        Q_final=np.diag([1.0, 0, 0, 0, 0]),
    )  # fmt: skip
    x0 = np.array([0.0, height, 0.0, 0.0, 1.0])
    return PolicyObjective(stepper, ThrowPolicy(), reward, x0, horizon, sigma)
