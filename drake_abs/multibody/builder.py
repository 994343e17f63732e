"""Build a scene's MultibodyPlant, its contact model and its stepper from a
:class:`drake_abs.multibody.scene.Scene`.

``make_stepper(scene)`` (or ``build_scene_model(scene).stepper()``) is the one way to get a
scene's batched step with every setting the scene names applied (smoothing, activation
distance); arguments override a setting explicitly, nothing is copied by hand. A stepper built
here is picklable: it is sent as its scene and settings and rebuilt where it is unpickled
(:func:`rebuild_stepper`).

This module is the top of the scene modules of :mod:`drake_abs.multibody`; each imports only
those below it: :mod:`~drake_abs.multibody.packages` (package resolution),
:mod:`~drake_abs.multibody.parser_messages` (Drake's parser warnings, reported once per file),
:mod:`~drake_abs.multibody.model_files`, :mod:`~drake_abs.multibody.scene_entries`,
:mod:`~drake_abs.multibody.parsing` (model files into a plant),
:mod:`~drake_abs.multibody.contacts` (contact candidates), :mod:`~drake_abs.multibody.scene`.
Run ``python -m drake_abs.multibody.builder SCENE...`` to print what a scene's plant holds
(:func:`~drake_abs.multibody.model_files.model_report`).
"""

from __future__ import annotations

import difflib
import functools
import hashlib
import sys
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, ModelInstanceIndex

from drake_abs.contact.lcs import GradientMode
from drake_abs.contact.smoothing import Smoothing
from drake_abs.multibody.contacts import contact_candidates
from drake_abs.multibody.drake_dynamics import (
    ContactModelBase,
    GroundPlane,
    MultibodyContactModel,
    PointContact,
)
from drake_abs.multibody.geometry_contacts import PairContact
from drake_abs.multibody.model_files import format_model_report, model_report, read_mjcf
from drake_abs.multibody.parsing import add_model_specs, resolve_model_file
from drake_abs.multibody.pinocchio_dynamics import PinocchioContactModel
from drake_abs.multibody.scene import Scene, shipped_scenes
from drake_abs.multibody.scene_compliance import scene_compliance
from drake_abs.multibody.stepper import (
    PENETRATION_TOL,
    SOFT_PENETRATION_TOL,
    SOLVER_OPTIONS,
    ComplementarityStepper,
)
from drake_abs.multibody.unmodelled_geometry import UnmodelledGeometry, warn_initial_penetration

#: The keyword arguments :meth:`SceneModel.stepper` accepts: its own overrides of the scene's
#: settings, the switches of :class:`ComplementarityStepper` and the solver's options.
STEPPER_KEYWORDS = (
    "smoothing", "activation_distance", "gradient", "friction",
    "joint_limits", "damping", "springs", "joint_friction", "check_unmodelled", *SOLVER_OPTIONS,
)  # fmt: skip

#: A scene setting that a stepper keyword overrides under another name.
_SCENE_SETTING_KEYWORD = {"friction_model": "friction"}


def check_stepper_keywords(options: Mapping, scene: Scene, caller: str) -> None:
    """Refuse, when a stepper or a plant is built, a keyword argument that a stepper does not
    take. A setting that belongs to the scene (``time_step``, ``ground_height``, ...: a
    :class:`Scene` key) is named as such, with how to change it there; any other unknown name
    gets the list of the accepted ones (and the closest of them).

    Args:
        options: the keyword arguments given (only their names are checked here; the stepper
            checks the values).
        scene: the scene the stepper is built from (named in the message).
        caller: the function the keywords were given to, which starts the message.

    Raises:
        ValueError: naming the first bad keyword and where the setting belongs.
    """
    unknown = [name for name in options if name not in STEPPER_KEYWORDS]
    if not unknown:
        return
    scene_keys = {f.name for f in fields(Scene)}
    for name in unknown:
        if name not in scene_keys:
            continue
        value = options[name]
        shipped = scene.name in shipped_scenes() and Scene.load(scene.name) == scene
        source = f"Scene.load({scene.name!r}).to_dict()" if shipped else "scene.to_dict()"
        how = f"Scene.from_dict({{**{source}, {name!r}: {value!r}}})"
        instead = _SCENE_SETTING_KEYWORD.get(name)
        also = f" (or override it with the keyword argument {instead}=...)" if instead else ""
        raise ValueError(
            f"{caller}: {name}={value!r} is not a stepper option: {name} is a setting of the "
            f"scene {scene.name!r} (its YAML key {name!r}); build from a scene with it "
            f"changed, e.g. {how}{also}"
        )
    hints = []
    for name in unknown:
        close = difflib.get_close_matches(name, STEPPER_KEYWORDS, n=1)
        if close:
            hints.append(f"{name!r}: did you mean {close[0]!r}?")
    hint = f" ({'; '.join(hints)})" if hints else ""
    raise ValueError(
        f"{caller}: unknown stepper option(s) {sorted(unknown)}{hint}; the keyword arguments "
        f"are {', '.join(STEPPER_KEYWORDS)}, and the scene's settings are changed in the scene"
    )


