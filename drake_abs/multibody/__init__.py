"""Rigid-body scenes: scene files, the MultibodyPlant or pinocchio dynamics of a scene's models,
and the batched complementarity step built on them (needs pydrake and pinocchio).

Start from ``make_stepper("box_push")`` or ``build_scene_model(Scene.load("box_push"))``.
"""

from drake_abs.multibody.builder import SceneModel, build_scene_model, make_stepper
from drake_abs.multibody.packages import PACKAGE_DIR
from drake_abs.multibody.scene import ContactSpec, ModelSpec, Scene, shipped_scenes
from drake_abs.multibody.stepper import (
    ComplementarityStepper,
    ExplicitSpringWarning,
    StepOverflowWarning,
)
from drake_abs.multibody.unmodelled_geometry import (
    InitialPenetrationWarning,
    UnmodelledPenetrationWarning,
)

__all__ = [
    "PACKAGE_DIR",
    "ComplementarityStepper",
    "ContactSpec",
    "InitialPenetrationWarning",
    "ModelSpec",
    "Scene",
    "SceneModel",
    "ExplicitSpringWarning",
    "StepOverflowWarning",
    "UnmodelledPenetrationWarning",
    "build_scene_model",
    "make_stepper",
    "shipped_scenes",
]
