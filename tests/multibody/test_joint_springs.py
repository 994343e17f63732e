"""Joint springs in the step (docs/math.md section 6c): read from SDF (``spring_stiffness``) and
MJCF (``stiffness``, ``springref``) files, taken implicitly like the damping, against the closed
form of implicit Euler, central differences, both dynamics providers and MuJoCo."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs.contact.damping import JointSprings, implicit_damping
from drake_abs.contact.smoothing import ContactAware, Exact
from drake_abs.multibody import Scene, build_scene_model
from drake_abs.multibody.joint_limits import joint_damping, joint_springs
from drake_abs.multibody.model_files import read_mjcf

H = 0.01

SLIDER = """<?xml version="1.0"?>
<sdf version="1.9">
  <model name="slider">
    <link name="block">
      <inertial><mass>{mass}</mass>
        <inertia><ixx>0.01</ixx><iyy>0.01</iyy><izz>0.01</izz><ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia>
      </inertial>
    </link>
    <joint name="rail" type="prismatic">
      <parent>world</parent><child>block</child>
      <axis><xyz>1 0 0</xyz>
        <limit><effort>100</effort></limit>
        <dynamics><damping>{damping}</damping><spring_stiffness>{stiffness}</spring_stiffness>
          <spring_reference>{reference}</spring_reference></dynamics>
      </axis>
    </joint>
  </model>
</sdf>
"""

ARM = """<?xml version="1.0"?>
<sdf version="1.9">
  <model name="arm">
    <link name="upper"><pose>0 0 -0.25 0 0 0</pose>
      <inertial><mass>1.0</mass><inertia><ixx>0.02</ixx><iyy>0.02</iyy><izz>0.01</izz><ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia></inertial>
    </link>
    <link name="lower"><pose>0 0 -0.75 0 0 0</pose>
      <inertial><mass>0.7</mass><inertia><ixx>0.015</ixx><iyy>0.015</iyy><izz>0.01</izz><ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia></inertial>
    </link>
    <joint name="shoulder" type="revolute"><parent>world</parent><child>upper</child>
      <pose>0 0 0.25 0 0 0</pose>
      <axis><xyz>0 1 0</xyz><limit><effort>20</effort></limit>
        <dynamics><damping>0.8</damping><spring_stiffness>40</spring_stiffness>
          <spring_reference>0.3</spring_reference></dynamics></axis>
    </joint>
    <joint name="elbow" type="revolute"><parent>upper</parent><child>lower</child>
      <pose>0 0 0.25 0 0 0</pose>
      <axis><xyz>0 1 0</xyz><limit><lower>-1.0</lower><upper>0.4</upper><effort>20</effort></limit>
        <dynamics><damping>0.5</damping><spring_stiffness>25</spring_stiffness>
          <spring_reference>-0.2</spring_reference></dynamics></axis>
    </joint>
  </model>
</sdf>
"""

# a rotor about the vertical axis (gravity has no effect on it), spring reference in degrees
ROTOR = """<mujoco model="rotor">
  <compiler angle="{angle}"/>
  <default><joint stiffness="{default_stiffness}"/></default>
  <worldbody>
    <body name="disc">
      <joint name="spin" type="hinge" axis="0 0 1" damping="{damping}" stiffness="{stiffness}"
             springref="{springref}"/>
      <joint name="lift" type="slide" axis="0 0 1"/>
      <geom type="cylinder" size="0.2 0.02" mass="2"/>
    </body>
  </worldbody>
