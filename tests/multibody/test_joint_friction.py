"""Dry joint friction (MJCF ``frictionloss``) as complementarity rows of the step (docs/math.md
section 6e; drake_abs/multibody/joint_friction.py): sticking below the bound, sliding at
(tau - F) / I above it, deceleration to a stop, Jacobians against central differences, MuJoCo
on the same file, tiny and huge bounds, exact and smoothed steps."""

from __future__ import annotations

import pickle
import warnings

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs.contact.smoothing import ContactAware, Exact, Fixed, GaussianMatched
from drake_abs.multibody import Scene, build_scene_model
from drake_abs.multibody.model_files import read_mjcf

H = 0.01

# a block on a horizontal rail (gravity has no effect on it), driven by a motor of gear 1
SLIDER = """<mujoco model="slider">
  <option timestep="{h}" integrator="Euler"/>
  <worldbody>
    <body name="block">
      <joint name="rail" type="slide" axis="1 0 0" frictionloss="{F}" damping="{d}"/>
      <geom type="box" size="0.1 0.1 0.1" mass="{m}"/>
    </body>
  </worldbody>
  <actuator><motor joint="rail" gear="1"/></actuator>
</mujoco>
"""

# a point-like bob of 1 kg on a massless arm of 0.5 m, hinged 0.53 m above the floor: hanging,
# its 5 cm sphere is 0.03 m above the ground; range +-1.2 rad
PENDULUM = """<mujoco model="pendulum">
  <compiler angle="radian"/>
  <option timestep="{h}" integrator="Euler"/>
  <worldbody>
    <body name="arm" pos="0 0 0.58">
      <joint name="hinge" type="hinge" axis="0 1 0" frictionloss="{F}" damping="{d}"
             range="-1.2 1.2"/>
      <geom type="sphere" pos="0 0 -0.5" size="0.05" mass="1"/>
    </body>
  </worldbody>
  <actuator><motor joint="hinge" gear="1"/></actuator>
</mujoco>
"""

I_PENDULUM = 0.5**2 + 0.4 * 0.05**2  # kg m^2 about the hinge


def _write(tmp_path, template, name, **values):
    path = tmp_path / f"{name}.xml"
    path.write_text(template.format(**{"h": H, "d": 0.0, **values}))
    return path


def _model(
    tmp_path, template, name, *, contact=None, friction_directions=2, dynamics="auto", **values
):
    path = _write(tmp_path, template, name, **values)
    body = "block" if template is SLIDER else "arm"
    point = [0.0, 0.0, 0.0] if template is SLIDER else [0.0, 0.0, -0.5]
    data = {
        "name": name, "time_step": H, "models": [{"file": str(path)}],
        "contacts": [{"body": body, "points": [point], "radius": 0.05, "friction": 0.5}],
        "ground_height": -10.0 if contact is None else contact,
        "activation_distance": 0.1, "friction_directions": friction_directions,
        "dynamics": dynamics,
    }  # fmt: skip
    return build_scene_model(Scene.from_dict(data))


SMOOTHINGS = {
    "exact": Exact(),
    "bs": Fixed(1e-7),
    "abs": ContactAware(1e-4, 0.05),
    "gauss": GaussianMatched(1e-4),
}


def _run(stepper, x, u, steps):
    xs, impulses = [np.asarray(x, float)], []
    for _ in range(steps):
        r = stepper.step(xs[-1][None], np.atleast_1d(u), jacobians=False)
        assert r.converged.all()
        xs.append(r.x_next[0])
        impulses.append(r.joint_friction_impulse[0])
    return np.array(xs), np.array(impulses)


def test_frictionloss_is_read_reported_and_pickled(tmp_path):
    sm = _model(tmp_path, SLIDER, "slider", F=2.0, d=0.0, m=1.0)
    np.testing.assert_array_equal(sm.joint_friction, [2.0])
    assert read_mjcf(tmp_path / "slider.xml").frictionloss == (("rail", 2.0),)
    (joint,) = sm.model_report()["joints"]
    assert joint["frictionloss"] == 2.0
    stepper = sm.stepper()
    assert stepper.joint_friction.names == ("rail",)
    again = pickle.loads(pickle.dumps(stepper))
    x = np.array([[0.0, 0.3]])
    np.testing.assert_array_equal(
        again.step(x, np.zeros(1), jacobians=False).x_next,
        stepper.step(x, np.zeros(1), jacobians=False).x_next,
    )
    none = sm.stepper(joint_friction=None)  # the switch turns it off
    assert none.step(x, np.zeros(1), jacobians=False).x_next[0, 1] == pytest.approx(0.3)
    dropped = read_mjcf(tmp_path / "slider.xml", ("joint.frictionloss",))
    assert dropped.frictionloss == () and dropped.dropped == (
        "joint 'rail': frictionloss=2 (dry joint friction)",
    )


