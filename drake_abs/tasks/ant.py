"""gymnasium's Ant-v5 on our plant (scene ``gym_ant``): its observation, its reward (forward
velocity, control cost, contact cost, healthy reward), its healthy test, and MuJoCo's external
contact wrenches per body (``cfrc_ext``) reproduced from our step's contact impulses.

State x = (q, v) in our coordinates (q = (qw, qx, qy, qz, x, y, z, 8 joints), v = (w_W, v_W, 8
joint rates); :class:`~drake_abs.tasks.free_body.FreeBodyCoordinates` maps them to MuJoCo's qpos
and qvel). Actions: the 8 motors' ctrl in [-1, 1] (gear 150), in the file's actuator order.

Reward of a transition (x_t, a_t, x_{t+1}) with gymnasium v5's defaults (``ant_v5.py``)::

    r_t = w_f (x_{t+1} - x_t) / dt - w_c |a_t|^2 - w_k |clip(F_{t+1}, -1, 1)|^2 + h healthy(x_{t+1})

w_f = 1, w_c = 0.5, w_k = 5e-4, h = 1; x is the torso's x position (m), F the 13 x 6 external
wrenches of the step (below). Healthy (``is_healthy``, closed interval): qpos and qvel finite and
the torso's height z in [0.2, 1.0] m; unhealthy ends the episode.

- **Forward velocity.** gymnasium differences the torso's ``xpos``, which after ``mj_step`` is
  the body position at the start of the last physics step of the frame skip (one 10 ms step
  behind qpos); we difference the state's position over the control period. Per step the two
  differ by the change of one physics step's displacement; over an episode they telescope to
  the same distance but for one physics step at each end.
- **Contact wrenches** (:class:`ContactWrenches`): MuJoCo's ``cfrc_ext`` holds, per body, the
  contact force the ground exerts on it as a spatial force ``(torque, force)`` in world
  orientation, the torque taken about the centre of mass of the body's whole tree (the Ant's
  centre of mass). We form it from the step's impulses: each contact candidate's impulse
  ``lambda_n n + lambda_t`` (N s, normal and friction) divided by the control period is a force
  at the candidate's ground point (its sphere's centre less its radius along the normal) at the
  state after the step. ZeroOrderHold sums the impulses over its substeps, so this is the
  period's mean force; MuJoCo's is the force of the last physics step, soft (it pushes through
  a penetration); ours is hard. How close they come is measured in
  ``tests/tasks/test_locomotion_walker_ant.py``.
- **No derivative of the contact cost.** The step's impulse Jacobians are not chained through
  the task's substeps (None when substeps > 1) and the friction impulses have none; the contact
  cost enters the reward's value and not its derivatives (``dr/dx``, ``dr/du`` leave it out).
  With gymnasium's clip at +-1 N (N m) most entries saturate while in contact (the Ant weighs
  8.9 N), where its derivative is zero anyway.

Observation (:class:`AntObservation`): gymnasium's ``qpos[2:]`` and ``qvel`` (27 values; x and y
left out), a function of the state. gymnasium's default observation also carries the clipped
``cfrc_ext`` (78 more), which is not a function of the state but of the last step; a policy of
the state cannot see it. The task's observation is therefore gymnasium's
``include_cfrc_ext_in_observation=False`` layout, and a policy trained on it runs in Ant-v5 at its
defaults as the policy with zero weights on the 78 contact entries;
:meth:`AntObservation.with_contact_forces` forms gymnasium's 105-value vector from a step's
wrenches, for comparisons.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs._validation import as_count
from drake_abs.tasks.free_body import FreeBodyCoordinates

__all__ = ["AntObservation", "AntReward", "ContactWrenches"]


def _batch(value, name: str, size: int, what: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != size:
        raise ValueError(f"{name} must have shape (M, {what}) = (M, {size}); got {arr.shape}")
    return arr


@dataclass(frozen=True)
class AntObservation:
    """gymnasium Ant-v5's observation of the state, ``(qpos[skip:], qvel)`` in MuJoCo's
    coordinates, with its Jacobian (an :class:`~drake_abs.tasks.adapters.Observation`).

    Args:
        joints: one-dof joints after the free one (8 for the Ant).
        skip: leading qpos entries left out (2: x and y, gymnasium's
            ``exclude_current_positions_from_observation=True``).
    """

    joints: int = 8
    skip: int = 2

    def __post_init__(self):
        as_count(self.joints, "joints", minimum=0)
        if not 0 <= self.skip <= 7 + self.joints:
            raise ValueError(f"skip must be in 0 .. nq = {7 + self.joints}; got {self.skip!r}")

    @property
    def coordinates(self) -> FreeBodyCoordinates:
        return FreeBodyCoordinates(self.joints)

    @property
    def nq(self) -> int:
        return 7 + self.joints

    @property
    def nx(self) -> int:
        return 13 + 2 * self.joints

    @property
    def n_obs(self) -> int:
        return self.nx - self.skip

    def __call__(self, x) -> np.ndarray:
        """o (M, n_obs) of states x (M, nx)."""
        x = _batch(x, "x", self.nx, "nx")
        return self.coordinates.to_mujoco(x)[:, self.skip :]

    def jacobian(self, x) -> np.ndarray:
        """do/dx (M, n_obs, nx)."""
        x = _batch(x, "x", self.nx, "nx")
        return self.coordinates.jacobian(x)[:, self.skip :]

    def vjp(self, x, g_o) -> np.ndarray:
        """g_o do/dx (M, nx) for g_o (M, n_obs)."""
        g_o = _batch(g_o, "g_o", self.n_obs, "n_obs")
        return np.einsum("bo,box->bx", g_o, self.jacobian(x))

    def with_contact_forces(self, x, wrenches, force_range=(-1.0, 1.0)) -> np.ndarray:
        """gymnasium's default observation (M, n_obs + 6 nb): :meth:`__call__` of x (M, nx)
        followed by ``wrenches`` (M, nb, 6) (:class:`ContactWrenches`, the bodies but the
        world's) clipped to ``force_range``, flattened body by body."""
        wrenches = np.asarray(wrenches, dtype=float)
        if wrenches.ndim != 3 or wrenches.shape[2] != 6:
            raise ValueError(f"wrenches must have shape (M, nb, 6); got {wrenches.shape}")
        lo, hi = force_range
        flat = np.clip(wrenches, lo, hi).reshape(wrenches.shape[0], -1)
        return np.concatenate([self(x), flat], axis=1)


class ContactWrenches:
    """MuJoCo's ``cfrc_ext`` (bodies 1 .. nb, world left out) of our steps: per body, the
    spatial force ``(torque, force)`` (N m, N) the ground exerts on it, in world orientation,
    the torque about the centre of mass of all the model's bodies (MuJoCo's ``subtree_com`` of
    the tree's root; the module docstring says how it is formed from the step's impulses).

    Args:
        scene_model: the scene's :class:`~drake_abs.multibody.builder.SceneModel` (its plant,
            its point contact candidates and ground normal); pickled as its scene, rebuilt on
            loading.
        bodies: MuJoCo's body names in body-id order, world first (MuJoCo names an unnamed body
            ``None`` or ``""``; Drake names it ``body<id>``).
    """

    def __init__(self, scene_model, bodies):
        contact_model = scene_model.contact_model
        self._source = (scene_model.scene, tuple(bodies))
        self.plant = contact_model.plant
        self.normal = np.asarray(contact_model.normal, dtype=float)
        self.contacts = list(contact_model.contacts)
        names = [n if n else f"body{i}" for i, n in enumerate(bodies)]
        self.n_bodies = len(names) - 1
        self._context = self.plant.CreateDefaultContext()
        self._instances = sorted(
            {self.plant.GetBodyByName(n).model_instance() for n in names[1:]}, key=int
        )
        self._column = np.empty(len(self.contacts), dtype=np.int64)
        self._frames = []
        for i, c in enumerate(self.contacts):
            if not hasattr(c, "p_BC"):
                raise ValueError("contact_model must have point contacts against the ground only")
            if c.body not in names[1:]:
                raise ValueError(f"contact body {c.body!r} is not one of bodies {names[1:]}")
            self._column[i] = names.index(c.body) - 1
            self._frames.append(self.plant.GetBodyByName(c.body).body_frame())

    def __reduce__(self):
        return (_rebuilt_wrenches, self._source)

    def points_and_com(self, q) -> tuple[np.ndarray, np.ndarray]:
        """(contact points' ground points (nc, 3) in the world, centre of mass (3,)) at one
        configuration q (nq,) (m). The ground point is the sphere's lowest point along the
        normal; its frame offset is fixed in the body (the radius along the world normal is
        subtracted from the body's point after placing it)."""
        plant, ctx = self.plant, self._context
        plant.SetPositions(ctx, np.asarray(q, dtype=float))
        world = plant.world_frame()
        p = np.empty((len(self.contacts), 3))
        for i, (c, frame) in enumerate(zip(self.contacts, self._frames, strict=True)):
            p[i] = plant.CalcPointsPositions(ctx, frame, np.asarray(c.p_BC, float), world)[:, 0]
            p[i] -= c.radius * self.normal
        com = plant.CalcCenterOfMassPositionInWorld(ctx, self._instances)
        return p, np.asarray(com).ravel()

    def __call__(self, x_next, impulse, friction_impulse, dt: float) -> np.ndarray:
        """Wrenches (M, nb, 6) of a batch of steps: states after the steps x_next (M, nx),
        normal impulses (M, nc) and friction impulses (M, nc, 3) (N s; ``Step.impulse``,
        ``Step.friction_impulse``), over the period dt (s)."""
        x_next = np.asarray(x_next, dtype=float)
        impulse = np.asarray(impulse, dtype=float)
        nc = len(self.contacts)
        M = x_next.shape[0]
        if impulse.shape != (M, nc):
            raise ValueError(f"impulse must have shape (M, nc) = ({M}, {nc}); got {impulse.shape}")
        if friction_impulse is None:
            friction_impulse = np.zeros((M, nc, 3))
        friction_impulse = np.asarray(friction_impulse, dtype=float)
        if friction_impulse.shape != (M, nc, 3):
            raise ValueError(
                f"friction_impulse must have shape (M, nc, 3) = ({M}, {nc}, 3); got "
                f"{friction_impulse.shape}"
            )
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a finite period > 0 (s); got {dt!r}")
        nq = self.plant.num_positions()
        out = np.zeros((M, self.n_bodies, 6))
        force = (impulse[:, :, None] * self.normal + friction_impulse) / dt  # (M, nc, 3)
        for m in range(M):
            touching = np.flatnonzero(np.any(force[m] != 0.0, axis=1))
            if touching.size == 0:
                continue
            p, com = self.points_and_com(x_next[m, :nq])
            f = force[m, touching]
            torque = np.cross(p[touching] - com, f)
            np.add.at(out[m], (self._column[touching], slice(0, 3)), torque)
            np.add.at(out[m], (self._column[touching], slice(3, 6)), f)
        return out


def _rebuilt_wrenches(scene, bodies) -> ContactWrenches:
    """A :class:`ContactWrenches` rebuilt from its scene (unpickling; needs Drake)."""
    from drake_abs.multibody.builder import shared_scene_model  # Drake, only when rebuilding

    return ContactWrenches(shared_scene_model(scene), bodies)


@dataclass(frozen=True)
class AntReward:
    """gymnasium Ant-v5's reward of a transition (module docstring), batched, with the
    derivatives of its smooth terms (a :class:`~drake_abs.engine.protocols.TransitionReward`
    that also reads the step: ``uses_step = True``, the engine passes ``step=``).

    Args:
        dt: the control period (s).
        contact_wrenches: forms the contact cost's wrenches from a step (None: no contact cost,
            as ``contact_cost_weight = 0``).
        forward_reward_weight, ctrl_cost_weight, contact_cost_weight, healthy_reward: gymnasium's
            weights (defaults: v5's).
        healthy_z_range: the torso height's healthy range (m), closed.
        contact_force_range: the clip of each wrench entry in the contact cost.
        terminate_when_unhealthy: ``terminated`` where x_next is unhealthy.
        joints: one-dof joints after the free one (8).
    """

    dt: float
    contact_wrenches: ContactWrenches | None = None
    forward_reward_weight: float = 1.0
    ctrl_cost_weight: float = 0.5
    contact_cost_weight: float = 5e-4
    healthy_reward: float = 1.0
    healthy_z_range: tuple[float, float] = (0.2, 1.0)
    contact_force_range: tuple[float, float] = (-1.0, 1.0)
    terminate_when_unhealthy: bool = True
    joints: int = 8
    uses_step = True

    def __post_init__(self):
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a finite time step > 0 (s); got {self.dt!r}")
        for name in ("forward_reward_weight", "ctrl_cost_weight", "contact_cost_weight",
                     "healthy_reward"):  # fmt: skip
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite; got {getattr(self, name)!r}")
        for name in ("healthy_z_range", "contact_force_range"):
            lo, hi = getattr(self, name)
            if not lo <= hi:
                raise ValueError(f"{name} must be (low, high) with low <= high; got {(lo, hi)}")

    @property
    def nq(self) -> int:
        return 7 + self.joints

    @property
    def nv(self) -> int:
        return 6 + self.joints

    @property
    def nx(self) -> int:
        return self.nq + self.nv

    @property
    def nu(self) -> int:
        return self.joints

    def _check(self, x, u, x_next):
        x = _batch(x, "x", self.nx, "nx")
        u = _batch(u, "u", self.nu, "nu")
        x_next = _batch(x_next, "x_next", self.nx, "nx")
        if not x.shape[0] == u.shape[0] == x_next.shape[0]:
            raise ValueError("x, u and x_next must have the same batch size M")
        return x, u, x_next

    def is_healthy(self, x) -> np.ndarray:
        """(M,) bool: state finite and the torso's height q[6] in ``healthy_z_range``."""
        x = _batch(x, "x", self.nx, "nx")
        lo, hi = self.healthy_z_range
        z = x[:, 6]
        return np.all(np.isfinite(x), axis=1) & (lo <= z) & (z <= hi)

    def terminated(self, x_next) -> np.ndarray:
        healthy = self.is_healthy(x_next)
        return ~healthy if self.terminate_when_unhealthy else np.zeros_like(healthy)

    def wrenches(self, x_next, step) -> np.ndarray:
        """The step's contact wrenches (M, nb, 6) (:class:`ContactWrenches`)."""
        if self.contact_wrenches is None:
            raise ValueError("this reward has no contact_wrenches (no contact cost)")
        return self.contact_wrenches(x_next, step.impulse, step.friction_impulse, self.dt)

    def contact_cost(self, wrenches) -> np.ndarray:
        """``w_k |clip(F)|^2`` (M,) of wrenches (M, nb, 6)."""
        lo, hi = self.contact_force_range
        F = np.clip(np.asarray(wrenches, dtype=float), lo, hi)
        return self.contact_cost_weight * np.sum(F * F, axis=(1, 2))

    def terms(self, x, u, x_next, step=None) -> dict[str, np.ndarray]:
        """gymnasium's ``info`` terms, each (M,): ``x_velocity``, ``y_velocity`` (m/s),
        ``reward_forward``, ``reward_ctrl``, ``reward_survive`` and, given the ``step`` (and
        a contact cost), ``reward_contact``. The reward is the sum of the ``reward_*`` terms."""
        x, u, x_next = self._check(x, u, x_next)
        vx = (x_next[:, 4] - x[:, 4]) / self.dt
        vy = (x_next[:, 5] - x[:, 5]) / self.dt
        out = {
            "x_velocity": vx,
            "y_velocity": vy,
            "reward_forward": self.forward_reward_weight * vx,
            "reward_ctrl": -self.ctrl_cost_weight * np.sum(u * u, axis=1),
            "reward_survive": self.healthy_reward * self.is_healthy(x_next),
        }
        if step is not None and self.contact_wrenches is not None:
            out["reward_contact"] = -self.contact_cost(self.wrenches(x_next, step))
        return out

    def transition(self, x, u, x_next, step=None):
        """(r (M,), dr/dx (M, nx), dr/du (M, nu), dr/dx_next (M, nx)); ``step`` (the
        :class:`~drake_abs.contact.step.Step` from x under u) is needed when the reward has a
        contact cost, which has no derivative here (module docstring)."""
        if step is None and self.contact_wrenches is not None:
            raise ValueError(
                "step must be given: the contact cost is formed from the step's impulses"
            )
        terms = self.terms(x, u, x_next, step)
        r = sum(value for key, value in terms.items() if key.startswith("reward_"))
        M = r.shape[0]
        dr_dx, dr_dxn = np.zeros((M, self.nx)), np.zeros((M, self.nx))
        dr_dx[:, 4] = -self.forward_reward_weight / self.dt
        dr_dxn[:, 4] = self.forward_reward_weight / self.dt
        dr_du = -2.0 * self.ctrl_cost_weight * np.asarray(u, dtype=float)
        return r, dr_dx, dr_du, dr_dxn

    def terminal(self, x) -> tuple[np.ndarray, np.ndarray]:
        """No terminal reward: zeros (M,), (M, nx)."""
        x = _batch(x, "x", self.nx, "nx")
        return np.zeros(x.shape[0]), np.zeros(x.shape)

    def position_info(self, x) -> dict[str, np.ndarray]:
        """gymnasium's position ``info`` at states x (M, nx), each (M,): ``x_position``,
        ``y_position``, ``distance_from_origin`` (m)."""
        x = _batch(x, "x", self.nx, "nx")
        return {
            "x_position": x[:, 4],
            "y_position": x[:, 5],
            "distance_from_origin": np.hypot(x[:, 4], x[:, 5]),
        }