</mujoco>
"""


def _scene(tmp_path, text, name, *, suffix="sdf", body="block", time_step=H, **extra):
    path = tmp_path / f"{name}.{suffix}"
    path.write_text(text)
    data = {
        "name": name, "time_step": time_step, "models": [{"file": str(path), "weld": None}],
        "contacts": [{"body": body, "points": [[0.0, 0.0, 0.0]], "radius": 0.0}],
        "ground_height": -10.0, "activation_distance": 0.1, **extra,
    }  # fmt: skip
    return Scene.from_dict(data)


def _slider(tmp_path, name="slider", *, dynamics="auto", time_step=H, **values):
    values = {"mass": 2.0, "damping": 0.6, "stiffness": 50.0, "reference": 0.25, **values}
    scene = _scene(tmp_path, SLIDER.format(**values), name, dynamics=dynamics, time_step=time_step)
    return build_scene_model(scene), values


@pytest.mark.parametrize("dynamics", ["pinocchio", "drake"])
def test_spring_on_a_slider_steps_as_implicit_euler(tmp_path, dynamics):
    """v+ = (m v + h (u - k (q - q_ref))) / (m + h d + h^2 k), q+ = q + h v+: the spring taken
    at the step's end, for both dynamics providers."""
    sm, p = _slider(tmp_path, dynamics=dynamics)
    stepper = sm.stepper()
    m, d, k, r = p["mass"], p["damping"], p["stiffness"], p["reference"]
    assert stepper.springs.stiffness.tolist() == [k] and stepper.springs.reference.tolist() == [r]
    x = np.array([0.9, -1.5])
    for u in (0.0, 3.0, -7.0, 0.0, 12.0):
        q, v = x
        want_v = (m * v + H * (u - k * (q - r))) / (m + H * d + H * H * k)
        x = stepper.step(x[None], np.array([u]), jacobians=False).x_next[0]
        assert x[1] == pytest.approx(want_v, rel=1e-12, abs=1e-14)
        assert x[0] == pytest.approx(q + H * want_v, rel=1e-12, abs=1e-14)
    off = sm.stepper(springs=False).step(np.array([[0.9, -1.5]]), np.zeros(1), jacobians=False)
    assert off.x_next[0, 1] == pytest.approx(m * -1.5 / (m + H * d), rel=1e-12)


def test_stiff_spring_at_a_large_time_step_is_stable_where_an_explicit_one_diverges(tmp_path):
    """h^2 k / m = 2500: the implicit spring damps the motion out; the same spring applied
    explicitly (semi-implicit Euler, MuJoCo's Euler integrator) grows by a factor ~ h^2 k / m
    per step."""
    h, m, k = 0.05, 1.0, 1e6
    sm, _ = _slider(tmp_path, "stiff", time_step=h, mass=m, damping=0.0, stiffness=k, reference=0.0)
    stepper = sm.stepper()
    x = np.array([0.1, 0.0])
    explicit = x.copy()
    amplitude = []
    for _ in range(40):
        x = stepper.step(x[None], np.zeros(1), jacobians=False).x_next[0]
        amplitude.append(np.abs(x).max())
        explicit[1] -= h * k / m * explicit[0]
        explicit[0] += h * explicit[1]
    assert np.all(np.diff(amplitude) <= 0) and amplitude[-1] < 1e-6  # dies out
    assert np.abs(explicit).max() > 1e50  # the explicit spring blows up


def _fd_check(stepper, x, u, eps=1e-7, rtol=1e-6):
    r = stepper.step(x[None], u)
    assert r.converged.all()
    n = x.size

    def f(p):
        return stepper.step(p[None, :n], p[None, n:], jacobians=False).x_next[0]

    fd = central_difference(f, np.concatenate([x, u]), eps=eps)
    analytic = np.concatenate([r.dx_dx[0], r.dx_du[0]], axis=1)
    np.testing.assert_allclose(analytic, fd, atol=rtol * (1 + np.abs(fd).max()))
    return r


