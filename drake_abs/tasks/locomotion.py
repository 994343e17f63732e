"""gymnasium's Hopper-v5 and HalfCheetah-v5 tasks on our plant: the published MuJoCo models
(scenes ``gym_hopper`` and ``gym_half_cheetah``), gymnasium v5's reward terms, observation vector,
action range and reset noise, batched and differentiable for the closed-loop engine.

State x = (q, v), nx = nq + nv, in MuJoCo's order (q = qpos, v = qvel; q[0] = rootx, the
forward position in m; q[1] = rootz, m; q[2] = rooty, the torso's pitch in rad). The action
(gymnasium's ``ctrl``) is in [-1, 1] per motor; the scene's stepper takes joint torque = gear *
ctrl (:class:`~drake_abs.tasks.adapters.ActionScaled`) and clips it at the effort limit, gear N m,
which is gymnasium's clipping of ctrl to its ``ctrlrange`` [-1, 1].

Reward of a transition (x_t, a_t, x_{t+1}), as gymnasium v5 computes it (``_get_rew``)::

    r_t = w_f (x_{t+1}[0] - x_t[0]) / dt  -  w_c |a_t|^2  +  h * healthy(x_{t+1})

with gymnasium's defaults: Hopper w_f = 1, w_c = 1e-3, h = 1; HalfCheetah w_f = 1, w_c = 0.1,
h = 0 (no healthy term). The control cost is on the action as given (before clipping), as in
gymnasium. The healthy reward counts only when the state after the step is healthy (v5), and for
the Hopper an unhealthy state ends the episode (``terminated``). Its healthy test (strict
inequalities, as gymnasium's ``is_healthy``): every entry of x[2:] in (-100, 100), the height
q[1] in (0.7, inf), the pitch q[2] in (-0.2, 0.2). The indicator has zero derivative.

**Control period: gymnasium's.** A task acts once per control period ``dt``, by default
gymnasium's (``frame_skip`` times the model file's time step: Hopper 4 x 2 ms = 8 ms,
HalfCheetah 5 x 10 ms = 50 ms), holding the action over ``substeps`` steps of our plant
(:class:`~drake_abs.engine.steppers.ZeroOrderHold`) of ``dt / substeps`` each; by default as
few substeps as keep our step at or below the scene's own ``time_step`` (10 ms): one 8 ms step
for the Hopper, five 10 ms steps for the HalfCheetah. The forward velocity divides by ``dt``, so
an episode of 1000 actions lasts what gymnasium's does (8 s, 50 s). ``locomotion_task(...,
control_period=, substeps=)`` trades accuracy for speed (fewer, longer steps).

**Smooth survive term (a training option).** gymnasium's healthy reward is an indicator: its
derivative is zero, so a first-order method sees no reason to stay up. ``GymLocomotionReward(...,
smooth_survive=SmoothHealthy(...))`` replaces it, in the reward a method trains on, by a product
of logistic functions of the height's and the pitch's margins to the healthy ranges (1 deep
inside, 1/2 at a bound; :class:`SmoothHealthy`; a larger width is a smoother term felt farther
from the bounds). Termination stays gymnasium's (the indicator), and so does the reward that
scores a policy.

Observation (gymnasium v5, ``exclude_current_positions_from_observation=True``): q[1:] and v,
the Hopper's v clipped to [-10, 10] (11 values); the HalfCheetah's unclipped (17 values).

Initial state: gymnasium resets to its model's initial pose (our scenes' ``x0``: the same pose)
plus noise: the Hopper q and v each uniform in +-5e-3; the HalfCheetah q uniform in +-0.1 and v
0.1 times a standard normal. The batched objective (:meth:`LocomotionTask.objective`) starts every
rollout from the one ``x0``; :meth:`LocomotionTask.initial_states` draws gymnasium's reset noise
for experiments that want it (``engine.rollout`` takes (M, nx) initial states).

Building a task (:func:`locomotion_task`) builds the scene's stepper, which needs Drake
(:mod:`drake_abs.multibody`, imported when called); the rest of this module is Drake-free.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from drake_abs._validation import as_count, as_finite_array
from drake_abs.engine.protocols import Policy
from drake_abs.engine.steppers import ZeroOrderHold
from drake_abs.policy.estimators import PolicyObjective
from drake_abs.tasks.adapters import ActionScaled, ObservationPolicy
from drake_abs.tasks.ant import AntObservation, AntReward
from drake_abs.tasks.free_body import FreeBodyCoordinates

__all__ = [
    "CONTACT_LAWS",
    "GymLocomotionReward",
    "HealthyRanges",
    "LocomotionObservation",
    "LocomotionTask",
    "ResetNoise",
    "SmoothHealthy",
    "TASKS",
    "locomotion_task",
]


def _batch(value, name: str, size: int, what: str) -> np.ndarray:
    """``value`` as a float array (M, size), ``ValueError`` naming ``name`` otherwise."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != size:
        raise ValueError(f"{name} must have shape (M, {what}) = (M, {size}); got {arr.shape}")
    return arr


