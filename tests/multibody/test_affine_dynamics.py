"""Plants whose dynamics are affine in the state (prismatic joints only) skip the per-state
rigid-body algorithms: their quantities, steps and Jacobians equal the general provider's, and
no plant with a rotation takes that path."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.contact.smoothing import ContactAware
from drake_abs.multibody import Scene, build_scene_model, shipped_scenes

NARROW = ("dphi", "dJn", "dJt", "dN")


def _field(quant, name: str):
    """A quantity, derivatives with all P columns (providers may give narrow ones)."""
    value = getattr(quant, name)
    return quant.full(name) if value is not None and name in NARROW else value


TRANSLATING_BOX = {
    "name": "box_translating",
    "time_step": 0.01,
    "models": [{"file": "drake_abs:models/box_translating.sdf"}],
    "contacts": [{"body": "box", "points": [[0.0, 0.0, -0.1], [0.05, 0.0, -0.1]],
                  "friction": 0.5}],
    "friction_directions": 2,
    "initial_state": {"q": [0.0, 0.1], "v": [1.0, 0.0]},
}  # fmt: skip


def _pair(dynamics: str):
    data = {**TRANSLATING_BOX, "dynamics": dynamics}
    fast = build_scene_model(Scene.from_dict(data))
    general = build_scene_model(Scene.from_dict(data))
    general.contact_model.affine = None
    return fast, general


@pytest.mark.parametrize("dynamics", ["pinocchio", "drake"])
def test_affine_quantities_equal_the_general_providers(dynamics, rng):
    fast, general = _pair(dynamics)
    assert fast.contact_model.affine is not None
    B = 5
    q = np.column_stack([rng.uniform(-1, 1, B), rng.uniform(0.05, 0.2, B)])
    v, u = rng.normal(size=(B, 2)), rng.normal(size=(B, 1))
    for active in (np.array([0, 1]), np.array([1])):
        a = fast.contact_model.quantities(q, v, u, active)
        b = general.contact_model.quantities(q, v, u, active)
        for name in ("W", "v_free", "phi", "Jn", "Jt", "N", "dv_free", "dphi", "dJn", "dJt"):
            np.testing.assert_allclose(_field(a, name), _field(b, name), atol=1e-12,
                                       err_msg=name)  # fmt: skip
        f = rng.normal(size=(B, 2))
        np.testing.assert_allclose(a.dW_dot(f), b.dW_dot(f), atol=1e-12)
    np.testing.assert_allclose(
        fast.contact_model.affine.distances(q), general.contact_model.distances(q), atol=1e-14
    )


def test_affine_steps_and_jacobians_equal_the_general_path(rng):
    fast, general = _pair("pinocchio")
    smoothing = ContactAware(1e-3, 0.02)
    x = np.column_stack([rng.uniform(-1, 1, 8), rng.uniform(0.099, 0.11, 8),
                         rng.normal(size=8), rng.normal(size=8) - 1.0])  # fmt: skip
    u = rng.normal(size=(8, 1)) * 5
    for activation in (np.inf, 0.005):  # every candidate, and a pruned set per state
        a = fast.stepper(smoothing=smoothing, activation_distance=activation).step(x, u)
        b = general.stepper(smoothing=smoothing, activation_distance=activation).step(x, u)
        assert a.converged.all() and b.converged.all()
        np.testing.assert_array_equal(a.active, b.active)
        for name in ("x_next", "impulse"):
            np.testing.assert_allclose(_field(a, name), _field(b, name), rtol=1e-9,
                                       atol=1e-11, err_msg=name)  # fmt: skip
        # a sticking contact is degenerate in the linearised cone (the opposite direction has
        # zero impulse and zero slack); the tangential compliance (1e-8 relative on the friction
        # block) resolves it, so either path's Jacobians are defined to that scale there
        for name in ("dx_dx", "dx_du", "dimpulse_dx"):
            np.testing.assert_allclose(_field(a, name), _field(b, name), rtol=1e-9,
                                       atol=1e-7, err_msg=name)  # fmt: skip


@pytest.mark.parametrize("name", shipped_scenes())
def test_no_plant_with_a_rotation_takes_the_affine_path(name):
    assert build_scene_model(name).contact_model.affine is None