@pytest.mark.parametrize("dynamics", ["pinocchio", "drake"])
@pytest.mark.parametrize("smoothing", [Exact(), ContactAware(1e-3, 0.05)], ids=["exact", "abs"])
def test_two_link_arm_with_springs_at_an_elbow_stop_matches_central_differences(
    tmp_path, dynamics, smoothing
):
    """M(q) depends on the elbow angle and the springs' torques on q: the dW and -h W K
    terms of dx+/dx are exercised, with a joint-limit row in the LCP."""
    scene = _scene(tmp_path, ARM, "arm", body="lower", dynamics=dynamics)
    stepper = build_scene_model(scene).stepper(smoothing=smoothing)
    assert stepper.springs.active
    x, u = np.array([0.3, 0.38, -1.0, 6.0]), np.array([2.0, 15.0])
    r = _fd_check(stepper, x, u)
    assert r.limit_impulse[0, 1] > 1e-3  # the elbow's upper stop acts
    # the springs change the step and its Jacobian
    free = build_scene_model(scene).stepper(smoothing=smoothing, springs=False).step(x[None], u)
    assert np.abs(free.dx_dx - r.dx_dx).max() > 1e-3


@pytest.mark.parametrize("dynamics", ["pinocchio", "drake"])
def test_spring_and_damping_columns_match_central_differences(tmp_path, dynamics):
    """dx+/dtheta for the springs' stiffness and reference, the damping and a mass (whose dW,
    dv_free are carried through the springs: -h dW (D' v_free' - tau_k)), against steppers
    with the parameter moved (with_parameters)."""
    scene = _scene(tmp_path, ARM, "arm", body="lower", dynamics=dynamics)
    stepper = build_scene_model(scene).stepper()
    names = stepper.parameter_names
    assert names[-4:] == (
        "stiffness[shoulder]", "stiffness[elbow]", "springref[shoulder]", "springref[elbow]"
    )  # fmt: skip
    values = dict(zip(names, stepper.parameter_values(), strict=True))
    assert values["stiffness[elbow]"] == 25.0 and values["springref[shoulder]"] == 0.3
    x, u = np.array([0.3, 0.1, -1.0, 2.0]), np.array([2.0, 1.0])  # free of the elbow's stops
    columns = [
        "stiffness[shoulder]", "stiffness[elbow]", "springref[shoulder]", "springref[elbow]",
        "damping[elbow]", "mass[upper]", "mass[lower]",
    ]  # fmt: skip
    r = stepper.step(x[None], u, parameters=columns)
    eps = 1e-6
    for j, name in enumerate(columns):
        plus = stepper.with_parameters({name: values[name] + eps}).step(x[None], u)
        minus = stepper.with_parameters({name: values[name] - eps}).step(x[None], u)
        fd = (plus.x_next[0] - minus.x_next[0]) / (2 * eps)
        np.testing.assert_allclose(r.dx_dtheta[0, :, j], fd, rtol=1e-6, atol=1e-9, err_msg=name)
        assert np.abs(fd).max() > 1e-6, name  # every column moves the step


def test_springs_taken_in_the_batched_pass_equal_the_generic_implicit_step(rng):
    """Pinocchio takes the springs into its one ABA (armature + h (D + h K), torque - K (q -
    q_ref)); the generic path (implicit_damping of the undamped quantities) gives the same W,
    free velocity and derivatives."""
    sm = build_scene_model("gym_half_cheetah")
    model = sm.contact_model
    D, K = joint_damping(sm.plant), joint_springs(sm.plant)
    assert K.stiffness.tolist() == [0, 0, 0, 240, 180, 120, 180, 120, 60]
    B = 4
    q = sm.q0 + 0.2 * rng.standard_normal((B, model.nq))
    v, u = rng.standard_normal((B, model.nv)), rng.standard_normal((B, model.nu))
    for derivatives in (False, True):
        ours = model.quantities(q, v, u, derivatives=derivatives, damping=D, springs=K)
        undamped = model.quantities(q, v, u, derivatives=derivatives)
        want = implicit_damping(undamped, D, model.h, springs=K)[0]
        for field in ("W", "v_free", "dv_free"):
            a, b = getattr(ours, field), getattr(want, field)
            if b is None:
                continue
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * (1 + np.abs(b).max()))
    f = rng.standard_normal((B, model.nv))
    b = want.dW_dot(f)
    np.testing.assert_allclose(ours.dW_dot(f), b, rtol=0, atol=1e-12 * (1 + np.abs(b).max()))


