"""The mechanical energy of a plant's states (multibody.energy): a falling ball's is m g z plus
m v^2 / 2, batched or one state, and bad shapes are refused."""

import numpy as np
import pytest

from drake_abs.multibody import build_scene_model
from drake_abs.multibody.energy import mechanical_energy
from drake_abs.reference.comparison_scenes import ComparisonScenes


def test_a_balls_energy_is_potential_plus_kinetic():
    plant = build_scene_model(ComparisonScenes().scene("ball")).plant
    mass = plant.CalcTotalMass(plant.CreateDefaultContext())
    xs = np.zeros((3, 12))
    xs[:, 2] = [0.3, 0.1, 0.05]  # height (m)
    xs[:, 7] = [0.0, 1.0, -2.0]  # v_y (m/s)
    g = -plant.gravity_field().gravity_vector()[2]
    expected = mass * g * xs[:, 2] + 0.5 * mass * xs[:, 7] ** 2
    np.testing.assert_allclose(mechanical_energy(plant, xs), expected, rtol=1e-12)
    assert mechanical_energy(plant, xs[1]) == pytest.approx(expected[1], rel=1e-12)
    with pytest.raises(ValueError, match="xs must be"):
        mechanical_energy(plant, xs[:, :6])