@dataclass(frozen=True)
class SceneModel:
    """A scene's dynamics: a continuous MultibodyPlant (no SceneGraph: contacts are the scene's
    declared points) and its contact model, plus the initial state."""

    scene: Scene
    plant: MultibodyPlant
    contact_model: ContactModelBase
    q0: np.ndarray
    v0: np.ndarray

    @property
    def x0(self) -> np.ndarray:
        """The scene's initial state x = (q0, v0), shape (nq + nv,)."""
        return np.concatenate([self.q0, self.v0])

    @functools.cached_property
    def joint_friction(self) -> np.ndarray:
        """The dry friction bound of each velocity, (nv,) in N m or N (0 where none), from the
        scene's MJCF files (:func:`scene_joint_friction`), which the step takes as
        complementarity rows (:mod:`drake_abs.multibody.joint_friction`)."""
        return scene_joint_friction(self.scene, self.plant)

    @functools.cached_property
    def unmodelled_geometry(self) -> UnmodelledGeometry:
        """The collision geometry of the scene's models that its contact candidates do not
        cover (:class:`~drake_abs.multibody.unmodelled_geometry.UnmodelledGeometry`; read from
        the model files when first needed, once per process), which the scene's steppers
        check after every step (their option ``check_unmodelled``)."""
        return UnmodelledGeometry.of_scene(self.scene, self.plant, self.contact_model.contacts)

    def suggest_contacts(self, bodies=None, tolerance: float = PENETRATION_TOL):
        """Contact entries that model the collision geometry of ``bodies`` (names, as
        :class:`~drake_abs.multibody.unmodelled_geometry.UnmodelledPenetrationWarning` gives
        them; default: every body whose geometry no candidate covers to within ``tolerance``,
        m) from its shapes, a
        :class:`~drake_abs.multibody.unmodelled_geometry.SuggestedContacts`: ``.entries``
        (mappings of the scene YAML's ``contacts`` schema), ``.yaml`` (text to paste under a
        scene file's ``contacts:``) and ``.added_to(scene)`` (the scene with them). See
        :meth:`~drake_abs.multibody.unmodelled_geometry.UnmodelledGeometry.suggest_contacts`
        for the points of each shape."""
        return self.unmodelled_geometry.suggest_contacts(bodies, tolerance)

    def model_report(self) -> dict:
        """What the plant holds of the scene's model files: per joint its coordinates, limits,
        damping, armature, spring and dry friction (``frictionloss``, N m or N), per actuator
        its gear and effort limit (see :func:`drake_abs.multibody.model_files.model_report`)."""
        report = model_report(self.plant)
        for joint in report["joints"]:
            joint["frictionloss"] = float(self.joint_friction[joint["v_index"]])
        return report

    def stepper(
        self,
        *,
        smoothing: Smoothing | None = None,
        activation_distance: float | None = None,
        gradient: GradientMode = "total",
        friction: str | None = None,
        **solver_options,
    ) -> ComplementarityStepper:
        """The scene's batched step, with the scene's smoothing, activation distance and
        contact compliance (:mod:`drake_abs.multibody.scene_compliance`).

        Args:
            smoothing: replaces the scene's smoothing (larger mu: more smoothing). It
                is used as given at the scene's ``time_step``: the smoothing's
                ``reference_time_step`` does not rescale it (wrap it in
                :class:`~drake_abs.contact.smoothing.TimeStepScaled` for that).
            activation_distance: replaces the scene's activation distance (m).
            gradient: ``"frozen"`` or ``"total"`` (see :class:`ComplementarityStepper`).
            friction: replaces the scene's friction formulation (``"stewart_trinkle"`` or
                ``"anitescu"``).
            solver_options: the switches of :class:`ComplementarityStepper`
                (``joint_limits``, ``damping``, ``springs``: True (default) takes the
                scene's ``joint_springs``, ``joint_friction``) and the
                interior-point solver's options (``tol``, ``max_iterations``, ``exact_tol``,
                ``strict``). Any other name is refused here (:func:`check_stepper_keywords`);
                a scene setting such as ``time_step`` is changed in the scene.
        """
        check_stepper_keywords(solver_options, self.scene, "SceneModel.stepper")
        springs = solver_options.get("springs", True)
        if springs is True:  # the scene's treatment of its springs
            springs = self.scene.joint_springs
        stepper = ComplementarityStepper(
            self.contact_model,
            self.scene.make_smoothing() if smoothing is None else smoothing,
            gradient,
            self.scene.activation_distance if activation_distance is None else activation_distance,
            self.scene.friction_model if friction is None else friction,
            compliance=scene_compliance(self.scene, self.contact_model),
            **{"joint_friction": self.joint_friction, **solver_options, "springs": springs},
        )
        stepper.scene, stepper.rebuild = self.scene, rebuild_stepper  # picklable
        stepper.unmodelled = self.unmodelled_geometry
        return stepper


