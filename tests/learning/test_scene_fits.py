"""The scene parameter fits (drake_abs/learning/scene_fits.py): the learned names of the shipped
scenes, a seeded start off the file's values within its bounds, and every fit lowering its loss
on data of the scene's own model from that start, the ground height moving back toward the
file's."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.learning.scene_fits import (
    FITS,
    fit_parameters,
    learned_names,
    perturbed_start,
)
from drake_abs.learning.scene_losses import learned_values, stepper_at
from drake_abs.multibody import build_scene_model


@pytest.fixture(scope="module")
def box():
    return build_scene_model("box_push").stepper()


def test_learned_names(box):
    assert learned_names(box) == ["ground_height", "friction[*]", "mass[box]"]
    hopper = build_scene_model("gym_hopper").stepper()
    names = learned_names(hopper)
    assert names[:2] == ["ground_height", "friction[*]"]
    assert [n for n in names if n.startswith("mass[")] == [
        "mass[torso]", "mass[thigh]", "mass[leg]", "mass[foot]"
    ]  # fmt: skip
    damped = [n for n in names if n.startswith("damping[")]
    values = learned_values(hopper, damped)
    assert damped and np.all(values > 0)  # only the joints the file damps


def test_perturbed_start_is_seeded_off_the_file_within_bounds(box):
    names = learned_names(box) + ["damping[free]"]
    truth = np.array([0.0, 0.5, 1.0, 0.0])
    start, scale, lo, hi = perturbed_start(names, truth, ground_offset=0.02, perturbation=0.3,
                                           rng=np.random.default_rng(0))  # fmt: skip
    again = perturbed_start(names, truth, ground_offset=0.02, perturbation=0.3,
                            rng=np.random.default_rng(0))  # fmt: skip
    for a, b in zip((start, scale, lo, hi), again, strict=True):
        np.testing.assert_array_equal(a, b)
    assert start[0] == 0.02 and scale[0] == 0.01 and (lo[0], hi[0]) == (-0.2, 0.2)
    factors = start[1:3] / truth[1:3]
    assert np.all((np.abs(factors - 1) >= 0.15 - 1e-12) & (np.abs(factors - 1) <= 0.3 + 1e-12))
    assert start[3] == 0.5 and (lo[3], hi[3]) == (0.0, 10.0)  # an undamped joint starts at 0.5
    assert np.all((lo <= start) & (start <= hi) & (scale > 0))
    with pytest.raises(ValueError, match="truth"):
        perturbed_start(names, truth[:2], ground_offset=0.02, perturbation=0.3,
                        rng=np.random.default_rng(0))  # fmt: skip


def _box_data(box, n: int = 30):
    """Transitions of the box's own model from tilted, lifted states under pushes."""
    rng = np.random.default_rng(1)
    x = np.zeros((n, 6))
    x[:, 1] = 0.1 + rng.uniform(0.0, 0.01, n)  # the half height: the corners at the ground
    x[:, 2] = rng.uniform(-0.05, 0.05, n)
    x[:, 1] += 0.2 * np.abs(np.sin(x[:, 2]))
    x[:, 3:] = rng.uniform(-0.5, 0.5, (n, 3))
    u = rng.uniform(-10.0, 10.0, (n, 1))
    return x, u, box.step(x, u, jacobians=False).x_next


@pytest.mark.parametrize("fit", FITS)
def test_every_fit_lowers_its_loss(box, fit):
    x, u, x_next = _box_data(box)
    names = learned_names(box)
    truth = learned_values(box, names)
    start, scale, lo, hi = perturbed_start(names, truth, ground_offset=0.02, perturbation=0.3,
                                           rng=np.random.default_rng(0))  # fmt: skip
    result = fit_parameters(box, x, u, x_next, fit, names, start, scale, lo, hi,
                            search_iterations=3, search_directions=2, gradient_iterations=5,
                            max_transitions=20, seed=2)  # fmt: skip
    assert result.loss < result.start_loss
    assert np.all((lo <= result.theta) & (result.theta <= hi))
    assert abs(result.theta[0] - truth[0]) < abs(start[0] - truth[0])  # the ground comes back
    assert stepper_at(box, names, result.theta) is not None


def test_unknown_fit_is_named(box):
    x, u, x_next = _box_data(box, 4)
    names = ["ground_height"]
    with pytest.raises(ValueError, match="fit must be one of"):
        fit_parameters(box, x, u, x_next, "adam", names, [0.0], [0.01], [-1.0], [1.0])
