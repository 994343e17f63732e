"""The model parameters after the ground height, the friction coefficients and the masses
(docs/math.md section 6d): each point candidate's radius, each one-velocity joint's damping and
each point candidate's offset ``p_BC``. Every new column of ``dx_dtheta`` and
``dimpulse_dtheta`` against central differences of steps (the next state and the normal
impulses) of the model with that parameter changed (a contact model re-built with the
candidate's radius or offset moved; a scene re-built from a model file with the joint's damping
re-written), for exact and smoothed contact, both friction formulations and both dynamics
providers, at states away from contact-mode switches.

A parameter at the edge of its range (a radius or a damping of 0) is differenced one-sidedly, to
second order, ``(-3 f(0) + 4 f(e) - f(2 e)) / (2 e)``: a model with a negative radius or damping
is never built.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scene_variants import contact_state, with_joint_damping

from drake_abs.contact.smoothing import Exact, Fixed
from drake_abs.multibody import ComplementarityStepper, Scene, build_scene_model
from drake_abs.multibody.drake_dynamics import PointContact

#: the differences' step for lengths (m)
EPS = 1e-6
#: and for damping (N m s / rad, N s / m; values of order 1): the quotients' error is rounding
#: down to steps of 1e-4 (it scales as 1 / step: for gym_hopper's smallest damping column,
#: 0.0016, one-sided, 3e-8, 1.5e-9, 1e-10 at steps 1e-6, 1e-5, 1e-4), so 1e-5
EPS_DAMPING = 1e-5
#: relative agreement demanded of every column (against its largest entry)
RTOL = 1e-5
#: an absolute floor for the differences' rounding: a step's x+ and impulses are O(1) and
#: exact to about 1e-14 (the interior point's solve), so a quotient with step 1e-6 carries
#: about 1e-8
FLOOR = 1e-8
#: and one relative to the largest entry of the step's columns checked: the friction rows'
#: regularization (a relative 1e-8 of their diagonal, docs/math.md section 6b) is held
#: constant when differentiating, as in every Jacobian of the step, while it moves with the
#: geometry; where the exact derivative is 0 (a sliding box's corner moved along its slide,
#: under Anitescu) the columns show it: both it and the difference are O(1e-7), proportional
#: to the regularization (measured: 1e-10 and 1e-6 scale them by 1e-2 and 1e2)
STEP_FLOOR = 1e-9


def _states(name: str, model) -> tuple[np.ndarray, np.ndarray]:
    """A state in contact and an input, per scene (none at a contact-mode switch)."""
    return contact_state(name, model)


def _difference(f, value: float, eps: float = EPS) -> np.ndarray:
    """df/dd at d = 0 for a parameter at ``value``: central, or one-sided (second order) when
    ``value`` is 0 (the lower end of its range), with step ``eps``."""
    if value == 0.0:
        return (-3.0 * f(0.0) + 4.0 * f(eps) - f(2.0 * eps)) / (2.0 * eps)
    return (f(eps) - f(-eps)) / (2.0 * eps)


def _check(analytic: np.ndarray, fd: np.ndarray, name: str, block: float) -> None:
    """Assert the column ``analytic`` matches ``fd`` to RTOL of its largest entry, above the
    floors (FLOOR, and STEP_FLOOR of ``block``, the largest entry of the columns checked)."""
    scale = np.abs(fd).max()
    err = np.abs(analytic - fd).max()
    assert err <= RTOL * scale + FLOOR + STEP_FLOOR * block, (
        f"{name}: error {err:.3g}, largest entry {scale:.3g}"
    )


def _stacked(step) -> np.ndarray:
    """A one-state step's next state and normal impulses stacked, (nx + nc, 1); with parameter
    Jacobians, their columns (nx + nc, T) instead."""
    if step.dx_dtheta is not None:
        return np.concatenate([step.dx_dtheta[0], step.dimpulse_dtheta[0]])
    return np.concatenate([step.x_next[0], step.impulse[0]])[:, None]


def _with_contacts(model, stepper: ComplementarityStepper, contacts) -> ComplementarityStepper:
    """``stepper`` on a contact model of the same provider re-built with ``contacts``."""
    cm = model.contact_model
    rebuilt = type(cm)(model.plant, contacts, cm.ground, cm.h, cm.cone.directions)
    return ComplementarityStepper(
        rebuilt, stepper.smoothing, stepper.gradient, stepper.activation_distance, stepper.friction
    )


def _moved(contact: PointContact, which: str, delta: float) -> PointContact:
    """The candidate with its radius (``which="radius"``) or offset coordinate ``"x"``, ``"y"``,
    ``"z"`` moved by delta (m)."""
    if which == "radius":
        return replace(contact, radius=contact.radius + delta)
    p = list(contact.p_BC)
    p["xyz".index(which)] += delta
    return replace(contact, p_BC=tuple(p))


def _geometry_parameter(name: str) -> tuple[int, str]:
    """``"radius[3]"`` -> (3, "radius"); ``"offset[3].y"`` -> (3, "y")."""
    i = int(name[name.index("[") + 1 : name.index("]")])
    return i, "radius" if name.startswith("radius") else name[-1]


SCENES = ("box_push", "ball_throw", "hopper", "gym_hopper")


@pytest.mark.parametrize("name", SCENES)
def test_parameter_names_are_unique_and_values_follow_them(name):
    model = build_scene_model(name)
    cm = model.contact_model
    stepper = model.stepper()
    names, values = stepper.parameter_names, stepper.parameter_values()
    assert len(set(names)) == len(names) and values.shape == (len(names),)
    assert np.isfinite(values).all()
    nc, nb = len(cm.contacts), len(cm.massive_bodies)
    points = cm.point_contacts
    assert points.tolist() == list(range(nc))  # every candidate here is a point or sphere
    # the order: ground, friction, masses, radii, damping, offsets, unit inertias
    start = 1 + nc + nb
    assert names[start : start + nc] == tuple(f"radius[{i}]" for i in range(nc))
    np.testing.assert_array_equal(values[start : start + nc], [c.radius for c in cm.contacts])
    joints = [cm.plant.get_joint(j) for j in cm.plant.GetJointIndices()]
    one_dof = [j for j in joints if j.num_velocities() == 1]
    damping = names[start + nc : start + nc + len(one_dof)]
    assert damping == tuple(f"damping[{j.name()}]" for j in one_dof)
    np.testing.assert_array_equal(
        values[start + nc : start + nc + len(one_dof)],
        [j.default_damping_vector()[0] for j in one_dof],
    )
    start += nc + len(one_dof)
    offsets = names[start : start + 3 * nc]
    assert offsets == tuple(f"offset[{i}].{a}" for i in range(nc) for a in "xyz")
    np.testing.assert_array_equal(
        values[start : start + 3 * nc], np.reshape([c.p_BC for c in cm.contacts], -1)
    )
    # after them (so that the columns before keep their indices): each body's unit inertia
    # about its centre of mass (m^2), its rotational inertia about the centre of mass over its
    # mass; then the joint springs' stiffness and reference, last
    inertias = names[start + 3 * nc : start + 3 * nc + 6 * nb]
    entries = ("xx", "yy", "zz", "xy", "xz", "yz")
    assert inertias == tuple(f"unit_inertia[{b}].{e}" for b in cm.massive_bodies for e in entries)
    ctx = cm.plant.CreateDefaultContext()
    for k, body in enumerate(cm.massive_bodies):
        M = cm.plant.GetBodyByName(body).CalcSpatialInertiaInBodyFrame(ctx)
        I_com = M.Shift(M.get_com()).CalcRotationalInertia().CopyToFullMatrix3()
        want = I_com[[0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]] / M.get_mass()
        got = values[start + 3 * nc + 6 * k : start + 3 * nc + 6 * (k + 1)]
        np.testing.assert_allclose(got, want, rtol=1e-14, atol=1e-18)
    springs = names[start + 3 * nc + 6 * nb :]
    assert springs == tuple(f"stiffness[{j.name()}]" for j in one_dof) + tuple(
        f"springref[{j.name()}]" for j in one_dof
    )
    np.testing.assert_array_equal(values[start + 3 * nc + 6 * nb :], 0.0)  # no spring here
    # without joint damping (springs) in the step, damping (stiffness) is no parameter
    undamped = ComplementarityStepper(cm, damping=False)
    assert not any(n.startswith("damping[") for n in undamped.parameter_names)
    assert undamped.parameter_values().shape == (len(undamped.parameter_names),)
    unsprung = ComplementarityStepper(cm, springs=False)
    assert not any(n.startswith(("stiffness[", "springref[")) for n in unsprung.parameter_names)
    assert unsprung.parameter_names == names[: len(names) - 2 * len(one_dof)]


@pytest.mark.parametrize("dynamics", ["pinocchio", "drake"])
@pytest.mark.parametrize("name", ["box_push", "ball_throw", "hopper"])
def test_point_geometry_derivatives_match_differences_of_the_rows(name, dynamics):
    """The provider's rows (phi, Jn, Jt) are affine in a candidate's radius and offset: their
    derivatives against central differences of the rows of re-built contact models, to
    rounding. The radius does not move the normal row (n . (n x w) = 0), only the tangent rows
    (the witness point's lever arm); at a body orientation other than the identity."""
    model = build_scene_model(replace(Scene.load(name), dynamics=dynamics))
    cm = model.contact_model
    x, u = _states(name, model)
    if name == "ball_throw":  # a general orientation
        quat = np.array([0.9, 0.2, -0.3, 0.25])
        x[:4] = quat / np.linalg.norm(quat)
    q, v, u = x[None, : cm.nq], x[None, cm.nq :], u[None]
    active = np.arange(len(cm.contacts))
    dphi, dJn, dJt = cm.point_parameter_derivatives(q, active)
    # the candidate of each tangent row (k per frictional candidate)
    owner = np.repeat(np.flatnonzero(~np.isnan(cm.cone.coefficients)), cm.cone.directions)
    assert dJt.shape[1] == owner.size
    assert np.abs(dJn[..., 0]).max() < 1e-14  # the radius leaves Jn alone
    assert np.abs(dJt[..., 0]).max() > 1e-3  # but moves Jt (rolling)
    for i in range(len(cm.contacts)):
        for c, which in enumerate(("radius", "x", "y", "z")):

            def rows(d, i=i, which=which):
                contacts = list(cm.contacts)
                contacts[i] = _moved(contacts[i], which, d)
                other = type(cm)(model.plant, contacts, cm.ground, cm.h, cm.cone.directions)
                s = other.quantities(q, v, u, active, derivatives=False)
                return s.phi[0], s.Jn[0], s.Jt[0]

            # each row depends on its own candidate's geometry only
            own_n, own_t = (active == i)[:, None], (owner == i)[:, None]
            want = (dphi[0, :, c] * own_n[:, 0], dJn[0, ..., c] * own_n, dJt[0, ..., c] * own_t)
            plus, minus = rows(EPS), rows(-EPS)
            for k, got in enumerate(want):
                fd = (plus[k] - minus[k]) / (2 * EPS)
                np.testing.assert_allclose(got, fd, rtol=0, atol=1e-8, err_msg=f"{i} {which}")


@pytest.mark.parametrize("dynamics", ["pinocchio", "drake"])
@pytest.mark.parametrize("friction", ["stewart_trinkle", "anitescu"])
@pytest.mark.parametrize("smoothing", [Exact(), Fixed(1e-3)], ids=["exact", "fixed"])
@pytest.mark.parametrize("name", ["box_push", "ball_throw", "hopper", "gym_hopper"])
def test_radius_and_offset_columns_match_central_differences(name, smoothing, friction, dynamics):
    """(gym_hopper: with joint damping, and joint-limit rows in the same LCP, after the
    contacts.)"""
    scene = replace(Scene.load(name), dynamics=dynamics, friction_model=friction)
    model = build_scene_model(scene)
    cm = model.contact_model
    stepper = model.stepper(smoothing=smoothing)
    x, u = _states(name, model)
    r = stepper.step(x[None], u, parameters=True)
    assert r.converged.all() and r.active.any()
    names = stepper.parameter_names
    columns = [j for j, n in enumerate(names) if n.startswith(("radius[", "offset["))]
    assert len(columns) == 4 * len(cm.contacts)
    analytic = _stacked(r)
    block = np.abs(analytic[:, columns]).max()
    touching = r.impulse[0] > 1e-6  # (an active candidate may stay clear of the ground)
    assert touching.any()
    for j in columns:
        i, which = _geometry_parameter(names[j])

        def f(d, i=i, which=which):
            contacts = list(cm.contacts)
            contacts[i] = _moved(contacts[i], which, d)
            step = _with_contacts(model, stepper, contacts).step(x[None], u, jacobians=False)
            assert step.converged.all()
            return _stacked(step)[:, 0]

        value = cm.contacts[i].radius if which == "radius" else 1.0  # offsets: any sign
        fd = _difference(f, value)
        _check(analytic[:, j], fd, names[j], block)
        if not r.active[0, i]:  # a candidate out of the LCP moves nothing (to rounding)
            assert not analytic[:, j].any() and np.abs(fd).max() < FLOOR
        elif which == "radius" and touching[i]:  # the parameters matter here
            assert np.abs(fd).max() > 1e-2
    # the radius moves the tangent rows: its column is not the ground height's (which moves
    # the distance alone, as the radius does, by -1)
    for i in np.flatnonzero(touching):
        rolling = r.dx_dtheta[0, :, names.index(f"radius[{i}]")] - r.dx_dtheta[0, :, 0]
        assert np.abs(rolling).max() > 1e-2


@pytest.mark.parametrize("name", ["ball_throw", "hopper"])
def test_moving_the_point_along_the_normal_is_shrinking_the_radius(name):
    """Consistency of the geometry columns: the witness point ``p_BC - r R^T n`` and the
    distance ``n . R p_BC - r`` (plus terms free of both) depend on p_BC and r through
    ``p_BC - r R^T n`` only, so moving p_BC by ``R^T n`` is shrinking r: ``sum_a (R^T n)_a
    d/d offset_a = -d/d radius``, at a pitched foot and a turned ball."""
    model = build_scene_model(name)
    cm = model.contact_model
    stepper = model.stepper(smoothing=Fixed(1e-3))
    x, u = _states(name, model)
    if name == "ball_throw":
        quat = np.array([0.9, 0.2, -0.3, 0.25])
        x[:4] = quat / np.linalg.norm(quat)
    r = stepper.step(x[None], u, parameters=True)
    names, D = r.theta_names, r.dx_dtheta[0]
    ctx = model.plant.CreateDefaultContext()
    model.plant.SetPositions(ctx, x[: cm.nq])
    i = 0
    body = model.plant.GetBodyByName(cm.contacts[i].body)
    a = model.plant.EvalBodyPoseInWorld(ctx, body).rotation().matrix().T @ cm.normal
    along = sum(a[k] * D[:, names.index(f"offset[{i}].{axis}")] for k, axis in enumerate("xyz"))
    radius = D[:, names.index(f"radius[{i}]")]
    assert np.abs(radius).max() > 1.0
    np.testing.assert_allclose(along, -radius, rtol=1e-10, atol=1e-10 * np.abs(radius).max())


DAMPING_CASES = [
    ("gym_hopper", "stewart_trinkle", "pinocchio"),  # damping 1 on the legs, 0 on the base
    ("gym_hopper", "stewart_trinkle", "drake"),
    ("gym_hopper", "anitescu", "pinocchio"),
    ("hopper", "stewart_trinkle", "pinocchio"),  # no damping: the step skips it (W' = W)
    ("hopper", "stewart_trinkle", "drake"),
]


@pytest.mark.parametrize("smoothing", [Exact(), Fixed(1e-3)], ids=["exact", "fixed"])
@pytest.mark.parametrize(
    "name, friction, dynamics", DAMPING_CASES, ids=["-".join(c) for c in DAMPING_CASES]
)
def test_damping_columns_match_central_differences(name, friction, dynamics, smoothing, tmp_path):
    """Each joint's damping column against steps of scenes whose model file gives that joint
    another damping (the other parameters' derivatives are carried to the damped step first,
    then these columns are added)."""
    scene = replace(Scene.load(name), dynamics=dynamics, friction_model=friction)
    model = build_scene_model(scene)
    stepper = model.stepper(smoothing=smoothing)
    assert stepper._damps == (name == "gym_hopper")  # hopper: every damping is 0
    x, u = _states(name, model)
    r = stepper.step(x[None], u, parameters=True)
    assert r.converged.all() and r.active.any()
    names = stepper.parameter_names
    values = stepper.parameter_values()
    joints = [n[len("damping[") : -1] for n in names if n.startswith("damping[")]
    assert len(joints) == model.contact_model.nv  # every joint of these has one velocity
    analytic = _stacked(r)
    block = np.abs(analytic[:, [names.index(f"damping[{j}]") for j in joints]]).max()
    largest = 0.0
    for joint in joints:
        j = names.index(f"damping[{joint}]")

        def f(d, joint=joint, value=values[j]):
            other = with_joint_damping(scene, joint, value + d, tmp_path)
            step = (
                build_scene_model(other)
                .stepper(smoothing=smoothing)
                .step(x[None], u, jacobians=False)
            )
            assert step.converged.all()
            return _stacked(step)[:, 0]

        fd = _difference(f, values[j], EPS_DAMPING)
        _check(analytic[:, j], fd, names[j], block)
        largest = max(largest, np.abs(fd).max())
    assert largest > 1e-3  # damping matters here