def test_half_cheetah_providers_agree_with_springs(rng):
    """The half-cheetah step with its springs: pinocchio and the MultibodyPlant give the same
    next states and Jacobians."""
    scene = Scene.load("gym_half_cheetah")
    pin = build_scene_model(scene).stepper()
    drake = build_scene_model(Scene.from_dict({**scene.to_dict(), "dynamics": "drake"})).stepper()
    assert pin.springs.active and drake.springs.active
    B = 3
    x0 = build_scene_model(scene).x0
    x = x0 + np.concatenate([0.2 * rng.standard_normal((B, 9)), rng.standard_normal((B, 9))], 1)
    u = 30.0 * rng.standard_normal((B, 6))
    a, b = pin.step(x, u), drake.step(x, u)
    np.testing.assert_allclose(a.x_next, b.x_next, rtol=0, atol=1e-10)
    np.testing.assert_allclose(a.dx_dx, b.dx_dx, rtol=0, atol=1e-8)
    np.testing.assert_allclose(a.dx_du, b.dx_du, rtol=0, atol=1e-10)


def test_stepper_without_springs_pickles_as_such(tmp_path):
    sm, _ = _slider(tmp_path)
    for flag in (True, False):
        stepper = sm.stepper()
        stepper = sm.stepper() if flag else _without_springs(sm)
        other = pickle.loads(pickle.dumps(stepper))
        x = np.array([[0.9, -1.5]])
        np.testing.assert_array_equal(
            other.step(x, np.zeros(1), jacobians=False).x_next,
            stepper.step(x, np.zeros(1), jacobians=False).x_next,
        )
        assert other.springs.active == flag
        assert ("stiffness[rail]" in other.parameter_names) == flag


def _without_springs(sm):
    from drake_abs.multibody.builder import rebuild_stepper
    from drake_abs.multibody.stepper import ComplementarityStepper

    stepper = ComplementarityStepper(sm.contact_model, springs=False)
    stepper.scene, stepper.rebuild = sm.scene, rebuild_stepper
    return stepper


def test_with_parameters_sets_a_stiffness_where_the_file_has_none(tmp_path):
    sm, p = _slider(tmp_path, stiffness=0.0, reference=0.0)
    stepper = sm.stepper()
    assert not stepper.springs.active
    k, r = 80.0, -0.3
    sprung = stepper.with_parameters({"stiffness[rail]": k, "springref[rail]": r})
    want, _ = _slider(tmp_path, "sprung", stiffness=k, reference=r)
    x = np.array([[0.4, 0.7]])
    np.testing.assert_allclose(
        sprung.step(x, np.ones(1), jacobians=False).x_next,
        want.stepper().step(x, np.ones(1), jacobians=False).x_next,
        rtol=1e-13,
    )
    with pytest.raises(ValueError, match="stiffness"):
        stepper.with_parameters({"stiffness[rail]": -1.0})


def test_bad_springs_are_refused_by_name():
    with pytest.raises(ValueError, match="stiffness"):
        JointSprings(np.array([-1.0]), np.zeros(1), np.zeros(1, dtype=int))
    with pytest.raises(ValueError, match="q_index"):
        JointSprings(np.array([1.0]), np.zeros(1), np.array([-1]))
    sm = build_scene_model("gym_hopper")
    model = sm.contact_model
    q, v, u = sm.q0[None], np.zeros((1, model.nv)), np.zeros((1, model.nu))
    with pytest.raises(ValueError, match="springs"):
        model.quantities(q, v, u, springs=JointSprings.none(model.nv + 1))


