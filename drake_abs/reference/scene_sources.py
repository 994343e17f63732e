"""Our scenes in the reference simulators, as sources of transition data: a scene's Drake twin
(:class:`~drake_abs.reference.drake_plant.DrakePlantStepper`, SAP / Similar / Lagged) and its
MuJoCo counterpart (:data:`~drake_abs.reference.scene_sources.MUJOCO_MODELS`: gymnasium's
``Hopper-v5`` and ``HalfCheetah-v5`` as published, and this package's ``models/box_planar.xml``
for ``box_push``), each a stepper in the scene's own coordinates, checked against the scene's
plant, with a contact probe.

Coordinates: x = the scene's (q, v), entry by entry (the twin's positions, velocities and
actuators are the scene's by name and order, :func:`check_drake_coordinates`; MuJoCo's one-dof
joints are the scene's positions, qpos = q and qvel = v, and its motors drive the scene's
actuators with gear * ctrlrange = the effort limits, :func:`check_mujoco_coordinates`); u = the
scene's input in N or N m (MuJoCo's ctrl is u / gear, :class:`TorqueInput`), applied as given:
clip it at the effort limits beforehand where the scene's own stepper would.

One step is one step of the scene (its time step): the twin is a discrete plant at that period;
MuJoCo takes ``frame_skip`` = time step / MuJoCo's timestep substeps (:func:`whole_frame_skip`;
5 for the Hopper's 2 ms, 1 for the HalfCheetah's and the box's 10 ms).

Contact probes (``SceneSource.in_contact``, states (N, nx) -> (N,) bool): Drake, a point pair in
the twin's contact results at the state; MuJoCo, ``ncon > 0`` after its position stage (contacts
within the geoms' margins, self-contacts included), on a scratch ``MjData`` so that the
stepper's own data (its warm start) is left alone.

Run a source in the engine (:func:`drake_abs.engine.open_loop` for given inputs,
:func:`~drake_abs.engine.rollout` for a policy) and keep the run as
:meth:`drake_abs.learning.transitions.Transitions.from_trajectory`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from drake_abs._validation import as_finite_array
from drake_abs.contact.step import Step
from drake_abs.engine.protocols import Stepper
from drake_abs.multibody.joint_limits import effort_limits
from drake_abs.reference.drake_plant import DrakePlantStepper
from drake_abs.reference.mujoco_plant import MujocoStepper

__all__ = [
    "MUJOCO_MODELS",
    "SceneSource",
    "TorqueInput",
    "check_drake_coordinates",
    "check_mujoco_coordinates",
    "drake_source",
    "mujoco_source",
    "whole_frame_skip",
]

#: Our scenes' MuJoCo counterparts, each a gymnasium environment id or a model file of this
#: package (the box of ``box_push``'s SDF with the scene's contact points as 1 mm spheres over a
#: floor lowered by their radius, friction 0.5, pyramidal cone, Euler at 0.01 s).
MUJOCO_MODELS = {
    "box_push": "models/box_planar.xml",
    "gym_hopper": "Hopper-v5",
    "gym_half_cheetah": "HalfCheetah-v5",
}
_PACKAGE = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class SceneSource:
    """A reference simulator of one of our scenes, in the scene's coordinates.

    Attributes:
        name: what simulates it, e.g. ``"drake-sap:box_push"``, ``"mujoco-Hopper-v5:gym_hopper"``,
            ``"mujoco:box_push"`` (the ``source`` of the transitions it records).
        stepper: a :class:`~drake_abs.engine.protocols.Stepper` of x (B, nq + nv), u (B, nu) in
            the scene's units.
        in_contact: states (N, nx) -> (N,) bool: whether the simulator has contact there.
        time_step: seconds per step (the scene's).
    """

    name: str
    stepper: Stepper
    in_contact: Callable[[np.ndarray], np.ndarray]
    time_step: float


def drake_source(
    scene_model, approximation: str = "sap", *, material: dict | None = None
) -> SceneSource:
    """The scene's Drake twin at its time step (``approximation`` ``"sap"``, ``"similar"`` or
    ``"lagged"``; point-contact ``material`` as
    :func:`~drake_abs.reference.drake_twin.make_drake_twin` takes it), its coordinates checked
    to be the scene's. ``scene_model``: the scene's
    :class:`~drake_abs.multibody.builder.SceneModel`."""
    stepper = DrakePlantStepper(scene_model.scene, approximation, material=material)
    check_drake_coordinates(stepper.twin.plant, scene_model.plant, scene_model.scene.name)
    twin = stepper.twin
    context = twin.diagram.CreateDefaultContext()
    plant_context = twin.plant.GetMyMutableContextFromRoot(context)
    results = twin.plant.get_contact_results_output_port()

    def in_contact(x) -> np.ndarray:
        x = _states(x, stepper.nx)
        out = np.empty(x.shape[0], bool)
        for i, state in enumerate(x):
            twin.plant.SetPositionsAndVelocities(plant_context, state)
            out[i] = results.Eval(plant_context).num_point_pair_contacts() > 0
        return out

    name = f"drake-{approximation}:{scene_model.scene.name}"
    return SceneSource(name, stepper, in_contact, stepper.time_step)


def mujoco_source(scene_model, *, options: dict | None = None) -> SceneSource:
    """The scene's MuJoCo counterpart (:data:`MUJOCO_MODELS`), ``options`` applied to its model
    (:func:`~drake_abs.reference.mujoco_plant.apply_options`: ``timestep``, ``integrator``,
    ``cone``, ``contact=False``, ``springs=False``), stepped ``frame_skip`` times per step of the
    scene, its coordinates checked to be the scene's, driven in the scene's units
    (:class:`TorqueInput`). E.g. ``options={"integrator": "Euler", "timestep": 0.01}`` makes
    MuJoCo's step the scene's semi-implicit Euler step (MuJoCo applies the HalfCheetah's joint
    springs explicitly, the scene's step implicitly; add ``"springs": False`` and step the
    scene with ``stepper(springs=False)`` to compare without them)."""
    scene = scene_model.scene
    if scene.name not in MUJOCO_MODELS:
        raise ValueError(
            f"scene_model must be one of the scenes {sorted(MUJOCO_MODELS)}; got {scene.name!r}"
        )
    target = MUJOCO_MODELS[scene.name]
    if target.endswith(".xml"):
        first, name = MujocoStepper(_PACKAGE / target, options=options), f"mujoco:{scene.name}"
    else:
        first = MujocoStepper.from_gymnasium(target, frame_skip=1, options=options)
        name = f"mujoco-{target}:{scene.name}"
    skip = whole_frame_skip(float(first.model.opt.timestep), float(scene.time_step))
    stepper = MujocoStepper(first.model, frame_skip=skip)  # the options are in first.model
    gear = check_mujoco_coordinates(
        stepper.model, scene_model.plant, effort_limits(scene_model.plant), scene.name
    )
    return SceneSource(name, TorqueInput(stepper, gear), _mujoco_probe(stepper.model),
                       stepper.time_step)  # fmt: skip


def whole_frame_skip(timestep: float, time_step: float) -> int:
    """The substeps of ``timestep`` (s) in one step of ``time_step`` (s); ``ValueError`` unless
    ``time_step`` is a whole multiple of ``timestep``."""
    ratio = time_step / timestep
    skip = int(round(ratio))
    if skip < 1 or abs(ratio - skip) > 1e-9 * ratio:
        raise ValueError(
            f"time_step {time_step} s is not a whole multiple of the simulator's timestep "
            f"{timestep} s"
        )
    return skip


@dataclass(frozen=True)
class TorqueInput:
    """A :class:`~drake_abs.reference.mujoco_plant.MujocoStepper` driven by joint torques or
    forces: ``step(x, u)`` is ``stepper.step(x, u / gear)`` (MuJoCo's actuator force is gear *
    ctrl), its ``dx_du`` divided by the gears column by column.

    Args:
        stepper: the MuJoCo stepper (its u is ctrl).
        gear: (nu,) the motors' gears (N m or N per unit of ctrl), nonzero.
    """

    stepper: MujocoStepper
    gear: np.ndarray
    parameter_names = ()

    def __post_init__(self):
        gear = as_finite_array(self.gear, "gear", ndim=(1,))
        if gear.shape != (self.stepper.nu,) or np.any(gear == 0):
            raise ValueError(f"gear must be nonzero with shape ({self.stepper.nu},); got {gear}")
        object.__setattr__(self, "gear", gear)

    @property
    def nx(self) -> int:
        return self.stepper.nx

    @property
    def nu(self) -> int:
        return self.stepper.nu

    @property
    def time_step(self) -> float:
        return self.stepper.time_step

    def step(self, x, u, *, jacobians: bool = True, parameters: bool = False) -> Step:
        """One step of a batch: x (B, nx), u (B, nu) torques or forces (or one of each)."""
        ctrl = np.asarray(u, dtype=float) / self.gear
        step = self.stepper.step(x, ctrl, jacobians=jacobians, parameters=parameters)
        return step if step.dx_du is None else replace(step, dx_du=step.dx_du / self.gear)


def check_drake_coordinates(plant, scene_plant, scene_name: str = "scene") -> None:
    """``AssertionError`` unless ``plant``'s positions, velocities and actuators are those of
    ``scene_plant`` (the scene's MultibodyPlant), by name and in order (so x = (q, v) and u map
    entry by entry)."""
    for what in ("GetPositionNames", "GetVelocityNames", "GetActuatorNames"):
        theirs, ours = list(getattr(plant, what)()), list(getattr(scene_plant, what)())
        assert theirs == ours, f"{scene_name}: the Drake twin's {what[3:]} {theirs} are not {ours}"


def check_mujoco_coordinates(model, scene_plant, effort, scene_name: str = "scene") -> np.ndarray:
    """``AssertionError`` unless the MuJoCo ``model``'s joints are the scene's coordinates in
    order (one-dof slide and hinge joints named as ``scene_plant``'s positions, qpos = q and
    qvel = v entry by entry) and its motors drive the scene's actuated joints in order with
    gear * ctrlrange = ``effort`` (nu,), the effort limits. Returns the gears (nu,): ctrl =
    u / gear."""
    import mujoco

    names = [n.removesuffix("_x").removesuffix("_q") for n in scene_plant.GetPositionNames(False)]
    joints = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)]
    assert joints == names, f"{scene_name}: MuJoCo's joints {joints} are not our q {names}"
    one_dof = {int(mujoco.mjtJoint.mjJNT_SLIDE), int(mujoco.mjtJoint.mjJNT_HINGE)}
    assert all(int(k) in one_dof for k in model.jnt_type), "MuJoCo joints must be slide or hinge"
    assert np.array_equal(model.jnt_qposadr, np.arange(model.njnt)), "qpos is not joint by joint"
    assert np.array_equal(model.jnt_dofadr, np.arange(model.njnt)), "qvel is not joint by joint"
    actuated = [
        scene_plant.get_joint_actuator(i).joint().name()
        for i in scene_plant.GetJointActuatorIndices()
    ]
    motors = [joints[j] for j in model.actuator_trnid[:, 0]]
    assert motors == actuated, f"{scene_name}: MuJoCo's motors drive {motors}, ours {actuated}"
    gear = np.array(model.actuator_gear[:, 0], float)
    limit = np.abs(gear) * np.abs(model.actuator_ctrlrange).max(axis=1)
    assert np.allclose(limit, effort, rtol=1e-9), (
        f"MuJoCo's gear * ctrlrange {limit}, ours {effort}"
    )
    return gear


def _mujoco_probe(model) -> Callable[[np.ndarray], np.ndarray]:
    """states (N, nx) -> (N,) whether MuJoCo finds a contact there (a scratch MjData)."""
    import mujoco

    scratch = mujoco.MjData(model)
    nq, nv = model.nq, model.nv

    def in_contact(x) -> np.ndarray:
        x = _states(x, nq + nv)
        out = np.empty(x.shape[0], bool)
        for i, state in enumerate(x):
            scratch.qpos[:], scratch.qvel[:] = state[:nq], state[nq:]
            mujoco.mj_fwdPosition(model, scratch)
            out[i] = scratch.ncon > 0
        return out

    return in_contact


def _states(x, nx: int) -> np.ndarray:
    x = as_finite_array(x, "x", ndim=(1, 2))
    x = np.atleast_2d(x)
    if x.shape[1] != nx:
        raise ValueError(f"x must have shape (N, nx) = (N, {nx}); got {x.shape}")
    return x