def scene_joint_friction(scene: Scene, plant: MultibodyPlant) -> np.ndarray:
    """The dry friction bound of each velocity of ``plant`` (nv,) (N m or N; 0: none): every
    MJCF joint's ``frictionloss`` (:func:`~drake_abs.multibody.model_files.read_mjcf`, with the
    model's ``ignore``) on its joint's velocity, found in the model instance the file was parsed
    into (the model's ``name``, else the file's ``<mujoco model>``). Other formats have none
    (Drake drops a URDF joint's ``<dynamics friction>``, warning that it does not model it)."""
    out = np.zeros(plant.num_velocities())
    for i, spec in enumerate(scene.models):
        key = f"models[{i}].file"
        path = resolve_model_file(spec, f"{scene.locate(key)}: {key}")
        if path.suffix.lower() != ".xml":
            continue
        info = read_mjcf(path, spec.ignore)
        if not info.frictionloss:
            continue
        name = spec.name or ElementTree.parse(path).getroot().get("model")
        instance = plant.GetModelInstanceByName(name)
        for joint, bound in info.frictionloss:
            out[plant.GetJointByName(joint, instance).velocity_start()] += bound
    return out


def add_scene_models(
    plant: MultibodyPlant, scene: Scene, parser: Parser | None = None, *, collisions: bool = True
) -> None:
    """Parse the scene's models into ``plant`` (not finalized), with welds, actuators and
    floating bases; ``collisions=False`` leaves the files' collision geometry out (see
    :func:`~drake_abs.multibody.parsing.add_model_specs`)."""
    add_model_specs(plant, scene.models, scene.locate, parser, collisions=collisions)


def _check_armature(model: PinocchioContactModel, plant: MultibodyPlant) -> None:
    """``NotImplementedError`` unless the pinocchio model has the plant's reflected inertias
    (actuator armature, which Drake's mass matrix includes) as its armature."""
    reflected = np.zeros(plant.num_velocities())
    for i in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(i)
        reflected[actuator.joint().velocity_start()] += actuator.default_reflected_inertia()
    armature = np.asarray(getattr(model.pin_model, "armature", np.zeros_like(reflected)))
    if not np.allclose(armature, reflected, rtol=1e-12, atol=0.0):
        raise NotImplementedError(
            "the plant's actuators have reflected inertia (armature) "
            f"{reflected.tolist()} that the pinocchio dynamics do not include (they have "
            f"{armature.tolist()}); use dynamics: drake"
        )


#: Scene models built in this process by :func:`shared_scene_model`, most recently used last.
_SHARED: OrderedDict[tuple, SceneModel] = OrderedDict()
#: How many scene models :func:`shared_scene_model` keeps (the least recently used goes).
SHARED_SCENE_MODELS = 16