@dataclass(frozen=True)
class LocomotionObservation:
    """gymnasium v5's observation of a planar locomotion model: ``(q[skip:], clip(v, -c, c))``.

    Args:
        nq, nv: sizes of q and v (x = (q, v)).
        velocity_clip: c (units of v); None: v unclipped (HalfCheetah), 10 for the Hopper.
        skip: leading entries of q left out (1: gymnasium's
            ``exclude_current_positions_from_observation=True``, the forward position).
    """

    nq: int
    nv: int
    velocity_clip: float | None = None
    skip: int = 1

    def __post_init__(self):
        as_count(self.nq, "nq", minimum=1)
        as_count(self.nv, "nv", minimum=0)
        if not 0 <= self.skip <= self.nq:
            raise ValueError(f"skip must be in 0 .. nq = {self.nq}; got {self.skip!r}")
        if self.velocity_clip is not None and not self.velocity_clip > 0:
            raise ValueError(f"velocity_clip must be > 0 or None; got {self.velocity_clip!r}")

    @property
    def nx(self) -> int:
        return self.nq + self.nv

    @property
    def n_obs(self) -> int:
        return self.nq - self.skip + self.nv

    def _inside(self, v: np.ndarray) -> np.ndarray:
        """Where the clip passes v through (derivative 1); 0 at and beyond the bounds."""
        if self.velocity_clip is None:
            return np.ones_like(v)
        return (np.abs(v) < self.velocity_clip).astype(float)

    def __call__(self, x) -> np.ndarray:
        """o (M, n_obs) of states x (M, nx)."""
        x = _batch(x, "x", self.nx, "nx")
        v = x[:, self.nq :]
        if self.velocity_clip is not None:
            v = np.clip(v, -self.velocity_clip, self.velocity_clip)
        return np.concatenate([x[:, self.skip : self.nq], v], axis=1)

    def jacobian(self, x) -> np.ndarray:
        """do/dx (M, n_obs, nx): a selection, with zero rows where a velocity is clipped."""
        x = _batch(x, "x", self.nx, "nx")
        M, kept = x.shape[0], self.nq - self.skip
        J = np.zeros((M, self.n_obs, self.nx))
        J[:, np.arange(kept), self.skip + np.arange(kept)] = 1.0
        J[:, kept + np.arange(self.nv), self.nq + np.arange(self.nv)] = self._inside(
            x[:, self.nq :]
        )
        return J

    def vjp(self, x, g_o) -> np.ndarray:
        """g_o do/dx (M, nx) for g_o (M, n_obs)."""
        x = _batch(x, "x", self.nx, "nx")
        g_o = _batch(g_o, "g_o", self.n_obs, "n_obs")
        kept = self.nq - self.skip
        g_x = np.zeros((x.shape[0], self.nx))
        g_x[:, self.skip : self.nq] = g_o[:, :kept]
        g_x[:, self.nq :] = g_o[:, kept:] * self._inside(x[:, self.nq :])
        return g_x


