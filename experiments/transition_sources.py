"""Transition data that no one here wrote: rollouts of our scenes (``box_push``, ``gym_hopper``,
``gym_half_cheetah``) simulated by Drake's own MultibodyPlant (SAP, or Similar / Lagged) and by
MuJoCo, recorded as :class:`~drake_abs.learning.transitions.Transitions` in our scenes' state
coordinates and input units, so that our complementarity model's parameters can be fitted to
them and its prediction errors measured.

Sources (every one seeded: the same arguments give identical arrays):

- :func:`sap_transitions`: the scene's Drake twin (``make_drake_twin`` of
  ``drake_abs/reference/drake_twin.py``: the same model files in a discrete MultibodyPlant at
  the scene's time step, compliant point contact through a collision sphere at each declared
  contact point; a point contact of radius 0 becomes a 1 mm sphere, whose surface lies 1 mm below
  the point). Its state is
  checked to be ours entry by entry (the same position and velocity names in the same order,
  :func:`check_drake_coordinates`). One step = Drake's discrete update of the diagram.
- :func:`mujoco_transitions`: ``gym_hopper`` and ``gym_half_cheetah`` in gymnasium's
  ``Hopper-v5`` / ``HalfCheetah-v5`` (as published: soft contact on the capsules, the Hopper RK4
  at 2 ms, the HalfCheetah Euler at 10 ms with its joint springs, which our scene drops), with
  ``frame_skip`` such that one environment step is one step of our scene
  (:func:`~drake_abs.experiments.locomotion_transfer.same_period_frame_skip`: 5 and 1); our
  x = (qpos, qvel), checked joint by joint (:func:`check_mujoco_coordinates`); an episode ends
  where the environment says ``terminated`` (the Hopper's healthy test; its options through
  ``env_options``) or after ``steps``. ``box_push`` in ``drake_abs/models/box_planar.xml`` (the
  box of the SDF with the scene's contact points as 1 mm spheres over a floor lowered by their
  radius, friction 0.5, pyramidal cone, Euler at 0.01 s), stepped with the mujoco API directly.

Initial states: the scene's x0 (or ``initial_state``) plus seeded noise: for the locomotion
scenes gymnasium's reset noise (:data:`drake_abs.tasks.locomotion.TASKS`), drawn from
``default_rng(episode seed)`` exactly as ``env.reset(seed=episode seed)`` draws it, so Drake and
MuJoCo episodes of one seed start from the same states; for the box a random position offset,
tilt (lifted so that no corner starts below the ground) and velocity.

Inputs: the scene's units (the stepper's u: N for the box's push, joint torques N m for the
locomotion scenes, MuJoCo's ``ctrl`` times the gear), clipped to the actuators' effort limits
before they are applied and recorded as applied. A policy is a callable ``policy(x, t) -> u``
(x our state (nx,), t the step within the episode), optionally with ``reset(seed)`` called at
each episode's start with the episode's seed: :func:`random_policy`, :func:`scripted_policy`
(a push profile for the box, a sinusoidal gait with seeded phases for the others) and
:func:`feedback_policy` (any x -> u map, e.g. a trained linear policy).

``contact`` of each transition: whether the source had contact at x or at x_next (Drake: a
penetrating point pair in its contact results; MuJoCo: ``ncon > 0``, its contacts within the
geoms' margins, self-contacts included). :func:`prediction_errors` measures our exact model's
one-step predictions on a data set, split by that flag.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from drake_abs.learning.transitions import Transitions, error_summary, one_step_predictions

SCENES = ("box_push", "gym_hopper", "gym_half_cheetah")
#: Our locomotion scenes' gymnasium environments.
MUJOCO_ENVS = {"gym_hopper": "Hopper-v5", "gym_half_cheetah": "HalfCheetah-v5"}
#: The box's MuJoCo model (the SDF's box, the scene's contact points).
BOX_MJCF = "models/box_planar.xml"
#: The box's initial-state noise, as half-widths of the position offset (m), the tilt (rad),
#: the lift (m) and the velocity (m/s, m/s, rad/s).
BOX_NOISE = {"x": 0.1, "pitch": 0.1, "lift": 0.02, "v": (0.5, 0.2, 1.0)}
BOX_HALF = (0.2, 0.1)  # half length and half height (m), the contact points' offsets

Policy = Callable[[np.ndarray, int], np.ndarray]


# ---------------------------------------------------------------------------------- scenes


@functools.cache
def scene_model(scene_name: str):
    """The scene's :class:`~drake_abs.multibody.builder.SceneModel` (built once per process)."""
    from drake_abs.multibody import build_scene_model

    if scene_name not in SCENES:
        raise ValueError(f"scene_name must be one of {SCENES}; got {scene_name!r}")
    return build_scene_model(scene_name)