def shared_scene_model(scene: Scene) -> SceneModel:
    """:func:`build_scene_model` of ``scene``, built once per process and shared: by the steppers
    a worker rebuilds from pickles (several objectives of one scene) and by the tasks built on
    a scene (:func:`drake_abs.tasks.locomotion.locomotion_task`, called for every method,
    seed, environment and scoring run), so that each model file is parsed once, not once per
    task (a test-size ``drake-abs experiment locomotion`` parsed each file 10 times).

    The key is the scene (as YAML text) and the contents of its model files, so an edited file
    is parsed again. What is shared is the finalized plant and the contact model; every stepper
    made from it is its own (its settings, parameters and caches), and the contact model's
    contexts are scratch space that each evaluation sets afresh, which sharing within one
    process (one thread) allows. Callers that change a model in place must build their own
    (:func:`build_scene_model`)."""
    digests = []
    for i, spec in enumerate(scene.models):
        key = f"models[{i}].file"
        path = resolve_model_file(spec, f"{scene.locate(key)}: {key}")
        digests.append(hashlib.sha1(path.read_bytes()).hexdigest() if path.is_file() else "")
    key = (scene.to_yaml(), *digests)
    model = _SHARED.get(key)
    if model is None:
        model = build_scene_model(scene)
        _SHARED[key] = model
        while len(_SHARED) > SHARED_SCENE_MODELS:
            _SHARED.popitem(last=False)
    _SHARED.move_to_end(key)
    return model


def rebuild_stepper(scene: Scene, settings: dict) -> ComplementarityStepper:
    """A pickled :class:`ComplementarityStepper` rebuilt from its scene and settings (smoothing,
    gradient, activation_distance, friction, joint_limits, damping, springs, joint_friction,
    compliance, solver options, and
    ``parameters``: the model parameters changed by
    :meth:`~ComplementarityStepper.with_parameters`, ``{name: value}``), on the scene's
    :func:`shared_scene_model`."""
    model = shared_scene_model(scene)
    settings = dict(settings)
    parameters = settings.pop("parameters", None)
    stepper = ComplementarityStepper(model.contact_model, **settings)
    stepper.scene, stepper.rebuild = model.scene, rebuild_stepper
    stepper.unmodelled = model.unmodelled_geometry
    if parameters:
        stepper = stepper.with_parameters(parameters)
    return stepper


def make_stepper(scene: Scene | str | Path, **overrides) -> ComplementarityStepper:
    """The batched step of ``scene`` (a :class:`Scene`, a shipped scene's name such as
    ``"box_push"``, or a YAML path) with every scene setting applied; keyword arguments override
    a setting explicitly (see :meth:`SceneModel.stepper`; a name it does not take is refused
    before the plant is built)."""
    if not isinstance(scene, Scene):
        scene = Scene.load(scene)
    check_stepper_keywords(overrides, scene, "make_stepper")
    return build_scene_model(scene).stepper(**overrides)


def scene_contacts(scene: Scene) -> list[PointContact | PairContact]:
    """The contact candidates of ``scene``, in its order (see
    :func:`~drake_abs.multibody.contacts.contact_candidates`)."""
    return contact_candidates(f"scene {scene.name!r}", scene.models, scene.contacts, scene.pairs)


def check_scene_bodies(scene: Scene, plant: MultibodyPlant) -> None:
    """``ValueError`` for a body (or model instance) that a ``contacts`` or ``pairs`` entry of
    ``scene`` names and ``plant`` (its models, parsed) does not have, naming the scene file, the
    key's line (:meth:`~drake_abs.multibody.scene.Scene.locate`), the key and the bodies there
    are (and the closest name)."""
    entries = [(f"contacts[{i}]", "body", c.body, "model", c.model)
               for i, c in enumerate(scene.contacts)]  # fmt: skip
    for i, p in enumerate(scene.pairs):
        entries += [(f"pairs[{i}]", "a", p.a, "model_a", p.model_a),
                    (f"pairs[{i}]", "b", p.b, "model_b", p.model_b)]  # fmt: skip
    for entry, field, body, model_field, model in entries:
        instances = None
        if model is not None:
            if not plant.HasModelInstanceNamed(model):
                key = f"{entry}.{model_field}"
                names = [plant.GetModelInstanceName(ModelInstanceIndex(k))
                         for k in range(plant.num_model_instances())]  # fmt: skip
                raise ValueError(
                    f"{scene.locate(key)}: {key}: no model instance {model!r}; the scene's: "
                    f"{', '.join(names)}{_closest(model, names)}"
                )
            instances = [plant.GetModelInstanceByName(model)]
        if instances is None:
            found = plant.HasBodyNamed(body)
            names = [plant.get_body(BodyIndex(b)).name() for b in range(plant.num_bodies())]
        else:
            found = plant.HasBodyNamed(body, instances[0])
            names = [plant.get_body(b).name() for b in plant.GetBodyIndices(instances[0])]
        if not found:
            key = f"{entry}.{field}"
            inside = f" in model instance {model!r}" if model is not None else ""
            names = sorted(set(names) - {"world"})
            raise ValueError(
                f"{scene.locate(key)}: {key}: no body {body!r}{inside}; the bodies: "
                f"{', '.join(names)}{_closest(body, names)}"
            )