@dataclass(frozen=True)
class HealthyRanges:
    """gymnasium Hopper-v5's healthy test of a state x = (q, v): every entry of x[2:] in
    ``state``, q[1] (height, m) in ``z``, q[2] (pitch, rad) in ``angle``; open intervals, as
    gymnasium's ``is_healthy``. Defaults: gymnasium's."""

    state: tuple[float, float] = (-100.0, 100.0)
    z: tuple[float, float] = (0.7, float("inf"))
    angle: tuple[float, float] = (-0.2, 0.2)

    def __post_init__(self):
        for name in ("state", "z", "angle"):
            lo, hi = getattr(self, name)
            if not lo < hi:
                raise ValueError(
                    f"{name} must be a range (low, high) with low < high; got {lo, hi}"
                )

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """(M,) bool: whether each state x (M, nx) is healthy."""
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[1] < 3:
            raise ValueError(f"x must have shape (M, nx) with nx >= 3; got {x.shape}")
        state = x[:, 2:]
        (s0, s1), (z0, z1), (a0, a1) = self.state, self.z, self.angle
        ok_state = np.all((s0 < state) & (state < s1), axis=1)
        return ok_state & (z0 < x[:, 1]) & (x[:, 1] < z1) & (a0 < x[:, 2]) & (x[:, 2] < a1)


@dataclass(frozen=True)
class SmoothHealthy:
    """A smooth stand-in for :class:`HealthyRanges`' indicator: ``s(x) = prod_b sigma(m_b /
    w_b)`` over the finite bounds b of the height q[1] (width ``z_width``, m) and the pitch q[2]
    (``angle_width``, rad), m_b the margin to the bound (positive inside), sigma the logistic
    function. s is in (0, 1): near 1 deep inside the ranges, 1/2 on a bound. A larger width is
    smoother (the term pulls from farther away, and less steeply). The state range (every entry
    of x[2:] in +-100) is left out: it never binds in practice.

    Args:
        ranges: the healthy ranges it stands in for (default gymnasium's Hopper's).
        z_width: w of the height's bounds (m), > 0.
        angle_width: w of the pitch's bounds (rad), > 0.
    """

    ranges: HealthyRanges = HealthyRanges()
    z_width: float = 0.05
    angle_width: float = 0.05

    def __post_init__(self):
        for name in ("z_width", "angle_width"):
            w = getattr(self, name)
            if not (np.isfinite(w) and w > 0):
                raise ValueError(f"{name} must be a finite number > 0; got {w!r}")

    def value_and_gradient(self, x) -> tuple[np.ndarray, np.ndarray]:
        """(s (M,), ds/dx (M, nx)) at states x (M, nx), nx >= 3."""
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[1] < 3:
            raise ValueError(f"x must have shape (M, nx) with nx >= 3; got {x.shape}")
        log_s = np.zeros(x.shape[0])
        dlog = np.zeros(x.shape)
        for col, (lo, hi), w in ((1, self.ranges.z, self.z_width),
                                 (2, self.ranges.angle, self.angle_width)):  # fmt: skip
            for bound, sign in ((lo, 1.0), (hi, -1.0)):
                if not np.isfinite(bound):
                    continue
                t = sign * (x[:, col] - bound) / w  # the margin, in widths
                log_s -= np.logaddexp(0.0, -t)  # log sigma(t)
                dlog[:, col] += sign / w * np.exp(-np.logaddexp(0.0, t))  # sigma(-t) dt/dx
        s = np.exp(log_s)
        return s, s[:, None] * dlog