@functools.cache
def exact_stepper(scene_name: str):
    """Our scene's own stepper (its exact contact, joint limits, damping, effort limits)."""
    return scene_model(scene_name).stepper()


def control_range(scene_name: str) -> tuple[np.ndarray, np.ndarray]:
    """(low, high), each (nu,): the actuators' effort limits (N or N m) of the scene."""
    effort = np.asarray(exact_stepper(scene_name).effort, float)
    return -effort, effort.copy()


def episode_seed(seed: int, episode: int) -> int:
    """The seed of episode ``episode`` of a source seeded ``seed`` (a 32-bit integer, for
    ``env.reset(seed=...)``, the initial-state noise and the policy's ``reset``)."""
    return int(np.random.SeedSequence([int(seed), int(episode)]).generate_state(1)[0])


def initial_state(scene_name: str, ep_seed: int, base=None, noise: bool = True) -> np.ndarray:
    """An episode's initial state: ``base`` (default the scene's x0) plus the scene's noise,
    drawn from ``default_rng(ep_seed)`` (for the locomotion scenes gymnasium's reset noise, as
    ``env.reset(seed=ep_seed)`` draws it)."""
    model = scene_model(scene_name)
    x = np.array(model.x0 if base is None else base, dtype=float)
    if x.shape != model.x0.shape or not np.all(np.isfinite(x)):
        raise ValueError(f"initial_state must be finite with shape {model.x0.shape}; got {x.shape}")
    if not noise:
        return x
    rng = np.random.default_rng(ep_seed)
    nq = model.contact_model.nq
    if scene_name == "box_push":
        pitch = x[2] + rng.uniform(-BOX_NOISE["pitch"], BOX_NOISE["pitch"])
        # lift so that the lowest corner is where it was before the tilt, then a random gap
        lift = (BOX_HALF[0] * abs(np.sin(pitch)) + BOX_HALF[1] * np.cos(pitch)) - BOX_HALF[1]
        x[0] += rng.uniform(-BOX_NOISE["x"], BOX_NOISE["x"])
        x[1] += lift + rng.uniform(0.0, BOX_NOISE["lift"])
        x[2] = pitch
        x[nq:] += rng.uniform(-1.0, 1.0, 3) * np.asarray(BOX_NOISE["v"])
        return x
    from drake_abs.tasks.locomotion import TASKS

    spec = next(t for t in TASKS.values() if t.scene == scene_name)
    return spec.reset_noise.sample(rng, x, nq, 1)[0]


# -------------------------------------------------------------------------------- policies


@dataclass
class RandomPolicy:
    """u uniform in [low, high] (nu,), a new sample each step; seeded (``seed``, and the episode
    seed given to ``reset``)."""

    nu: int
    low: np.ndarray
    high: np.ndarray
    seed: int
    _rng: np.random.Generator = field(init=False, repr=False)

    def __post_init__(self):
        self.low = np.broadcast_to(np.asarray(self.low, float), (self.nu,)).copy()
        self.high = np.broadcast_to(np.asarray(self.high, float), (self.nu,)).copy()
        if not (np.all(np.isfinite(self.low)) and np.all(np.isfinite(self.high))):
            raise ValueError("low and high must be finite (a control range)")
        if np.any(self.low > self.high):
            raise ValueError(f"low must be <= high; got low {self.low}, high {self.high}")
        self.reset(None)

    def reset(self, seed: int | None) -> None:
        key = [int(self.seed)] if seed is None else [int(self.seed), int(seed)]
        self._rng = np.random.default_rng(key)

    def __call__(self, x, t: int) -> np.ndarray:
        return self._rng.uniform(self.low, self.high)