def test_frictionloss_on_a_ball_joint_is_refused_and_anitescu_is_refused(tmp_path):
    path = tmp_path / "ball.xml"
    path.write_text(
        '<mujoco model="b"><worldbody><body name="b"><joint name="j" type="ball" '
        'frictionloss="3"/><geom type="sphere" size="0.1"/></body></worldbody></mujoco>'
    )
    with pytest.raises(ValueError, match="frictionloss=3 .*ball"):
        read_mjcf(path)
    sm = _model(tmp_path, SLIDER, "slider", F=2.0, d=0.0, m=1.0)
    with pytest.raises(ValueError, match="joint_friction.*stewart_trinkle"):
        sm.stepper(friction="anitescu")
    with pytest.raises(ValueError, match="joint_friction must be 1 finite numbers >= 0"):
        sm.stepper(joint_friction=np.array([-1.0]))
    # what needs the Anitescu generators of the step's rows refuses the pinned rows by name
    cone = sm.stepper().contact_problem(np.zeros((1, 2)), np.zeros(1), parameters=False).cone
    assert cone.pinned.tolist() == [False, True]  # the (far) contact, then the friction row
    with pytest.raises(ValueError, match="pinned contacts"):
        _ = cone.generators


@pytest.mark.parametrize("smoothing", ["exact", "bs", "abs", "gauss"])
def test_slider_sticks_below_the_bound_and_slides_at_the_excess_above(tmp_path, smoothing):
    """m = 2 kg, F = 3 N: a force of 2.9 N leaves the resting block at rest (exactly without
    smoothing; under barrier smoothing it creeps), 4 N accelerates it at (4 - 3) / 2 m/s^2."""
    m, F = 2.0, 3.0
    stepper = _model(tmp_path, SLIDER, "slider", F=F, d=0.0, m=m).stepper(
        smoothing=SMOOTHINGS[smoothing]
    )
    xs, p = _run(stepper, [0.0, 0.0], 2.9, 50)
    if smoothing in ("exact", "abs"):  # ABS: no contact near, so mu = mu_min = 0 here
        assert np.abs(xs).max() < 1e-8
        np.testing.assert_allclose(p, -2.9 * H, rtol=1e-8)  # the friction holds the force
    else:  # smoothed: sticking creeps (like a sticking contact), but slower than unheld
        creep = {"bs": 0.05, "gauss": 0.6}[smoothing] * (2.9 / m) * 50 * H
        assert np.abs(xs[:, 1]).max() < creep
    for u in (4.0, -4.0):
        xs, p = _run(stepper, [0.0, 0.0], u, 80)
        a = np.sign(u) * (abs(u) - F) / m
        if smoothing == "exact":
            np.testing.assert_allclose(xs[1:, 1], a * H * np.arange(1, 81), rtol=1e-8)
            np.testing.assert_allclose(p, -np.sign(u) * F * H, rtol=1e-8)
        else:  # smoothed: the friction falls short of its bound at low speed (by mu / (h v))
            np.testing.assert_allclose(np.diff(xs[-11:, 1]), a * H, rtol=0.05)
            np.testing.assert_allclose(p[-10:], -np.sign(u) * F * H, rtol=0.02)


def test_sliding_decelerates_at_the_bound_and_sticks(tmp_path):
    m, F, v0 = 1.5, 3.0, 0.5
    stepper = _model(tmp_path, SLIDER, "slider", F=F, d=0.0, m=m).stepper()
    xs, p = _run(stepper, [0.0, v0], 0.0, 40)
    stop = int(np.ceil(v0 / (H * F / m)))  # 25 steps of h F / m = 0.02 m/s
    want = np.maximum(v0 - H * F / m * np.arange(41), 0.0)
    np.testing.assert_allclose(xs[:, 1], want, atol=1e-9)
    assert np.all(np.abs(xs[stop + 1 :, 1]) < 1e-9)  # stuck
    np.testing.assert_allclose(xs[-1, 0], np.sum(want[1:]) * H, atol=1e-8)
    assert np.all(np.abs(p) <= H * F * (1 + 1e-9))