@dataclass(frozen=True)
class GymLocomotionReward:
    """gymnasium v5's locomotion reward of a transition, batched, with its derivatives (a
    :class:`~drake_abs.engine.protocols.TransitionReward`; the module docstring has the formula).

    Args:
        nq, nv, nu: sizes of q, v and the action.
        dt: the control period (s) the forward velocity divides by: the task's.
        forward_reward_weight: w_f (reward per m/s).
        ctrl_cost_weight: w_c (per unit of action squared).
        healthy_reward: h, per step ending healthy (0 and ``healthy=None``: no healthy term).
        healthy: the healthy test (:class:`HealthyRanges`) or None.
        terminate_when_unhealthy: ``terminated(x_next)`` is True where x_next is not healthy.
        smooth_survive: a training option: the healthy reward is ``h * s(x_next)``
            (:class:`SmoothHealthy`, with a derivative) instead of the indicator's; needs
            ``healthy``. Termination is unchanged. None (default): gymnasium's reward.

    :meth:`hopper` and :meth:`half_cheetah` give gymnasium v5's defaults.
    """

    nq: int
    nv: int
    nu: int
    dt: float
    forward_reward_weight: float = 1.0
    ctrl_cost_weight: float = 1e-3
    healthy_reward: float = 0.0
    healthy: HealthyRanges | None = None
    terminate_when_unhealthy: bool = False
    smooth_survive: SmoothHealthy | None = None

    def __post_init__(self):
        for name in ("nq", "nv", "nu"):
            as_count(getattr(self, name), name, minimum=1)
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a finite time step > 0 (s); got {self.dt!r}")
        for name in ("forward_reward_weight", "ctrl_cost_weight", "healthy_reward"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite; got {getattr(self, name)!r}")
        if self.healthy is None and (self.healthy_reward != 0 or self.terminate_when_unhealthy):
            raise ValueError(
                "healthy_reward and terminate_when_unhealthy need healthy (the HealthyRanges)"
            )
        if self.smooth_survive is not None:
            if self.healthy is None:
                raise ValueError("smooth_survive needs healthy (the HealthyRanges it smooths)")
            if not isinstance(self.smooth_survive, SmoothHealthy):
                raise ValueError(
                    f"smooth_survive must be a SmoothHealthy or None; got {self.smooth_survive!r}"
                )

    @classmethod
    def hopper(cls, dt: float, **overrides) -> GymLocomotionReward:
        """Hopper-v5's defaults: w_f = 1, w_c = 1e-3, h = 1, gymnasium's healthy ranges,
        terminated when unhealthy; ``overrides`` replace any (as gymnasium's keyword
        arguments do)."""
        settings = dict(
            forward_reward_weight=1.0, ctrl_cost_weight=1e-3, healthy_reward=1.0,
            healthy=HealthyRanges(), terminate_when_unhealthy=True,
        )  # fmt: skip
        return cls(6, 6, 3, dt, **(settings | overrides))

    @classmethod
    def walker2d(cls, dt: float, **overrides) -> GymLocomotionReward:
        """Walker2d-v5's defaults: w_f = 1, w_c = 1e-3, h = 1, healthy when the height q[1] is
        in (0.8, 2.0) m and the pitch q[2] in (-1, 1) rad (no range on the other entries: every
        x[2:] in (-inf, inf), which only a NaN fails), terminated when unhealthy."""
        healthy = HealthyRanges(state=(-np.inf, np.inf), z=(0.8, 2.0), angle=(-1.0, 1.0))
        settings = dict(
            forward_reward_weight=1.0, ctrl_cost_weight=1e-3, healthy_reward=1.0,
            healthy=healthy, terminate_when_unhealthy=True,
        )  # fmt: skip
        return cls(9, 9, 6, dt, **(settings | overrides))

    @classmethod
    def half_cheetah(cls, dt: float, **overrides) -> GymLocomotionReward:
        """HalfCheetah-v5's defaults: w_f = 1, w_c = 0.1, no healthy term, never terminated."""
        settings = dict(forward_reward_weight=1.0, ctrl_cost_weight=0.1)
        return cls(9, 9, 6, dt, **(settings | overrides))

    @property
    def nx(self) -> int:
        return self.nq + self.nv

    def _check(self, x, u, x_next) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x = _batch(x, "x", self.nx, "nx")
        u = _batch(u, "u", self.nu, "nu")
        x_next = _batch(x_next, "x_next", self.nx, "nx")
        if not x.shape[0] == u.shape[0] == x_next.shape[0]:
            raise ValueError(
                f"x, u and x_next must have the same batch size M; got {x.shape[0]}, "
                f"{u.shape[0]}, {x_next.shape[0]}"
            )
        return x, u, x_next

    def is_healthy(self, x) -> np.ndarray:
        """(M,) bool for states x (M, nx): all True without a healthy test."""
        x = _batch(x, "x", self.nx, "nx")
        return np.ones(x.shape[0], bool) if self.healthy is None else self.healthy(x)

    def terms(self, x, u, x_next) -> dict[str, np.ndarray]:
        """The reward's terms under gymnasium's ``info`` names, each (M,): ``x_velocity``
        (m/s), ``reward_forward``, ``reward_ctrl`` (minus the control cost) and, with a healthy
        test, ``reward_survive`` (the smooth term's value with ``smooth_survive``). The reward is
        the sum of the ``reward_*`` terms."""
        x, u, x_next = self._check(x, u, x_next)
        velocity = (x_next[:, 0] - x[:, 0]) / self.dt
        out = {
            "x_velocity": velocity,
            "reward_forward": self.forward_reward_weight * velocity,
            "reward_ctrl": -self.ctrl_cost_weight * np.sum(u * u, axis=1),
        }
        if self.smooth_survive is not None:
            smooth, _ = self.smooth_survive.value_and_gradient(x_next)
            out["reward_survive"] = self.healthy_reward * smooth
        elif self.healthy is not None:
            out["reward_survive"] = self.healthy_reward * self.is_healthy(x_next)
        return out

    def transition(self, x, u, x_next) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(r (M,), dr/dx (M, nx), dr/du (M, nu), dr/dx_next (M, nx)) of the transitions
        (x (M, nx), u (M, nu) actions, x_next (M, nx))."""
        terms = self.terms(x, u, x_next)
        r = sum(value for key, value in terms.items() if key.startswith("reward_"))
        M = r.shape[0]
        dr_dx, dr_dxn = np.zeros((M, self.nx)), np.zeros((M, self.nx))
        dr_dx[:, 0] = -self.forward_reward_weight / self.dt
        dr_dxn[:, 0] = self.forward_reward_weight / self.dt
        dr_du = -2.0 * self.ctrl_cost_weight * np.asarray(u, dtype=float)
        if self.smooth_survive is not None:
            _, ds = self.smooth_survive.value_and_gradient(x_next)
            dr_dxn += self.healthy_reward * ds
        return r, dr_dx, dr_du, dr_dxn

    def terminal(self, x) -> tuple[np.ndarray, np.ndarray]:
        """No terminal reward (gymnasium has none): zeros (M,), (M, nx)."""
        x = _batch(x, "x", self.nx, "nx")
        return np.zeros(x.shape[0]), np.zeros(x.shape)

    def terminated(self, x_next) -> np.ndarray:
        """(M,) bool: the episode ends at x_next (unhealthy, when ``terminate_when_unhealthy``)."""
        healthy = self.is_healthy(x_next)
        return ~healthy if self.terminate_when_unhealthy else np.zeros_like(healthy)


@dataclass(frozen=True)
class ResetNoise:
    """gymnasium v5's reset noise around the initial state: q + U(-s, s) per coordinate, then v
    + U(-s, s) (``velocity="uniform"``, Hopper) or v + s N(0, 1) (``"normal"``, HalfCheetah),
    drawn in that order from the generator, state after state (M states are gymnasium's next M
    resets from the same generator).

    Args:
        scale: s (units of q and v); gymnasium's ``reset_noise_scale``.
        velocity: ``"uniform"`` or ``"normal"``.
        coordinates: None: the state's coordinates are MuJoCo's (qpos, qvel). Else the map to
            them (:class:`~drake_abs.tasks.free_body.FreeBodyCoordinates`, the Ant): the noise
            is drawn on MuJoCo's (qpos, qvel) of x0, as gymnasium draws it, and mapped back
            (a noisy quaternion stays as drawn, off the unit sphere, as in gymnasium; the step
            normalises it, as ``mj_step`` does).
    """

    scale: float
    velocity: Literal["uniform", "normal"] = "uniform"
    coordinates: FreeBodyCoordinates | None = None

    def __post_init__(self):
        if not (np.isfinite(self.scale) and self.scale >= 0):
            raise ValueError(f"scale must be a finite number >= 0; got {self.scale!r}")
        if self.velocity not in ("uniform", "normal"):
            raise ValueError(f"velocity must be 'uniform' or 'normal'; got {self.velocity!r}")

    def sample(self, rng: np.random.Generator, x0, nq: int, M: int) -> np.ndarray:
        """(M, nx) initial states: x0 (nx,) = (q0, v0) plus the noise, with nq = len(q0)."""
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy Generator; got {type(rng).__name__}")
        x0 = as_finite_array(x0, "x0", ndim=(1,))
        M = as_count(M, "M", minimum=0)
        if self.coordinates is not None:
            x0 = self.coordinates.to_mujoco(x0[None])[0]
        nv, s = x0.size - nq, self.scale
        out = np.empty((M, x0.size))
        for m in range(M):
            q = x0[:nq] + rng.uniform(low=-s, high=s, size=nq)
            if self.velocity == "uniform":
                v = x0[nq:] + rng.uniform(low=-s, high=s, size=nv)
            else:
                v = x0[nq:] + s * rng.standard_normal(nv)
            out[m] = np.concatenate([q, v])
        return out if self.coordinates is None else self.coordinates.from_mujoco(out)


@dataclass(frozen=True)
class LocomotionTask:
    """One locomotion task on a scene: everything a batched objective or a gymnasium
    environment (:class:`drake_abs.tasks.gym_env.DrakeAbsEnv`) needs.

    Attributes:
        name: the task's name (``"hopper"``, ``"half_cheetah"`` or your own).
        stepper: one control period of the scene's plant, taking actions in [-1, 1]:
            ``ActionScaled(ZeroOrderHold(plant, substeps), gears)``
            (:class:`~drake_abs.tasks.adapters.ActionScaled`,
            :class:`~drake_abs.engine.steppers.ZeroOrderHold`).
        reward: a transition reward (:class:`GymLocomotionReward`).
        observation: the observation map (:class:`LocomotionObservation`).
        x0: (nx,) the scene's initial state (gymnasium's ``init_qpos``, ``init_qvel``).
        reset_noise: gymnasium's reset noise around x0.
        dt: the control period (s): one action lasts ``dt``, ``substeps`` plant steps.
        env_id: the gymnasium environment this task reproduces (``"Hopper-v5"``), if any.
        report_z: ``info`` has gymnasium Hopper's ``z_distance_from_origin``.
    """

    name: str
    stepper: ActionScaled
    reward: GymLocomotionReward
    observation: LocomotionObservation
    x0: np.ndarray
    reset_noise: ResetNoise
    dt: float
    env_id: str | None = None
    report_z: bool = False

    def __post_init__(self):
        if not isinstance(self.stepper, ActionScaled) or not isinstance(
            self.stepper.stepper, ZeroOrderHold
        ):
            raise ValueError(
                "stepper must be ActionScaled(ZeroOrderHold(plant, substeps), gears); got "
                f"{self.stepper!r}"
            )
        x0 = as_finite_array(self.x0, "x0", ndim=(1,))
        if x0.size != self.observation.nx or self.reward.nx != self.observation.nx:
            raise ValueError(
                f"x0 ({x0.size}), the reward ({self.reward.nx}) and the observation "
                f"({self.observation.nx}) must agree on nx"
            )
        object.__setattr__(self, "x0", x0)

    @property
    def plant(self):
        """The scene's stepper (one plant step of ``dt / substeps``, joint torques as input)."""
        return self.stepper.stepper.stepper

    @property
    def substeps(self) -> int:
        """Plant steps per action."""
        return self.stepper.stepper.substeps

    def with_plant(self, plant) -> LocomotionTask:
        """This task on another plant stepper (same substeps, gears, reward and observation)."""
        hold = ZeroOrderHold(plant, self.substeps)
        return replace(self, stepper=ActionScaled(hold, self.stepper.scale))

    @property
    def nq(self) -> int:
        return self.observation.nq

    @property
    def nx(self) -> int:
        return self.observation.nx

    @property
    def nu(self) -> int:
        return self.reward.nu

    @property
    def n_obs(self) -> int:
        return self.observation.n_obs

    def initial_states(self, rng: np.random.Generator, M: int) -> np.ndarray:
        """(M, nx) initial states with gymnasium's reset noise (gymnasium's next M resets)."""
        return self.reset_noise.sample(rng, self.x0, self.nq, M)

    def policy(self, inner: Policy) -> ObservationPolicy:
        """The full-state policy ``u = inner(obs(x))`` for an inner policy of the observation
        (``inner.nx == n_obs``, ``inner.nu == nu``)."""
        if inner.nu != self.nu:
            raise ValueError(f"inner must output nu = {self.nu} actions; its nu is {inner.nu}")
        return ObservationPolicy(inner, self.observation)

    def objective(
        self, inner: Policy, horizon: int, sigma: float = 0.1, **options
    ) -> PolicyObjective:
        """The batched objective of this task: ``PolicyObjective(stepper, policy(inner),
        reward, x0, horizon, sigma)``, every rollout from x0 (see :meth:`initial_states` for
        gymnasium's noisy starts). ``sigma`` is in units of the action; ``options`` (e.g.
        ``on_unconverged``) go to :class:`~drake_abs.policy.estimators.PolicyObjective`."""
        return PolicyObjective(
            self.stepper, self.policy(inner), self.reward, self.x0, horizon, sigma, **options
        )

    def reset_info(self, x) -> dict[str, np.ndarray]:
        """gymnasium's ``info`` at states x (M, nx), each (M,): ``x_position`` (m) and, for the
        Hopper, ``z_distance_from_origin`` (m, the height above the initial state's): the keys
        of gymnasium's reset ``info``, no more (the step's ``info`` adds ours:
        :func:`drake_abs.tasks.gym_env.step_task`)."""
        x = _batch(x, "x", self.nx, "nx")
        if hasattr(self.reward, "position_info"):  # the Ant: x, y and distance
            return self.reward.position_info(x)
        out = {"x_position": x[:, 0]}
        if self.report_z:
            out["z_distance_from_origin"] = x[:, 1] - self.x0[1]
        return out

    def info(self, x, u, x_next, step=None) -> dict[str, np.ndarray]:
        """gymnasium's ``info`` of a batch of steps, each (M,): :meth:`reset_info` of x_next
        and the reward's terms (:meth:`GymLocomotionReward.terms`; given the ``step``, a
        reward that reads it, the Ant's, adds its contact term)."""
        extra = {"step": step} if step is not None and getattr(self.reward, "uses_step", False) \
            else {}  # fmt: skip
        return self.reset_info(x_next) | self.reward.terms(x, u, x_next, **extra)