def random_policy(nu: int, low, high, seed: int) -> RandomPolicy:
    """Uniform random inputs in [low, high] (scalars or (nu,)), a new sample each step."""
    return RandomPolicy(int(nu), low, high, int(seed))


@dataclass
class SinusoidGait:
    """u_j = offset_j + amplitude_j sin(2 pi frequency t time_step + phase_j), the phases drawn
    uniform in [0, 2 pi) per episode from (``seed``, episode seed)."""

    amplitude: np.ndarray
    frequency: float
    time_step: float
    seed: int
    offset: np.ndarray | float = 0.0
    phases: np.ndarray = field(init=False)

    def __post_init__(self):
        self.amplitude = np.asarray(self.amplitude, float)
        self.offset = np.broadcast_to(np.asarray(self.offset, float), self.amplitude.shape).copy()
        self.reset(None)

    def reset(self, seed: int | None) -> None:
        key = [int(self.seed)] if seed is None else [int(self.seed), int(seed)]
        self.phases = np.random.default_rng(key).uniform(0.0, 2 * np.pi, self.amplitude.size)

    def __call__(self, x, t: int) -> np.ndarray:
        angle = 2 * np.pi * self.frequency * t * self.time_step + self.phases
        return self.offset + self.amplitude * np.sin(angle)


@dataclass
class PushProfile:
    """A train of pushes: pulse k lasts ``on`` steps with the profile amplitude_k sin^2 (pi s /
    on) (s its step), then ``off`` steps of zero; amplitudes uniform in [-max_push, max_push]
    (N), drawn per episode from (``seed``, episode seed)."""

    max_push: float
    seed: int
    on: int = 30
    off: int = 20
    amplitudes: np.ndarray = field(init=False)

    def __post_init__(self):
        if self.on < 1 or self.off < 0:
            raise ValueError(f"on must be >= 1 and off >= 0 steps; got {self.on}, {self.off}")
        self.reset(None)

    def reset(self, seed: int | None) -> None:
        key = [int(self.seed)] if seed is None else [int(self.seed), int(seed)]
        self.amplitudes = np.random.default_rng(key).uniform(-self.max_push, self.max_push, 64)

    def __call__(self, x, t: int) -> np.ndarray:
        period = self.on + self.off
        k, s = divmod(int(t), period)
        if s >= self.on:
            return np.zeros(1)
        amplitude = self.amplitudes[k % self.amplitudes.size]
        return np.array([amplitude * np.sin(np.pi * s / self.on) ** 2])


def scripted_policy(scene_name: str, seed: int, *, amplitude: float | None = None,
                    frequency: float | None = None) -> Policy:  # fmt: skip
    """A scene's scripted policy: for ``box_push`` a :class:`PushProfile` (pushes of up to
    ``amplitude`` N, default 12: the box slides beyond mu m g = 4.9 N and sticks below it); for
    ``gym_hopper`` / ``gym_half_cheetah`` a :class:`SinusoidGait` at ``frequency`` Hz (default
    2 / 2.5) of ``amplitude`` times each motor's gear (default 0.3 / 0.5), phases seeded."""
    if scene_name == "box_push":
        return PushProfile(12.0 if amplitude is None else float(amplitude), int(seed))
    if scene_name not in MUJOCO_ENVS:
        raise ValueError(f"scene_name must be one of {SCENES}; got {scene_name!r}")
    hopper = scene_name == "gym_hopper"
    _, high = control_range(scene_name)
    share = (0.3 if hopper else 0.5) if amplitude is None else float(amplitude)
    freq = (2.0 if hopper else 2.5) if frequency is None else float(frequency)
    return SinusoidGait(share * high, freq, scene_model(scene_name).scene.time_step, int(seed))


