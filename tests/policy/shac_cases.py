"""A small training environment for the SHAC tests: a point mass (x = (position m, velocity
m/s), force input) that should stay near the origin, with an alive bonus and an episode that
ends when it leaves |position| < 2."""

from dataclasses import dataclass

import numpy as np

from drake_abs.engine.steppers import LinearStepper
from drake_abs.tasks.adapters import ObservationPolicy
from drake_abs.tasks.locomotion import LocomotionObservation

DT = 0.1


@dataclass(frozen=True)
class StayNearZero:
    """r = 1 - p'^2 - 0.1 v'^2 - 0.01 u^2 of the next state (p', v'); terminated at |p'| > 2."""

    nx: int = 2
    nu: int = 1
    bound: float = 2.0

    def transition(self, x, u, x_next):
        r = 1 - x_next[:, 0] ** 2 - 0.1 * x_next[:, 1] ** 2 - 0.01 * u[:, 0] ** 2
        dr_dxn = np.stack([-2 * x_next[:, 0], -0.2 * x_next[:, 1]], axis=1)
        return r, np.zeros_like(x), -0.02 * u, dr_dxn

    def terminal(self, x):
        return np.zeros(len(x)), np.zeros_like(x)

    def terminated(self, x_next):
        return np.abs(x_next[:, 0]) > self.bound


@dataclass(frozen=True)
class PointMassEnv:
    """The environment: starts uniform in [-1, 1]^2, observes the full state."""

    stepper: LinearStepper = LinearStepper(
        np.array([[1.0, DT], [0.0, 1.0]]), np.array([[0.0], [DT]])
    )
    reward: StayNearZero = StayNearZero()
    observation: LocomotionObservation = LocomotionObservation(1, 1, None, 0)

    @property
    def n_obs(self) -> int:
        return 2

    @property
    def nu(self) -> int:
        return 1

    def initial_states(self, rng, M):
        return rng.uniform(-1.0, 1.0, (M, 2))

    def policy(self, inner):
        return ObservationPolicy(inner, self.observation)