@pytest.mark.parametrize("angle", ["degree", "radian"])
def test_mjcf_springs_are_read_with_their_reference_in_radians(tmp_path, angle):
    """MJCF: stiffness (own or from the default class) towards springref, in degrees under
    MuJoCo's default ``<compiler angle="degree">``; on a rotor about the vertical axis the step
    is the closed form of implicit Euler."""
    ref = 30.0 if angle == "degree" else 0.5
    text = ROTOR.format(angle=angle, default_stiffness=7, damping=0.2, stiffness=12, springref=ref)
    path = tmp_path / "rotor.xml"
    path.write_text(text)
    info = read_mjcf(path)
    want = np.deg2rad(ref) if angle == "degree" else ref
    assert info.springs == (("spin", 12.0, pytest.approx(want)), ("lift", 7.0, 0.0))
    scene = _scene(tmp_path, text, "rotor", suffix="xml", body="disc")
    sm = build_scene_model(scene)
    report = {j["name"]: j for j in sm.model_report()["joints"]}
    assert report["spin"]["stiffness"] == 12.0
    assert report["spin"]["springref"] == pytest.approx(want)
    assert report["lift"]["stiffness"] == 7.0
    stepper = sm.stepper()
    I = 2.0 * 0.2**2 / 2  # noqa: E741  (the disc's moment about its axis)
    x = np.array([0.0, 0.0, 2.0, 0.0])  # (spin, lift, their rates)
    r = stepper.step(x[None], np.zeros(0), jacobians=False)
    spin = stepper.springs.q_index.tolist().index(0)
    assert r.x_next[0, 2 + spin] == pytest.approx(
        (I * 2.0 + H * 12.0 * want) / (I + H * 0.2 + H * H * 12.0), rel=1e-9
    )
    dropped = read_mjcf(path, ("joint.stiffness",))
    assert dropped.springs == () and len(dropped.dropped) == 2


def test_mjcf_spring_on_a_ball_joint_is_refused(tmp_path):
    path = tmp_path / "ball.xml"
    path.write_text(
        '<mujoco><worldbody><body name="b"><joint name="j" type="ball" stiffness="3"/>'
        '<geom type="sphere" size="0.1"/></body></worldbody></mujoco>'
    )
    with pytest.raises(ValueError, match="stiffness=3 .*ball"):
        read_mjcf(path)
    assert read_mjcf(path, ("joint.stiffness",)).springs == ()


def test_half_cheetah_scene_reports_its_springs():
    report = build_scene_model("gym_half_cheetah").model_report()
    stiffness = {j["name"]: j["stiffness"] for j in report["joints"]}
    assert stiffness == {
        "rootx": 0.0, "rootz": 0.0, "rooty": 0.0, "bthigh": 240.0, "bshin": 180.0,
        "bfoot": 120.0, "fthigh": 180.0, "fshin": 120.0, "ffoot": 60.0,
    }  # fmt: skip
    assert all(j["springref"] == 0.0 for j in report["joints"])


def _rollout(stepper, x0, steps):
    xs, x = [x0], x0
    for _ in range(steps):
        r = stepper.step(x[None], np.zeros(6), jacobians=False)
        assert r.converged.all()
        x = r.x_next[0]
        xs.append(x)
    return np.array(xs)