@dataclass(frozen=True)
class _TaskSpec:
    scene: str
    env_id: str
    reward: str  # the GymLocomotionReward constructor
    velocity_clip: float | None
    reset_noise: ResetNoise
    report_z: bool
    control_period: float  # gymnasium's: frame_skip x the model file's timestep (s)
    #: the scene's ``compliance`` entry for MuJoCo's soft contact (``contact="mujoco"``)
    soft_contact: tuple = (("kind", "mujoco"), ("from_model", True))


#: The tasks :func:`locomotion_task` builds, by name: scene, gymnasium id, v5 settings.
TASKS: dict[str, _TaskSpec] = {
    "hopper": _TaskSpec(
        "gym_hopper", "Hopper-v5", "hopper", 10.0, ResetNoise(5e-3), True, 4 * 0.002
    ),
    "half_cheetah": _TaskSpec(
        "gym_half_cheetah",
        "HalfCheetah-v5",
        "half_cheetah",
        None,
        ResetNoise(0.1, "normal"),
        False,
        5 * 0.01,
    ),  # fmt: skip
    "walker2d": _TaskSpec(
        "gym_walker2d", "Walker2d-v5", "walker2d", 10.0, ResetNoise(5e-3), True, 4 * 0.002
    ),
    # the Ant's reward, observation and info are drake_abs.tasks.ant's (velocity_clip unused)
    "ant": _TaskSpec(
        "gym_ant",
        "Ant-v5",
        "ant",
        None,
        ResetNoise(0.1, "normal", FreeBodyCoordinates(8)),
        False,
        5 * 0.01,
        # the file sets no solref or solimp (MuJoCo's defaults, this option's too); the
        # scene's radii hold its 0.01 m margin already (scenes/gym_ant.yaml), and Drake's
        # names of its unnamed bodies cannot be looked up in the file (from_model)
        (("kind", "mujoco"), ("margin", 0.0)),
    ),  # fmt: skip
}

