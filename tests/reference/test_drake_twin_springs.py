"""The Drake twin of a scene with joint springs (gym_half_cheetah) carries the same springs as
the step (Drake's RevoluteSpring force elements), so comparisons stay on one model."""

from __future__ import annotations

import numpy as np
from pydrake.multibody.tree import ForceElementIndex, RevoluteSpring

from drake_abs.multibody import Scene, build_scene_model
from drake_abs.reference.drake_plant import DrakePlantStepper


def test_half_cheetah_twin_has_the_steps_springs_and_swings_like_it():
    scene = Scene.load("gym_half_cheetah")
    stepper = build_scene_model(scene).stepper()
    twin = DrakePlantStepper(scene, "sap")
    plant = twin.twin.plant
    springs = {}
    for i in range(plant.num_force_elements()):
        element = plant.get_force_element(ForceElementIndex(i))
        if isinstance(element, RevoluteSpring):
            springs[element.joint().velocity_start()] = (
                element.default_stiffness(), element.default_nominal_angle()
            )  # fmt: skip
    on = np.flatnonzero(stepper.springs.stiffness)
    assert sorted(springs) == on.tolist()
    for v in on:
        assert springs[v] == (stepper.springs.stiffness[v], stepper.springs.reference[v])
    # suspended 5 m up with bent legs: both swing the legs back towards 0 on the springs
    q0 = np.array([0.0, 5.0, 0.05, 0.4, -0.4, 0.3, -0.5, 0.5, -0.3])
    a = b = np.concatenate([q0, np.zeros(9)])
    for _ in range(60):
        a = stepper.step(a[None], np.zeros(6), jacobians=False).x_next[0]
        b = twin.step(b[None], np.zeros(6), jacobians=False).x_next[0]
    assert np.abs(a[3:9]).max() < 0.05 and np.abs(b[3:9]).max() < 0.05
    # measured 0.016 rad: the twin's spring force is explicit, ours implicit (first order in h)
    assert np.abs(a[3:9] - b[3:9]).max() < 0.03
