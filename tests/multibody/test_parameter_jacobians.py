"""Derivatives of a rigid-body step with respect to model parameters theta (the ground height,
each contact's friction coefficient, each body's mass): their own named block (``dx_dtheta``,
``theta_names``), never mixed into dx_du, and equal to central differences of steps of re-built
scenes (for the mass: the model file re-written with the mass and inertia scaled)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scene_variants import with_friction, with_mass

from drake_abs.contact.smoothing import ContactAware, Exact
from drake_abs.multibody import Scene, build_scene_model

EPS = 1e-6


def _states(name: str, model):
    """A state in contact (sliding, for the box and the ball), and an input, per scene."""
    if name == "box_push":  # resting on its two bottom corners, sliding at 1 m/s, pushed
        return model.x0, np.full(model.contact_model.nu, 3.0)
    if name == "hopper":  # the foot 5 cm up, falling at 6 m/s: lands within the step; torques
        x = model.x0.copy()
        x[model.contact_model.nq + 1] = -6.0
        return x, np.array([4.0, -3.0])
    x = model.x0.copy()  # ball_throw: the ball just above the ground, moving down and sideways
    # (q = (qw, qx, qy, qz, x, y, z), v = (wx, wy, wz, vx, vy, vz)); too fast to roll in a step
    x[6], x[10], x[11], x[12] = 0.0505, 3.0, 1.0, -0.6
    return x, np.zeros(model.contact_model.nu)


def _next_state(scene: Scene, smoothing, x, u) -> np.ndarray:
    step = build_scene_model(scene).stepper(smoothing=smoothing).step(x[None], u, jacobians=False)
    assert step.converged.all()
    return step.x_next[0]


# which derivatives must be non-zero here (the physics says so; "non-zero" is above 1e-5, far
# above the central differences' noise of about 1e-9): a free ball's step does not depend on
# its mass (every impulse scales with it); the hopper's foot sticks on landing
DEPENDS = {
    "box_push": {"ground", "friction", "mass"},
    "ball_throw": {"ground", "friction"},
    "hopper": {"ground", "mass"},
}


# (scene, friction formulation): Anitescu's generators move with the friction coefficients
CASES = [(name, "stewart_trinkle") for name in sorted(DEPENDS)] + [
    ("box_push", "anitescu"),
    ("ball_throw", "anitescu"),
]


@pytest.mark.parametrize("name, friction", CASES, ids=["-".join(c) for c in CASES])
@pytest.mark.parametrize("smoothing", [Exact(), ContactAware(1e-3, 0.02)], ids=["exact", "abs"])
def test_parameter_jacobians_match_central_differences(name, friction, smoothing, tmp_path):
    scene = replace(Scene.load(name), friction_model=friction)
    model = build_scene_model(scene)
    stepper = model.stepper(smoothing=smoothing)
    x, u = _states(name, model)
    r = stepper.step(x[None], u, parameters=True)
    assert r.converged.all() and r.active.any()
    names = stepper.parameter_names
    assert r.theta_names == names and names[0] == "ground_height"
    nc = len(model.contact_model.contacts)
    assert names[1 : 1 + nc] == tuple(f"friction[{i}]" for i in range(nc))  # all frictional
    bodies = model.contact_model.massive_bodies  # the floating base's chain is massless
    assert names[1 + nc : 1 + nc + len(bodies)] == tuple(f"mass[{b}]" for b in bodies)
    # after them: radii, joint damping, offsets (tests/multibody/test_model_parameters_extended.py)
    assert names[1 + nc + len(bodies)].startswith("radius[")
    nx = x.size
    assert r.dx_dtheta.shape == (1, nx, len(names)) and r.dx_du.shape == (1, nx, u.size)
    assert r.dimpulse_dtheta.shape == (1, nc, len(names))
    scale = 1.0 + np.abs(r.dx_dtheta[0, :, : 1 + nc + len(bodies)]).max()  # the columns here
    # ground height
    fd = (
        _next_state(replace(scene, ground_height=scene.ground_height + EPS), smoothing, x, u)
        - _next_state(replace(scene, ground_height=scene.ground_height - EPS), smoothing, x, u)
    ) / (2 * EPS)
    assert np.abs(fd).max() > 1e-5 or "ground" not in DEPENDS[name]
    np.testing.assert_allclose(r.dx_dtheta[0, :, 0], fd, atol=1e-5 * scale)
    # friction: one spec moves the coefficient of all its points (the sum of their columns)
    start = 0
    for k, spec in enumerate(scene.contacts):
        cols = [1 + start + j for j in range(len(spec.points))]
        start += len(spec.points)
        fd = (
            _next_state(with_friction(scene, k, EPS), smoothing, x, u)
            - _next_state(with_friction(scene, k, -EPS), smoothing, x, u)
        ) / (2 * EPS)
        assert np.abs(fd).max() > 1e-5 or "friction" not in DEPENDS[name]
        np.testing.assert_allclose(r.dx_dtheta[0][:, cols].sum(axis=1), fd, atol=1e-5 * scale)
    # each mass: scaled by 1 +- eps / m
    for j, body in enumerate(bodies):
        m = model.plant.GetBodyByName(body).default_mass()
        fd = (
            _next_state(with_mass(scene, body, 1 + EPS / m, tmp_path), smoothing, x, u)
            - _next_state(with_mass(scene, body, 1 - EPS / m, tmp_path), smoothing, x, u)
        ) / (2 * EPS)
        assert np.abs(fd).max() > 1e-5 or "mass" not in DEPENDS[name]
        np.testing.assert_allclose(r.dx_dtheta[0, :, 1 + nc + j], fd, atol=1e-5 * scale)


def test_parameter_jacobians_in_free_flight_are_zero_and_need_jacobians():
    model = build_scene_model("ball_throw")
    stepper = model.stepper()
    r = stepper.step(model.x0[None], np.zeros(model.contact_model.nu), parameters=True)
    assert not r.active.any() and not r.dx_dtheta.any()
    with pytest.raises(ValueError, match="jacobians"):
        stepper.step(model.x0[None], np.zeros(model.contact_model.nu), jacobians=False,
                     parameters=True)  # fmt: skip


@pytest.mark.parametrize(("name", "iz"), [("box_push", 1), ("ball_throw", 6)])
@pytest.mark.parametrize("smoothing", [Exact(), ContactAware(1e-3, 0.02)], ids=["exact", "abs"])
def test_parameter_jacobians_match_independent_identities(name, iz, smoothing):
    """Independent of central differences, from the state Jacobians (themselves checked against
    Drake AutoDiffXd and differences elsewhere): raising the flat ground by d is lowering the
    body by d and shifting the result up by d, so dx+/dh = -dx+/dz + e_z; for the box (one
    body, all its inertia scaled with the mass) a heavier box is a weaker push,
    dx+/dm = -(dx+/du u) / m."""
    model = build_scene_model(name)
    stepper = model.stepper(smoothing=smoothing)
    x, u = _states(name, model)
    r = stepper.step(x[None], u, parameters=True)
    want = -r.dx_dx[0][:, iz].copy()
    want[iz] += 1.0
    np.testing.assert_allclose(r.dx_dtheta[0][:, 0], want, rtol=1e-9, atol=1e-12)
    if name == "box_push":
        m = model.plant.GetBodyByName("box").default_mass()
        np.testing.assert_allclose(
            r.dx_dtheta[0][:, r.theta_names.index("mass[box]")],
            -(r.dx_du[0] @ u) / m,
            rtol=1e-8,
            atol=1e-12,
        )


def test_bodies_of_the_same_name_in_two_instances_get_their_own_mass_parameters():
    """Two copies of one model file: each body's mass is its own, qualified parameter, and each
    copy's step depends on its own mass only."""
    from drake_abs.multibody import Scene

    box = {"file": "drake_abs:models/box_translating.sdf"}
    scene = Scene.from_dict({
        "name": "two_boxes", "time_step": 0.01,
        "models": [{**box, "name": "a"}, {**box, "name": "b"}],
        "contacts": [{"body": "box", "model": m, "points": [[0.0, 0.0, -0.1]], "friction": 0.5}
                     for m in ("a", "b")],
    })  # fmt: skip
    model = build_scene_model(scene)
    stepper = model.stepper()
    names = stepper.parameter_names
    assert "mass[a::box]" in names and "mass[b::box]" in names and len(set(names)) == len(names)
    x = np.zeros(model.x0.size)
    x[[1, 3]] = 0.1  # both resting on the ground (q = x_a, z_a, x_b, z_b)
    u = np.array([20.0, -5.0])  # pushed, both sliding
    r = stepper.step(x[None], u, parameters=True)
    assert r.converged.all()
    a, b = names.index("mass[a::box]"), names.index("mass[b::box]")
    va, vb = model.contact_model.nq + 0, model.contact_model.nq + 2  # their x velocities
    assert abs(r.dx_dtheta[0, va, a]) > 1e-4 and abs(r.dx_dtheta[0, vb, b]) > 1e-4
    assert r.dx_dtheta[0, va, b] == 0.0 and r.dx_dtheta[0, vb, a] == 0.0