def test_suspended_half_cheetah_joints_follow_mujoco_with_springs():
    """The half-cheetah falling from 5 m up with its legs bent (no contact within the 0.6 s
    horizon): the legs swing back towards 0 on their springs. MuJoCo (gymnasium's file, Euler,
    one mj_step per step, contacts off) takes the spring explicitly, our step implicitly: the
    two differ by a relative O(h^2 K / I) per step, so the joint trajectories agree to first
    order in h. Without the springs ours leaves the legs bent."""
    pytest.importorskip("gymnasium")
    pytest.importorskip("mujoco")
    from drake_abs.reference.mujoco_plant import MujocoStepper

    q0 = np.array([0.0, 5.0, 0.05, 0.4, -0.4, 0.3, -0.5, 0.5, -0.3])
    x0 = np.concatenate([q0, np.zeros(9)])
    legs = slice(3, 9)
    gaps = {}
    for h in (0.01, 0.001):
        scene = Scene.from_dict({**Scene.load("gym_half_cheetah").to_dict(), "time_step": h})
        sm = build_scene_model(scene)
        options = {"timestep": h, "integrator": "Euler", "contact": False}
        mj = MujocoStepper.from_gymnasium("HalfCheetah-v5", frame_skip=1, options=options)
        steps = int(round(0.6 / h))
        ours = _rollout(sm.stepper(springs="implicit"), x0, steps)
        theirs = _rollout(mj, x0, steps)
        assert ours[:, 1].min() > 2.0  # in the air: no contact candidate near the ground
        assert np.abs(theirs[-1, legs]).max() < 0.05  # MuJoCo's legs swung back towards 0
        gaps[h] = np.abs(ours[:, legs] - theirs[:, legs]).max()
        if h == 0.01:
            bent = _rollout(sm.stepper(springs=False), x0, steps)
            gap_without = np.abs(bent[:, legs] - theirs[:, legs]).max()
    # measured: 0.093 rad at h = 10 ms, 0.011 rad at 1 ms (0.031 at 3 ms, 0.0033 at 0.3 ms);
    # without springs 0.69 rad
    assert gaps[0.01] < 0.12 and gaps[0.001] < 0.015, gaps
    assert 7.0 < gaps[0.01] / gaps[0.001] < 13.0, gaps  # first order in h
    assert gap_without > 0.5, gap_without


@pytest.mark.parametrize("dynamics", ["pinocchio", "drake"])
def test_an_explicit_spring_steps_as_mujocos_euler(tmp_path, dynamics):
    """springs="explicit": the spring torque at the step's start, the damping still implicit,
    v+ = (m v + h (u - k (q - q_ref))) / (m + h d), q+ = q + h v+ (MuJoCo's Euler integrator);
    it differs from the implicit step by the h^2 k in the denominator."""
    sm, p = _slider(tmp_path, dynamics=dynamics)
    stepper = sm.stepper(springs="explicit")
    assert not stepper.springs.implicit and sm.stepper().springs.implicit
    m, d, k, r = p["mass"], p["damping"], p["stiffness"], p["reference"]
    x = np.array([0.9, -1.5])
    for u in (0.0, 3.0, -7.0, 0.0, 12.0):
        q, v = x
        want_v = (m * v + H * (u - k * (q - r))) / (m + H * d)
        x = stepper.step(x[None], np.array([u]), jacobians=False).x_next[0]
        assert x[1] == pytest.approx(want_v, rel=1e-12, abs=1e-14)
        assert x[0] == pytest.approx(q + H * want_v, rel=1e-12, abs=1e-14)
    implicit = sm.stepper().step(np.array([[0.9, -1.5]]), np.zeros(1), jacobians=False)
    explicit = stepper.step(np.array([[0.9, -1.5]]), np.zeros(1), jacobians=False)
    assert abs(implicit.x_next[0, 1] - explicit.x_next[0, 1]) > 1e-3
    # it survives pickling (Ray workers rebuild the same stepper)
    again = pickle.loads(pickle.dumps(stepper))
    assert not again.springs.implicit