@dataclass
class FeedbackPolicy:
    """u = clip(scale * act(x), low, high): a state-feedback policy (e.g. a trained linear
    policy; deterministic, so no seeding)."""

    act: Callable[[np.ndarray], np.ndarray]
    scale: np.ndarray | float = 1.0
    low: np.ndarray | float | None = None
    high: np.ndarray | float | None = None

    def __call__(self, x, t: int) -> np.ndarray:
        u = np.asarray(self.scale, float) * np.asarray(self.act(np.asarray(x, float)), float)
        lo = -np.inf if self.low is None else self.low
        hi = np.inf if self.high is None else self.high
        return np.clip(u, lo, hi)


def feedback_policy(act: Callable[[np.ndarray], np.ndarray], *, scale=1.0, low=None,
                    high=None) -> FeedbackPolicy:  # fmt: skip
    """A policy of the state: ``act(x) -> a`` (x our state (nx,)), u = scale * a, clipped to
    [low, high]. For a policy trained on actions in [-1, 1] (gymnasium's ``ctrl``, a
    :class:`~drake_abs.tasks.locomotion.LocomotionTask`'s), ``scale`` = the motors' gears
    (:func:`control_range`'s high); e.g. a :class:`~drake_abs.policy.policies.LinearPolicy` of
    the full state with parameters theta: ``feedback_policy(lambda x: policy.act(theta,
    x[None])[0], scale=gears)``."""
    return FeedbackPolicy(act, scale, low, high)


def _reset(policy, ep_seed: int) -> None:
    reset = getattr(policy, "reset", None)
    if callable(reset):
        reset(ep_seed)


