"""Adapters between a reinforcement-learning interface and the engine's full-state protocols:
the action an agent chooses is not the plant's input, and what it observes is not the state.

- :class:`ActionScaled`: a :class:`~drake_abs.engine.protocols.Stepper` whose input is an
  action ``a`` (M, nu), the inner stepper's input being ``scale * a`` elementwise (gymnasium's
  ctrl in [-1, 1] times the motors' gears: joint torques in N m).
- :class:`ObservationPolicy`: a :class:`~drake_abs.engine.protocols.Policy` of the full state x
  made of an inner policy of an observation ``o = obs(x)``: ``u = pi(obs(x); theta)``, with the
  chain rule for its Jacobians and vector-Jacobian products.

An observation map is any object with ``n_obs``, ``nx``, ``__call__(x (M, nx)) -> (M, n_obs)``,
``jacobian(x) -> (M, n_obs, nx)`` and ``vjp(x, g_o (M, n_obs)) -> (M, nx)``, e.g.
:class:`drake_abs.tasks.locomotion.LocomotionObservation`.

Both are plain dataclasses of picklable parts, so an objective made of them can be sent to Ray
workers (:mod:`drake_abs.parallel`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Protocol, runtime_checkable

import numpy as np

from drake_abs._validation import as_finite_array
from drake_abs.contact.step import Step
from drake_abs.engine.protocols import Policy, Stepper, check_protocol

__all__ = ["ActionScaled", "Observation", "ObservationPolicy"]


@dataclass(frozen=True)
class ActionScaled:
    """``stepper`` driven by actions: ``step(x, a)`` is ``stepper.step(x, scale * a)``, its
    input Jacobians (``dx_du``, ``dimpulse_du``, ``dmu_du``) scaled column by column.

    Anything the inner stepper does to its input (a scene's stepper clips joint torques at the
    actuators' effort limits, with a zero ``dx_du`` column where it clips) is kept.

    Args:
        stepper: the inner :class:`~drake_abs.engine.protocols.Stepper`.
        scale: (nu,) or a scalar: the inner input per unit of action (for gymnasium's MuJoCo
            tasks, the motors' gears: N m per unit of ctrl). Nonzero and finite.
    """

    stepper: Stepper
    scale: np.ndarray

    def __post_init__(self):
        check_protocol(
            self.stepper, Stepper, "stepper", "step(x, u, *, jacobians, parameters) -> Step, "
            "parameter_names",
        )  # fmt: skip
        scale = as_finite_array(self.scale, "scale", ndim=(0, 1))
        if np.any(scale == 0):
            raise ValueError(f"scale must be nonzero (a zero column loses the input); got {scale}")
        object.__setattr__(self, "scale", np.atleast_1d(scale))

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """The inner stepper's model parameters (scaling the input adds none)."""
        return tuple(self.stepper.parameter_names)

    def step(self, x, u, *, jacobians: bool = True, parameters: bool = False, **options) -> Step:
        """Step a batch: x (M, nx), actions u (M, nu) (or what the inner stepper accepts);
        ``options`` (e.g. a scene stepper's ``smoothing_parameters``) go to the inner stepper."""
        u = np.asarray(u, dtype=float)
        if self.scale.size != 1 and (u.ndim == 0 or u.shape[-1] != self.scale.size):
            raise ValueError(
                f"u must have nu = {self.scale.size} entries in its last axis (the action); got "
                f"shape {u.shape}"
            )
        inner = self.stepper.step(
            x, u * self.scale, jacobians=jacobians, parameters=parameters, **options
        )
        scaled = {
            name: getattr(inner, name) * self.scale
            for name in ("dx_du", "dimpulse_du", "dmu_du")
            if getattr(inner, name) is not None
        }
        return replace(inner, **scaled) if scaled else inner


@runtime_checkable
class Observation(Protocol):
    """A differentiable observation map ``o = obs(x)`` for a batch: x (M, nx) -> o (M, n_obs)."""

    nx: int
    n_obs: int

    def __call__(self, x: np.ndarray) -> np.ndarray: ...

    def jacobian(self, x: np.ndarray) -> np.ndarray: ...

    def vjp(self, x: np.ndarray, g_o: np.ndarray) -> np.ndarray: ...


OBSERVATION_FORM = "nx, n_obs, __call__(x), jacobian(x), vjp(x, g_o)"


@dataclass(frozen=True)
class ObservationPolicy:
    """``u = pi(obs(x); theta)``: a :class:`~drake_abs.engine.protocols.Policy` of the full
    state x (nx) made of ``inner``, a policy of the observation (its ``nx`` is ``n_obs``).

    The parameters are the inner policy's (``n_params``); so are their meaning and any ``init``.
    An inner :class:`~drake_abs.engine.protocols.PullbackPolicy`'s ``pullback`` is not used:
    the engine recomputes the composed ``vjp`` in its reverse pass.

    Args:
        inner: a :class:`~drake_abs.engine.protocols.Policy` with ``inner.nx == observation.n_obs``.
        observation: the :class:`Observation` map.
    """

    inner: Policy
    observation: Observation

    def __post_init__(self):
        check_protocol(self.inner, Policy, "inner", "nx, nu, n_params, act, jacobians, vjp")
        check_protocol(self.observation, Observation, "observation", OBSERVATION_FORM)
        if self.inner.nx != self.observation.n_obs:
            raise ValueError(
                f"inner must take the observation: inner.nx = {self.inner.nx}, but the "
                f"observation has n_obs = {self.observation.n_obs} entries"
            )

    @property
    def nx(self) -> int:
        """The full state's size."""
        return self.observation.nx

    @property
    def nu(self) -> int:
        return self.inner.nu

    @property
    def n_params(self) -> int:
        return self.inner.n_params

    def _x(self, x) -> np.ndarray:
        x = as_finite_array(x, "x", ndim=(2,))
        if x.shape[1] != self.nx:
            raise ValueError(f"x must have shape (M, nx) = (M, {self.nx}); got {x.shape}")
        return x

    def act(self, theta, x) -> np.ndarray:
        """u (M, nu) at states x (M, nx)."""
        return self.inner.act(theta, self.observation(self._x(x)))

    def jacobians(self, theta, x) -> tuple[np.ndarray, np.ndarray]:
        """(du/dx (M, nu, nx), du/dtheta (M, nu, P)): du/do do/dx, and the inner policy's."""
        x = self._x(x)
        du_do, du_dth = self.inner.jacobians(theta, self.observation(x))
        return du_do @ self.observation.jacobian(x), du_dth

    def vjp(self, theta, x, g_u) -> tuple[np.ndarray, np.ndarray]:
        """(g_u du/dx (M, nx), g_u du/dtheta (M, P)) for g_u (M, nu)."""
        x = self._x(x)
        g_o, g_th = self.inner.vjp(theta, self.observation(x), g_u)
        return self.observation.vjp(x, g_o), g_th