#: The contact laws :func:`locomotion_task` offers.
CONTACT_LAWS = ("hard", "mujoco")


#: The settings of the scene's stepper that :func:`locomotion_task` passes on
#: (:meth:`drake_abs.multibody.builder.SceneModel.stepper`), besides the solver's options.
STEPPER_SETTINGS = ("activation_distance", "gradient", "friction")


def locomotion_task(
    name: Literal["hopper", "half_cheetah", "walker2d", "ant"],
    *,
    smoothing=None,
    reward_options=None,
    control_period: float | None = None,
    substeps: int | None = None,
    contact: Literal["hard", "mujoco"] = "hard",
    **stepper,
) -> LocomotionTask:
    """gymnasium's ``Hopper-v5``, ``HalfCheetah-v5``, ``Walker2d-v5`` or ``Ant-v5`` on our
    plant (builds the scene; needs Drake).

    Args:
        name: ``"hopper"``, ``"half_cheetah"``, ``"walker2d"`` or ``"ant"``
            (:mod:`drake_abs.tasks.ant`).
        smoothing: the contact smoothing (default: the scene's, exact contact), used as given at
            the plant's step ``control_period / substeps``.
        reward_options: replace gymnasium's reward settings (``ctrl_cost_weight``,
            ``smooth_survive``, ...; see :class:`GymLocomotionReward`).
        control_period: seconds per action (default gymnasium's: 8 ms Hopper and Walker2d,
            50 ms HalfCheetah and Ant).
        substeps: plant steps per action (default: the fewest that keep the plant's step at or
            below the scene's ``time_step``). More substeps: more accurate, slower.
        contact: ``"hard"`` (the scene's complementarity contact) or ``"mujoco"``: MuJoCo's
            soft contact from the model file's solref, solimp and margins, as a regularised
            complementarity problem (the scene's ``compliance: {kind: mujoco, from_model:
            true}``; see :mod:`drake_abs.contact.compliance`). Smoothing applies on top.
        stepper: other settings of the scene's stepper
            (:meth:`drake_abs.multibody.builder.SceneModel.stepper`).
    """
    if name not in TASKS:
        raise ValueError(f"name must be one of {sorted(TASKS)}; got {name!r}")
    from drake_abs.multibody.builder import shared_scene_model  # Drake, only when building
    from drake_abs.multibody.scene import Scene
    from drake_abs.multibody.stepper import SOLVER_OPTIONS

    # refused here, before the scene is built (and not at the first step)
    unknown = sorted(set(stepper) - set(STEPPER_SETTINGS) - set(SOLVER_OPTIONS))
    if unknown:
        raise ValueError(
            f"unknown option(s) {unknown} of locomotion_task({name!r}): it takes smoothing, "
            "reward_options, control_period, substeps, contact and the stepper's "
            f"{', '.join(STEPPER_SETTINGS + SOLVER_OPTIONS)}"
        )

    if contact not in CONTACT_LAWS:
        raise ValueError(f"contact must be one of {list(CONTACT_LAWS)}; got {contact!r}")
    spec = TASKS[name]
    scene = Scene.load(spec.scene)
    if contact == "mujoco":
        scene = Scene.from_dict({**scene.to_dict(), "compliance": dict(spec.soft_contact)})
    dt = spec.control_period if control_period is None else control_period
    real = isinstance(dt, int | float | np.integer | np.floating) and not isinstance(dt, bool)
    if not (real and np.isfinite(dt) and dt > 0):
        raise ValueError(f"control_period must be a finite number > 0 (s); got {dt!r}")
    dt = float(dt)
    if substeps is None:
        substeps = max(1, int(np.ceil(dt / scene.time_step - 1e-9)))
    substeps = as_count(substeps, "substeps", minimum=1)
    # built once per process and scene: a run makes a task per method, seed and scoring, and
    # each would parse the model file again (and repeat Drake's parser warnings)
    model = shared_scene_model(replace(scene, time_step=dt / substeps))
    gears = np.array([a["gear"] for a in model.model_report()["actuators"]], dtype=float)
    inner = model.stepper(smoothing=smoothing, **stepper)
    nq, nv, nu = inner.sizes[:3]
    if spec.reward == "ant":
        from drake_abs.tasks.ant import ContactWrenches  # Drake's plant, only when building

        instance = model.plant.GetBodyByName("torso").model_instance()
        bodies = ["world"] + [model.plant.get_body(i).name()
                              for i in model.plant.GetBodyIndices(instance)]  # fmt: skip
        reward = AntReward(dt, ContactWrenches(model, bodies), **(reward_options or {}))
        observation = AntObservation(nu)
    else:
        reward = getattr(GymLocomotionReward, spec.reward)(dt, **(reward_options or {}))
        observation = LocomotionObservation(nq, nv, spec.velocity_clip)
    if (nq, nv, nu) != (reward.nq, reward.nv, reward.nu):
        raise RuntimeError(f"scene {spec.scene!r} has sizes {(nq, nv, nu)}, not gymnasium's")
    return LocomotionTask(
        name=name, stepper=ActionScaled(ZeroOrderHold(inner, substeps), gears), reward=reward,
        observation=observation, x0=model.x0,
        reset_noise=spec.reset_noise, dt=dt, env_id=spec.env_id, report_z=spec.report_z,
    )  # fmt: skip