def _act(policy, x: np.ndarray, t: int, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    u = np.asarray(policy(x.copy(), t), dtype=float).reshape(-1)
    if u.shape != low.shape or not np.all(np.isfinite(u)):
        raise ValueError(f"the policy must return a finite u of shape {low.shape}; got {u}")
    return np.clip(u, low, high)


def _check_sizes(episodes, steps) -> tuple[int, int]:
    for name, value in (("episodes", episodes), ("steps", steps)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} must be an integer >= 1; got {value!r}")
    return int(episodes), int(steps)


class _Recorder:
    """Rows of one source, episode after episode."""

    def __init__(self):
        self.rows = {"x": [], "u": [], "x_next": [], "episode": [], "t": [], "contact": []}

    def add(self, x, u, x_next, episode, t, contact):
        for key, value in zip(self.rows, (x, u, x_next, episode, t, contact), strict=True):
            self.rows[key].append(np.array(value, copy=True))

    def transitions(self, source: str, time_step: float, nx: int, nu: int) -> Transitions:
        r = self.rows
        if not r["x"]:
            raise RuntimeError(f"{source}: no transition was recorded")
        return Transitions(
            x=np.array(r["x"]).reshape(-1, nx), u=np.array(r["u"]).reshape(-1, nu),
            x_next=np.array(r["x_next"]).reshape(-1, nx), episode=np.array(r["episode"], int),
            t=np.array(r["t"], int), source=source, time_step=time_step,
            contact=np.array(r["contact"], bool),
        )  # fmt: skip


# ---------------------------------------------------------------------------- Drake (SAP)


def check_drake_coordinates(plant, scene_name: str) -> None:
    """``AssertionError`` unless ``plant``'s positions and velocities are our scene's, by name
    and in order (so x = (q, v) maps entry by entry)."""
    ours = scene_model(scene_name).plant
    for what in ("GetPositionNames", "GetVelocityNames", "GetActuatorNames"):
        theirs_names, our_names = getattr(plant, what)(), getattr(ours, what)()
        assert list(theirs_names) == list(our_names), (
            f"{scene_name}: the Drake twin's {what[3:]} {theirs_names} are not ours {our_names}"
        )


def sap_transitions(
    scene_name: str,
    policy: Policy,
    episodes: int,
    steps: int,
    seed: int,
    approximation: str = "sap",
    material: dict | None = None,
    *,
    initial_state_base=None,
    noise: bool = True,
) -> Transitions:
    """``episodes`` rollouts of ``steps`` steps of the scene's Drake twin (a discrete
    MultibodyPlant at the scene's time step, ``approximation`` in sap, similar, lagged; point
    contact ``material`` as :func:`~drake_abs.reference.drake_twin.make_drake_twin` takes it,
    Drake's defaults otherwise) under ``policy``. Episode e starts at ``initial_state(scene,
    episode_seed(seed, e), initial_state_base, noise)``. An episode ends early only if the
    state stops being finite."""
    from drake_abs.reference.drake_twin import make_drake_twin

    episodes, steps = _check_sizes(episodes, steps)
    model = scene_model(scene_name)
    h = float(model.scene.time_step)
    twin = make_drake_twin(model.scene, approximation, time_step=h, sampled_outputs=False,
                           material=material)  # fmt: skip
    plant, diagram = twin.plant, twin.diagram
    check_drake_coordinates(plant, scene_name)
    low, high = control_range(scene_name)
    nx, nu = model.x0.size, low.size
    rec = _Recorder()
    for e in range(episodes):
        es = episode_seed(seed, e)
        _reset(policy, es)
        context = diagram.CreateDefaultContext()
        pc = plant.GetMyMutableContextFromRoot(context)
        plant.SetPositionsAndVelocities(pc, initial_state(scene_name, es, initial_state_base,
                                                          noise))  # fmt: skip
        port = plant.get_actuation_input_port()

        def touching(pc=pc) -> bool:
            results = plant.get_contact_results_output_port().Eval(pc)
            return results.num_point_pair_contacts() > 0

        x = plant.GetPositionsAndVelocities(pc).copy()
        contact_x = touching()
        for t in range(steps):
            u = _act(policy, x, t, low, high)
            if nu:
                port.FixValue(pc, u)
            context.SetDiscreteState(diagram.EvalUniquePeriodicDiscreteUpdate(context))
            x_next = plant.GetPositionsAndVelocities(pc).copy()
            if not np.all(np.isfinite(x_next)):
                break
            contact_next = touching()
            rec.add(x, u, x_next, e, t, contact_x or contact_next)
            x, contact_x = x_next, contact_next
    return rec.transitions(f"drake-{approximation}:{scene_name}", h, nx, nu)


# ----------------------------------------------------------------------------------- MuJoCo

_INTEGRATORS = ("Euler", "RK4", "implicit", "implicitfast")


def _apply_mujoco_options(model, options: dict | None, time_step: float) -> int:
    """Set ``options`` on a MuJoCo model: ``timestep`` (s), ``integrator`` (one of
    :data:`_INTEGRATORS`), ``cone`` (``"pyramidal"``, ``"elliptic"``), ``contact`` (False:
    contacts disabled), ``springs`` (False: joint stiffness zeroed, as our half-cheetah scene
    drops it). Returns the substeps per step of our scene (``time_step`` / timestep,
    ``ValueError`` unless whole)."""
    import mujoco

    options = dict(options or {})
    unknown = set(options) - {"timestep", "integrator", "cone", "contact", "springs"}
    if unknown:
        raise ValueError(f"mujoco_options: unknown keys {sorted(unknown)}")
    if "timestep" in options:
        model.opt.timestep = float(options["timestep"])
    if "integrator" in options:
        name = options["integrator"]
        if name not in _INTEGRATORS:
            raise ValueError(f"integrator must be one of {_INTEGRATORS}; got {name!r}")
        model.opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{name.upper()}")
    if "cone" in options:
        if options["cone"] not in ("pyramidal", "elliptic"):
            raise ValueError(f"cone must be 'pyramidal' or 'elliptic'; got {options['cone']!r}")
        model.opt.cone = getattr(mujoco.mjtCone, f"mjCONE_{options['cone'].upper()}")
    if options.get("contact", True) is False:
        model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    if options.get("springs", True) is False:
        model.jnt_stiffness[:] = 0.0
    ratio = time_step / float(model.opt.timestep)
    skip = int(round(ratio))
    if skip < 1 or abs(ratio - skip) > 1e-9 * ratio:
        raise ValueError(
            f"the scene's time step {time_step} s is not a whole multiple of MuJoCo's timestep "
            f"{model.opt.timestep} s"
        )
    return skip


def check_mujoco_coordinates(model, scene_name: str) -> np.ndarray:
    """``AssertionError`` unless the MuJoCo model's joints are our scene's coordinates in order
    (one-dof slide and hinge joints named as our positions, qpos = q and qvel = v entry by entry)
    and its motors drive our actuators' joints in order with gear * ctrlrange = our effort
    limits. Returns the gears (nu,): ctrl = u / gear."""
    import mujoco

    ours = scene_model(scene_name)
    names = [n.removesuffix("_x").removesuffix("_q") for n in ours.plant.GetPositionNames(False)]
    joints = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)]
    assert joints == names, f"{scene_name}: MuJoCo's joints {joints} are not our q {names}"
    one_dof = {int(mujoco.mjtJoint.mjJNT_SLIDE), int(mujoco.mjtJoint.mjJNT_HINGE)}
    assert all(int(k) in one_dof for k in model.jnt_type), "MuJoCo joints must be slide or hinge"
    assert np.array_equal(model.jnt_qposadr, np.arange(model.njnt)), "qpos is not joint by joint"
    assert np.array_equal(model.jnt_dofadr, np.arange(model.njnt)), "qvel is not joint by joint"
    # the motors: their joints in our actuator order, gear * ctrlrange = our effort limits
    drake_joints = [
        ours.plant.get_joint_actuator(i).joint().name()
        for i in ours.plant.GetJointActuatorIndices()
    ]
    motor_joints = [joints[j] for j in model.actuator_trnid[:, 0]]
    assert motor_joints == drake_joints, (
        f"{scene_name}: MuJoCo's motors drive {motor_joints}, ours {drake_joints}"
    )
    gear = np.array(model.actuator_gear[:, 0], float)
    _, high = control_range(scene_name)
    limit = np.abs(gear) * np.abs(model.actuator_ctrlrange).max(axis=1)
    assert np.allclose(limit, high, rtol=1e-9), f"MuJoCo's gear * ctrlrange {limit}, ours {high}"
    return gear