def _closest(name: str, names: list[str]) -> str:
    """`` (did you mean 'x'?)`` for the name of ``names`` closest to ``name``, or ``""``."""
    close = difflib.get_close_matches(name, names, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def build_scene_model(scene: Scene | str | Path) -> SceneModel:
    """The dynamics plant, contact model and initial state of ``scene`` (a :class:`Scene`, a
    shipped scene's name, or a YAML path). An initial state (the scene's ``initial_state``, else
    the model files' default pose) with a contact candidate deeper below the ground than the
    penetration tolerance (1 cm; 5 cm with soft contact) raises
    :class:`~drake_abs.multibody.unmodelled_geometry.InitialPenetrationWarning`, naming each
    such candidate and its depth."""
    if not isinstance(scene, Scene):
        scene = Scene.load(scene)
    plant = MultibodyPlant(0.0)
    add_scene_models(plant, scene)
    plant.Finalize()
    check_scene_bodies(scene, plant)
    contacts = scene_contacts(scene)
    ground = GroundPlane(scene.ground_normal, scene.ground_height)
    args = (plant, contacts, ground, scene.time_step, scene.friction_directions)
    if scene.dynamics == "drake":
        model = MultibodyContactModel(*args)
    else:
        try:
            model = PinocchioContactModel(*args)
            _check_armature(model, plant)
        except NotImplementedError:
            if scene.dynamics == "pinocchio":
                raise
            model = MultibodyContactModel(*args)
    context = plant.CreateDefaultContext()
    q, v = scene.initial_state.q, scene.initial_state.v
    q0 = np.asarray(plant.GetPositions(context) if q is None else q, float)
    v0 = np.asarray(plant.GetVelocities(context) if v is None else v, float)
    if q0.shape != (plant.num_positions(),) or v0.shape != (plant.num_velocities(),):
        raise ValueError(
            f"scene {scene.name!r}: initial_state q and v must have {plant.num_positions()} and "
            f"{plant.num_velocities()} entries; got {q0.shape} and {v0.shape}"
        )
    for s in model.quaternion_starts:  # a free body's (qw, qx, qy, qz): unit, to rounding
        norm = float(np.linalg.norm(q0[s : s + 4]))
        if not abs(norm - 1.0) <= 1e-3:
            raise ValueError(
                f"scene {scene.name!r}: initial_state q[{s}:{s + 4}] is a unit quaternion "
                f"(qw, qx, qy, qz); got norm {norm:.6g}"
            )
        q0[s : s + 4] /= norm
    soft = getattr(scene.compliance, "kind", "hard") != "hard"
    tolerance = SOFT_PENETRATION_TOL if soft else PENETRATION_TOL
    warn_initial_penetration(model, q0, tolerance, f"scene {scene.name!r}", scene, stacklevel=2)
    return SceneModel(scene, plant, model, q0, v0)


def main(argv: list[str] | None = None) -> None:
    """``python -m drake_abs.multibody.builder SCENE...``: print each scene's
    :func:`~drake_abs.multibody.model_files.model_report` (a shipped scene's name or a YAML
    path)."""
    names = sys.argv[1:] if argv is None else argv
    if not names:
        raise SystemExit("usage: python -m drake_abs.multibody.builder SCENE [SCENE ...]")
    for name in names:
        model = build_scene_model(name)
        print(f"scene {model.scene.name}:")
        print(format_model_report(model.model_report()))


if __name__ == "__main__":
    main()
