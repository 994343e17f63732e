"""What the closed-loop engine needs of a stepper, a policy and a reward (docs/math.md section 7).

Shapes are for a batch of M states: x (M, nx), u (M, nu), flat policy parameters theta (P,).

- :class:`Stepper`: ``step(x, u, *, jacobians, parameters) -> Step`` (the one step record,
  :class:`drake_abs.contact.step.Step`), and the names of its model parameters.
- :class:`Policy`: ``u = pi(x; theta)`` with ``act``, ``jacobians`` and ``vjp``.
- :class:`TimeVaryingPolicy`: a controller of the state and the step index, run forward only.
- :class:`PullbackPolicy`: a policy whose vector-Jacobian product needs the work of its forward
  evaluation (an MPC's KKT system): ``pullback(theta, x) -> (u, vjp)``; the engine then keeps
  ``vjp`` for the reverse pass instead of calling ``Policy.vjp`` again.
- :class:`Reward`: one sign convention for every objective: **rewards are maximised**. A cost
  (an MPC's tracking cost, a model-fitting loss) enters as its negative.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

import numpy as np

from drake_abs.contact.step import Step


@runtime_checkable
class Stepper(Protocol):
    """A batched step ``x+ = f(x, u)``: an :class:`~drake_abs.contact.lcs.LcsStepper`, a
    scene's ``ComplementarityStepper``, a ``QuadcopterStepper``, a
    :class:`~drake_abs.engine.steppers.LinearStepper`.

    ``step(x (M, nx), u (M, nu), jacobians=True, parameters=False)`` returns a
    :class:`~drake_abs.contact.step.Step`; with ``jacobians`` it has ``dx_dx`` (M, nx, nx) and
    ``dx_du`` (M, nx, nu), with ``parameters`` also ``dx_dtheta`` (M, nx, T) for the T model
    parameters ``parameter_names`` (a stepper without any raises ``ValueError``).
    """

    @property
    def parameter_names(self) -> tuple[str, ...]: ...

    def step(self, x, u, *, jacobians: bool = True, parameters: bool = False) -> Step: ...


@runtime_checkable
class Policy(Protocol):
    """A deterministic policy ``u = pi(x; theta)``, batched over states.

    - ``act(theta, x)`` -> u (M, nu);
    - ``jacobians(theta, x)`` -> (du/dx (M, nu, nx), du/dtheta (M, nu, P));
    - ``vjp(theta, x, g_u)`` -> (g_u du/dx (M, nx), g_u du/dtheta (M, P)): the reverse products
      of the adjoint pass, without forming du/dtheta (an MLP's can be large).
    """

    nx: int
    nu: int

    @property
    def n_params(self) -> int: ...

    def act(self, theta, x) -> np.ndarray: ...

    def jacobians(self, theta, x) -> tuple[np.ndarray, np.ndarray]: ...

    def vjp(self, theta, x, g_u) -> tuple[np.ndarray, np.ndarray]: ...


@runtime_checkable
class TimeVaryingPolicy(Protocol):
    """A controller of the state and the step index, ``u = pi(x, t; theta)``, marked by the
    class attribute ``time_varying = True``: ``act(theta, x (M, nx), t: int) -> u (M, nu)``
    (a scripted gait, a stepping controller, seeded random inputs). The engine runs it forward
    only (``gradient=False``): it has no Jacobians."""

    time_varying: bool
    nx: int
    nu: int

    def act(self, theta, x, t: int) -> np.ndarray: ...


#: ``vjp(g_u (M, nu)) -> (g_x (M, nx), g_theta (M, P))`` at the point where it was made.
PolicyVjp = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@runtime_checkable
class PullbackPolicy(Policy, Protocol):
    """A :class:`Policy` that also gives ``pullback(theta, x) -> (u (M, nu), vjp)``: the action
    and its vector-Jacobian product made from the same evaluation (the engine keeps ``vjp``
    per step when it differentiates, instead of evaluating the policy a second time)."""

    def pullback(self, theta, x) -> tuple[np.ndarray, PolicyVjp]: ...


@runtime_checkable
class Reward(Protocol):
    """A reward, maximised (a cost enters with a minus sign), batched over rollouts.

    - ``stage(x, u)`` -> (r (M,), dr/dx (M, nx), dr/du (M, nu)), summed over t = 0 .. H-1;
    - ``terminal(x)`` -> (r_T (M,), dr_T/dx (M, nx)), added at t = H.

    A reward of the transition is a :class:`TransitionReward` instead.
    """

    def stage(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...

    def terminal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...


@runtime_checkable
class TransitionReward(Protocol):
    """A reward of each transition (x_t, u_t, x_{t+1}), as gymnasium's locomotion rewards are
    (forward velocity from the positions before and after the step), maximised:

    - ``transition(x, u, x_next)`` -> (r (M,), dr/dx (M, nx), dr/du (M, nu), dr/dx_next (M, nx)),
      summed over t = 0 .. H-1;
    - ``terminal(x)`` -> (r_T (M,), dr_T/dx (M, nx)), added at t = H.

    A reward with the class attribute ``uses_step = True`` is called as ``transition(x, u,
    x_next, step=step)`` with the :class:`~drake_abs.contact.step.Step` that made x_next (a term
    of the step's contact impulses, as the Ant's contact cost; its derivatives are the
    reward's to give).

    Optionally ``terminated(x_next) -> (M,) bool``: an episode ends with the step that reached
    x_next (that step's reward counts; the later steps' rewards and the terminal reward do not,
    as in gymnasium, where ``terminated`` ends the episode). The indicator has zero derivative.
    """

    def transition(
        self, x: np.ndarray, u: np.ndarray, x_next: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...

    def terminal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...


#: What a reward argument must be, for error messages.
REWARD_FORM = "stage(x, u) or transition(x, u, x_next), and terminal(x)"


def check_reward(reward, name: str = "reward") -> None:
    """Raise ``TypeError`` naming the argument unless ``reward`` is a :class:`Reward` or a
    :class:`TransitionReward`."""
    if not isinstance(reward, Reward | TransitionReward):
        raise TypeError(f"{name} must be a Reward ({REWARD_FORM}); got {type(reward).__name__}")


def check_protocol(value, protocol: type, name: str, form: str) -> None:
    """Raise ``TypeError`` naming the argument unless ``value`` follows ``protocol``."""
    if not isinstance(value, protocol):
        raise TypeError(
            f"{name} must be a {protocol.__name__} ({form}); got {type(value).__name__}"
        )