def _contact_probe(model):
    """A function x -> whether MuJoCo finds a contact at state x (a scratch MjData, so the
    simulation's own data, warm start included, is left alone)."""
    import mujoco

    scratch = mujoco.MjData(model)
    nq = model.nq

    def contact(x: np.ndarray) -> bool:
        scratch.qpos[:] = x[:nq]
        scratch.qvel[:] = x[nq:]
        mujoco.mj_fwdPosition(model, scratch)
        return scratch.ncon > 0

    return contact


def box_mujoco_model(options: dict | None = None):
    """The box's MuJoCo model (:data:`BOX_MJCF`) with ``options`` applied (see
    :func:`mujoco_transitions`); returns (model, substeps per scene step)."""
    import mujoco

    from drake_abs.multibody.builder import PACKAGE_DIR

    model = mujoco.MjModel.from_xml_path(str(PACKAGE_DIR / BOX_MJCF))
    h = float(scene_model("box_push").scene.time_step)
    return model, _apply_mujoco_options(model, options, h)


def mujoco_transitions(
    scene_name: str,
    policy: Policy,
    episodes: int,
    steps: int,
    seed: int,
    *,
    initial_state_base=None,
    mujoco_options: dict | None = None,
    env_options: dict | None = None,
) -> Transitions:
    """``episodes`` rollouts of at most ``steps`` steps in MuJoCo under ``policy``: gymnasium's
    environment of the scene (``gym_hopper``, ``gym_half_cheetah``; ``env_options`` passed to
    ``gymnasium.make``, e.g. ``terminate_when_unhealthy=False``), or the box's model
    (``box_push``). One step = one step of our scene (``frame_skip`` MuJoCo steps).

    ``mujoco_options`` changes the MuJoCo model's settings (``timestep``, ``integrator``,
    ``cone``, ``contact=False``, ``springs=False``; ``frame_skip`` follows the timestep):
    e.g. ``{"integrator": "Euler", "timestep": 0.01}`` makes MuJoCo's step our semi-implicit
    Euler step.

    Episode e: the environment reset with ``seed=episode_seed(seed, e)`` (gymnasium's reset
    noise; for the box :func:`initial_state`'s), moved by the same noise around
    ``initial_state_base`` when that is given; it ends at ``terminated`` or after ``steps``."""
    episodes, steps = _check_sizes(episodes, steps)
    if scene_name == "box_push":
        return _box_mujoco(policy, episodes, steps, seed, initial_state_base, mujoco_options)
    if scene_name not in MUJOCO_ENVS:
        raise ValueError(f"scene_name must be one of {SCENES}; got {scene_name!r}")
    import gymnasium

    from drake_abs.experiments.locomotion_transfer import same_period_frame_skip

    env_id = MUJOCO_ENVS[scene_name]
    model = scene_model(scene_name)
    h = float(model.scene.time_step)
    frame_skip = same_period_frame_skip(env_id, h)["frame_skip"]
    env = gymnasium.make(env_id, frame_skip=frame_skip, max_episode_steps=steps,
                         disable_env_checker=True, **(env_options or {}))  # fmt: skip
    try:
        raw = env.unwrapped
        if mujoco_options:
            raw.frame_skip = _apply_mujoco_options(raw.model, mujoco_options, h)
        if abs(raw.dt - h) > 1e-12:
            raise RuntimeError(f"{env_id}: one step lasts {raw.dt} s, not the scene's {h} s")
        gear = check_mujoco_coordinates(raw.model, scene_name)
        data, nq = raw.data, raw.model.nq
        contact = _contact_probe(raw.model)
        low, high = control_range(scene_name)
        rec = _Recorder()

        def state() -> np.ndarray:
            return np.concatenate([data.qpos, data.qvel])

        base = None if initial_state_base is None else np.asarray(initial_state_base, float)
        for e in range(episodes):
            es = episode_seed(seed, e)
            _reset(policy, es)
            env.reset(seed=es)
            if base is not None:  # the same reset noise around the given state
                noise = state() - np.concatenate([raw.init_qpos, raw.init_qvel])
                x0 = base + noise
                raw.set_state(x0[:nq], x0[nq:])
            x = state()
            contact_x = contact(x)
            for t in range(steps):
                u = _act(policy, x, t, low, high)
                _, _, terminated, truncated, _ = env.step(u / gear)
                x_next = state()
                contact_next = contact(x_next)
                rec.add(x, u, x_next, e, t, contact_x or contact_next)
                x, contact_x = x_next, contact_next
                if terminated or truncated:
                    break
    finally:
        env.close()
    return rec.transitions(f"mujoco-{env_id}:{scene_name}", h, model.x0.size, low.size)