@pytest.mark.parametrize("dynamics", ["pinocchio", "drake"])
def test_explicit_spring_jacobians_and_columns_match_central_differences(tmp_path, dynamics):
    """dx+/dx, dx+/du and dx+/dtheta (stiffness, reference, damping, a mass) of the explicit
    springs' step against central differences (dW'/dK = 0 there)."""
    scene = _scene(tmp_path, ARM, "arm", body="lower", dynamics=dynamics)
    stepper = build_scene_model(scene).stepper(springs="explicit")
    # both springs stretched (an explicit stiffness column is 0 at its reference)
    x, u = np.array([0.5, 0.1, -1.0, 2.0]), np.array([2.0, 1.0])
    _fd_check(stepper, x, u)
    values = dict(zip(stepper.parameter_names, stepper.parameter_values(), strict=True))
    columns = ["stiffness[shoulder]", "stiffness[elbow]", "springref[elbow]", "damping[elbow]",
               "mass[lower]"]  # fmt: skip
    r = stepper.step(x[None], u, parameters=columns)
    eps = 1e-6
    for j, name in enumerate(columns):
        plus = stepper.with_parameters({name: values[name] + eps})
        assert not plus.springs.implicit  # with_parameters keeps the treatment
        minus = stepper.with_parameters({name: values[name] - eps})
        fd = (plus.step(x[None], u).x_next[0] - minus.step(x[None], u).x_next[0]) / (2 * eps)
        np.testing.assert_allclose(r.dx_dtheta[0, :, j], fd, rtol=1e-6, atol=1e-9, err_msg=name)
        assert np.abs(fd).max() > 1e-6, name


def test_explicit_springs_follow_mujoco_to_rounding_in_the_air():
    """The suspended HalfCheetah of the test above with springs="explicit": our step is then
    MuJoCo's Euler step (springs explicit, damping and armature implicit), so the legs follow
    MuJoCo's to rounding, where the implicit springs differ by 0.093 rad at 10 ms."""
    pytest.importorskip("gymnasium")
    pytest.importorskip("mujoco")
    from drake_abs.reference.mujoco_plant import MujocoStepper

    q0 = np.array([0.0, 5.0, 0.05, 0.4, -0.4, 0.3, -0.5, 0.5, -0.3])
    x0 = np.concatenate([q0, np.zeros(9)])
    sm = build_scene_model("gym_half_cheetah")
    options = {"timestep": 0.01, "integrator": "Euler", "contact": False}
    mj = MujocoStepper.from_gymnasium("HalfCheetah-v5", frame_skip=1, options=options)
    theirs = _rollout(mj, x0, 60)
    assert not sm.stepper().springs.implicit  # the shipped scene's choice
    ours = _rollout(sm.stepper(springs="explicit"), x0, 60)
    implicit = _rollout(sm.stepper(springs="implicit"), x0, 60)
    assert np.abs(ours - theirs).max() < 1e-6, np.abs(ours - theirs).max()
    assert np.abs(implicit[:, 3:9] - theirs[:, 3:9]).max() > 0.05


def test_a_spring_treatment_that_is_not_one_is_refused(tmp_path):
    sm, _ = _slider(tmp_path)
    with pytest.raises(ValueError, match="springs must be True, False, 'implicit' or 'explicit'"):
        sm.stepper(springs="semi")
    with pytest.raises(ValueError, match="implicit must be True or False"):
        JointSprings(np.ones(1), np.zeros(1), np.zeros(1, dtype=int), implicit="yes")


def test_explicit_springs_past_their_stability_bound_are_warned_of(tmp_path):
    """h^2 k / m = 2500 (the stiff slider above): explicit springs would grow each step, and the
    stepper says so when it is built; the implicit ones, and the HalfCheetah's explicit ones
    (h^2 K W_jj about 0.2 at most), build silently."""
    import warnings

    from drake_abs.multibody.stepper import ExplicitSpringWarning

    h, m, k = 0.05, 1.0, 1e6
    sm, _ = _slider(tmp_path, "stiff", time_step=h, mass=m, damping=0.0, stiffness=k, reference=0.0)
    with pytest.warns(ExplicitSpringWarning, match=r"velocity 0: 2\.5e\+03"):
        sm.stepper(springs="explicit")
    with warnings.catch_warnings():
        warnings.simplefilter("error", ExplicitSpringWarning)
        sm.stepper()  # implicit
        build_scene_model("gym_half_cheetah").stepper()  # explicit, within the bound