@pytest.mark.parametrize("F", [1e-6, 1e6])
@pytest.mark.parametrize("smoothing", ["exact", "bs", "abs", "gauss"])
def test_tiny_and_huge_bounds(tmp_path, F, smoothing):
    """F = 1e-6 N: the block moves as without friction (to h F per step); F = 1e6 N: it stops
    within a step and holds against any force below the bound. Every step converges."""
    m = 1.0
    sm = _model(tmp_path, SLIDER, f"slider{F:g}", F=F, d=0.0, m=m)
    stepper = sm.stepper(smoothing=SMOOTHINGS[smoothing])
    free = sm.stepper(smoothing=SMOOTHINGS[smoothing], joint_friction=None)
    x0, u = [0.0, 0.8], 5.0
    xs, p = _run(stepper, x0, u, 20)
    if F < 1:
        ref, _ = _run(free, x0, u, 20)
        np.testing.assert_allclose(xs, ref, atol=20 * H * F / m + 1e-12)
    else:
        tol = 1e-8 if smoothing == "exact" else 1e-3
        assert np.abs(xs[1:, 1]).max() < tol  # stopped in the first step
        assert p[0] == pytest.approx(-(m * 0.8 + H * u), rel=1e-6)  # what it takes to stop it


def test_pendulum_swings_until_gravity_no_longer_beats_the_friction(tmp_path):
    """Released at 1 rad with F = 1 N m: it swings, loses energy to the friction and sticks
    where the gravity torque m g l |sin(theta)| is at most F; every step converged."""
    F = 1.0
    stepper = _model(tmp_path, PENDULUM, "pendulum", F=F).stepper()
    xs, p = _run(stepper, [1.0, 0.0], 0.0, 400)
    assert np.abs(xs[-50:, 1]).max() < 1e-8  # stuck
    assert 9.81 * 0.5 * abs(np.sin(xs[-1, 0])) <= F * (1 + 1e-6)
    assert np.abs(xs[:, 0]).max() <= 1.0 + 1e-9  # friction only takes energy out
    assert np.abs(p).max() <= H * F * (1 + 1e-9)


@pytest.mark.parametrize("smoothing", ["exact", "bs", "abs", "gauss"])
@pytest.mark.parametrize(
    "state",
    [
        "slip",  # swinging, the friction at its bound
        "stick",  # at rest, the torque below the bound
        "slip_near_ground",  # ABS: mu follows the bob's distance to the ground (total mode)
    ],
)
def test_step_jacobians_match_central_differences_away_from_the_switch(tmp_path, smoothing, state):
    F = 1.5
    ground = 0.0 if state == "slip_near_ground" else None
    stepper = _model(tmp_path, PENDULUM, "pendulum", F=F, contact=ground).stepper(
        smoothing=SMOOTHINGS[smoothing]
    )
    x, u = {
        "slip": (np.array([0.4, 2.0]), np.array([0.3])),
        "stick": (np.array([0.05, 0.0]), np.array([0.4])),  # gravity 0.24 N m, plus 0.4 N m
        "slip_near_ground": (np.array([0.25, -1.5]), np.array([0.3])),
    }[state]
    r = stepper.step(x[None], u)
    assert r.converged.all()
    if state == "slip_near_ground":
        assert r.active.all()  # the bob's contact is in the LCP (not touching: under
        assert r.impulse[0, 0] < 0.02 * 9.81 * H  # smoothing a small force at a distance)
    if smoothing == "exact":
        bound = H * F
        if state == "stick":
            assert abs(r.joint_friction_impulse[0, 0]) < bound * 0.9
        else:
            assert abs(r.joint_friction_impulse[0, 0]) == pytest.approx(bound, rel=1e-8)

    def f(p):
        return stepper.step(p[None, :2], p[None, 2:], jacobians=False).x_next[0]

    fd = central_difference(f, np.concatenate([x, u]), eps=1e-7)
    analytic = np.concatenate([r.dx_dx[0], r.dx_du[0]], axis=1)
    np.testing.assert_allclose(analytic, fd, atol=1e-6 * (1 + np.abs(fd).max()))
    if smoothing == "exact" and state == "stick":  # stuck: the input does not move it
        assert np.abs(r.dx_du[0]).max() < 1e-6


@pytest.mark.parametrize("dynamics", ["pinocchio", "drake"])
def test_friction_limit_and_contact_rows_share_one_lcp(tmp_path, dynamics):
    """Swung hard into its upper stop (1.2 rad) with friction: the stop and the friction act
    in the same step, the bob never passes the stop, and the Jacobian (with a limit row and
    the friction rows in the LCP) matches central differences, with either provider."""
    stepper = _model(tmp_path, PENDULUM, "pendulum", F=0.5, dynamics=dynamics).stepper()
    x, u = np.array([1.15, 9.0]), np.array([2.0])
    r = stepper.step(x[None], u)
    assert r.converged.all() and r.limit_impulse[0, 1] > 1e-3
    assert r.x_next[0, 0] <= 1.2 + 1e-9
    assert r.joint_friction_impulse[0, 0] == pytest.approx(-0.5 * H, rel=1e-8)

    def f(p):
        return stepper.step(p[None, :2], p[None, 2:], jacobians=False).x_next[0]

    fd = central_difference(f, np.concatenate([x, u]), eps=1e-7)
    analytic = np.concatenate([r.dx_dx[0], r.dx_du[0]], axis=1)
    np.testing.assert_allclose(analytic, fd, atol=1e-6 * (1 + np.abs(fd).max()))