def _box_mujoco(policy, episodes, steps, seed, base, options) -> Transitions:
    import mujoco

    model, substeps = box_mujoco_model(options)
    gear = check_mujoco_coordinates(model, "box_push")
    data = mujoco.MjData(model)
    contact = _contact_probe(model)
    low, high = control_range("box_push")
    nq = model.nq
    rec = _Recorder()
    for e in range(episodes):
        es = episode_seed(seed, e)
        _reset(policy, es)
        mujoco.mj_resetData(model, data)
        x = initial_state("box_push", es, base)
        data.qpos[:], data.qvel[:] = x[:nq], x[nq:]
        mujoco.mj_forward(model, data)
        contact_x = contact(x)
        for t in range(steps):
            u = _act(policy, x, t, low, high)
            data.ctrl[:] = u / gear
            for _ in range(substeps):
                mujoco.mj_step(model, data)
            x_next = np.concatenate([data.qpos, data.qvel])
            if not np.all(np.isfinite(x_next)):
                break
            contact_next = contact(x_next)
            rec.add(x, u, x_next, e, t, contact_x or contact_next)
            x, contact_x = x_next, contact_next
    h = float(scene_model("box_push").scene.time_step)
    return rec.transitions("mujoco:box_push", h, 2 * nq, low.size)


# ------------------------------------------------------------------------ our predictions


#: A transition is "near a joint limit" when a limited joint is within this (rad or m) of its
#: limit at x or at x_next (the scenes' activation distance): our limits are hard, Drake's (SAP
#: constraints, which act before the limit at speed) and MuJoCo's soft.
NEAR_LIMIT = 0.1
#: ... and "clear of the ground" when every one of our contact points is at least this (m) above
#: it at x and at x_next: closer, our speculative contact may hold a point the source lets sink.
CLEARANCE = 1e-3