@pytest.mark.parametrize("k", [2, 3, 4])
def test_any_number_of_friction_directions_bounds_both_ways(tmp_path, k):
    stepper = _model(
        tmp_path, SLIDER, f"slider{k}", F=3.0, d=0.0, m=1.0, friction_directions=k
    ).stepper()
    for v in (0.5, -0.5):
        r = stepper.step(np.array([[0.0, v]]), np.zeros(1))
        assert r.joint_friction_impulse[0, 0] == pytest.approx(-np.sign(v) * 3.0 * H, rel=1e-8)


@pytest.mark.parametrize("template, x0, u", [
    (SLIDER, [0.0, 0.6], [1.0]),  # decelerates, sticks, then holds against 1 N
    (PENDULUM, [1.0, 0.0], [0.0]),  # swings down, loses energy, sticks
])  # fmt: skip
def test_against_mujoco_on_the_same_file(tmp_path, template, x0, u):
    """MuJoCo (Euler, the same time step, one mj_step per step) on the same file: MuJoCo's dry
    friction is a soft constraint (solreffriction), so it creeps slowly where ours sticks;
    the trajectories agree to about a millimetre (milliradian), and without the friction ours
    is far off."""
    pytest.importorskip("mujoco")
    from drake_abs.reference.mujoco_plant import MujocoStepper

    values = {"F": 2.0, "d": 0.0, "m": 1.0} if template is SLIDER else {"F": 1.0}
    sm = _model(tmp_path, template, "model", **values)
    mj = MujocoStepper(tmp_path / "model.xml", options={"integrator": "Euler", "contact": False})
    steps = 150
    ours, _ = _run(sm.stepper(), x0, u, steps)
    free, _ = _run(sm.stepper(joint_friction=None), x0, u, steps)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        theirs, x = [np.asarray(x0, float)], np.asarray(x0, float)
        for _ in range(steps):
            x = mj.step(x[None], np.asarray(u), jacobians=False).x_next[0]
            theirs.append(x)
    theirs = np.array(theirs)
    gap = np.abs(ours - theirs).max(axis=0)
    gap_free = np.abs(free - theirs).max(axis=0)
    # measured: slider 1.0e-3 m, 1.5e-3 m/s; pendulum 0.9e-3 rad, 4.2e-3 rad/s (MuJoCo's soft
    # friction creeps at ~1e-3 m/s or rad/s where ours sticks); without friction 1.9 m, 0.87 rad
    assert gap[0] < 3e-3 and gap[1] < 1e-2, gap
    assert gap_free[0] > 0.5, gap_free


@pytest.mark.parametrize("state", ["slip", "stick"])
def test_model_parameter_columns_with_joint_friction_match_central_differences(tmp_path, state):
    """The theta block with the friction rows in the LCP (their cone rows padded into the
    friction-coefficient block): the bob's mass, the joint's damping and the bob's contact
    friction and radius, against steppers with the parameter moved."""
    stepper = _model(tmp_path, PENDULUM, "pendulum", F=1.5, d=0.2, contact=0.0).stepper()
    x, u = {"slip": (np.array([0.3, -1.5]), np.array([0.3])),
            "stick": (np.array([0.05, 0.0]), np.array([0.4]))}[state]  # fmt: skip
    names = ("mass[arm]", "damping[hinge]", "friction[0]", "radius[0]", "ground_height")
    r = stepper.step(x[None], u, parameters=names)
    assert r.converged.all()
    values = dict(zip(stepper.parameter_names, stepper.parameter_values(), strict=True))
    eps = 1e-6
    for j, name in enumerate(names):
        plus = stepper.with_parameters({name: values[name] + eps}).step(x[None], u)
        minus = stepper.with_parameters({name: values[name] - eps}).step(x[None], u)
        fd = (plus.x_next[0] - minus.x_next[0]) / (2 * eps)
        np.testing.assert_allclose(r.dx_dtheta[0, :, j], fd, rtol=1e-6, atol=1e-8, err_msg=name)