def prediction_errors(data: Transitions, scene_name: str, stepper=None) -> dict:
    """Our model's one-step prediction errors on ``data``: ``stepper`` (default our scene's
    exact stepper) from each recorded (x, u), one state per call, compared with the recorded
    x_next (:func:`~drake_abs.learning.transitions.error_summary`: the mean and max of the
    largest absolute error in q and in v, per part: ``all``; ``free`` and ``contact`` by the
    source's contact flag; ``smooth``: free, our contact points clear of the ground
    (:data:`CLEARANCE`) and no joint near a limit (:data:`NEAR_LIMIT`), where both models step
    the same smooth dynamics), plus ``unconverged`` (steps whose contact solve did not
    converge), ``seconds`` and per transition the errors ``q_err``, ``v_err`` and the masks
    ``near_limit``, ``clear`` (arrays, N)."""
    stepper = exact_stepper(scene_name) if stepper is None else stepper
    start = time.perf_counter()
    x_pred, converged = one_step_predictions(stepper, data)
    nq = scene_model(scene_name).contact_model.nq
    q, q_next = data.x[:, :nq], data.x_next[:, :nq]
    near = np.zeros(len(data), bool)
    limits = getattr(stepper, "limits", None)
    if limits is not None and limits.size:
        near = np.minimum(limits.distances(q), limits.distances(q_next)).min(axis=1) < NEAR_LIMIT
    distances = stepper.model.distances
    clear = np.minimum(distances(q), distances(q_next)).min(axis=1) >= CLEARANCE
    parts = {} if data.contact is None else {"smooth": ~data.contact & ~near & clear}
    out = error_summary(data, x_pred, nq, parts)
    err = np.abs(x_pred - data.x_next)
    out["unconverged"] = int((~converged).sum())
    out["seconds"] = time.perf_counter() - start
    out["q_err"], out["v_err"] = err[:, :nq].max(axis=1), err[:, nq:].max(axis=1)
    out["near_limit"], out["clear"] = near, clear
    return out


def report(errors: dict[str, dict]) -> str:
    """A table of :func:`prediction_errors` results by source name."""
    lines = [f"{'source':36s} {'part':15s} {'n':>5s} {'q mean':>9s} {'q max':>9s} "
             f"{'v mean':>9s} {'v max':>9s}"]  # fmt: skip
    for name, e in errors.items():
        for part in ("smooth", "free", "contact", "all"):
            s = e.get(part)
            if not s or not s["n"]:
                continue
            lines.append(f"{name:36s} {part:15s} {s['n']:5d} {s['q_mean']:9.2e} {s['q_max']:9.2e} "
                         f"{s['v_mean']:9.2e} {s['v_max']:9.2e}")  # fmt: skip
    return "\n".join(lines)


def survey(episodes: int = 4, steps: int = 100, seed: int = 0) -> dict[str, dict]:
    """Every source and policy, with our exact model's one-step errors on each (the numbers the
    module's tests and report quote)."""
    out = {}
    for scene in SCENES:
        low, high = control_range(scene)
        if scene == "box_push":
            low, high = np.full(1, -12.0), np.full(1, 12.0)
        policies = {"random": random_policy(low.size, low, high, seed),
                    "scripted": scripted_policy(scene, seed)}  # fmt: skip
        for pname, policy in policies.items():
            sources = {"sap": lambda p=policy, s=scene: sap_transitions(s, p, episodes, steps,
                                                                       seed)}  # fmt: skip
            sources["mujoco"] = lambda p=policy, s=scene: mujoco_transitions(
                s, p, episodes, steps, seed,
                env_options={"terminate_when_unhealthy": False} if s == "gym_hopper" else None,
            )  # fmt: skip
            for sname, make in sources.items():
                data = make()
                out[f"{sname}:{scene}:{pname}"] = prediction_errors(data, scene)
    return out


if __name__ == "__main__":
    print(report(survey()))
