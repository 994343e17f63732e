"""What a model file declares about its joints, as the step honours it (docs/math.md section 6c):
position limits as complementarity rows, viscous damping taken implicitly, actuator effort
limits; each against closed forms and central differences."""

from __future__ import annotations

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs.contact.smoothing import ContactAware, Exact, Fixed
from drake_abs.multibody import Scene, build_scene_model

H = 0.01

PENDULUM = """<?xml version="1.0"?>
<sdf version="1.9">
  <model name="pendulum">
    <link name="arm">
      <pose>0 0 -0.5 0 0 0</pose>
      <inertial><mass>{mass}</mass>
        <inertia><ixx>0.01</ixx><iyy>0.01</iyy><izz>0.01</izz><ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia>
      </inertial>
    </link>
    <joint name="hinge" type="revolute">
      <parent>world</parent><child>arm</child>
      <pose>0 0 0.5 0 0 0</pose>
      <axis><xyz>0 1 0</xyz>
        <limit><lower>{lower}</lower><upper>{upper}</upper><effort>{effort}</effort></limit>
        <dynamics><damping>{damping}</damping></dynamics>
      </axis>
    </joint>
  </model>
</sdf>
"""

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
        <limit><effort>{effort}</effort></limit>
        <dynamics><damping>{damping}</damping></dynamics>
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
        <dynamics><damping>3.0</damping></dynamics></axis>
    </joint>
    <joint name="elbow" type="revolute"><parent>upper</parent><child>lower</child>
      <pose>0 0 0.25 0 0 0</pose>
      <axis><xyz>0 1 0</xyz><limit><lower>-1.0</lower><upper>0.4</upper><effort>20</effort></limit>
        <dynamics><damping>0.5</damping></dynamics></axis>
    </joint>
  </model>
</sdf>
"""


def _scene(tmp_path, template, name, **values):
    path = tmp_path / f"{name}.sdf"
    path.write_text(template.format(**values))
    return Scene.from_dict({
        "name": name, "time_step": H, "models": [{"file": str(path), "weld": None}],
        "contacts": [{"body": {PENDULUM: "arm", SLIDER: "block", ARM: "lower"}[template],
                      "points": [[0.0, 0.0, 0.0]], "radius": 0.0}],
        "ground_height": -10.0, "activation_distance": 0.1,
    })  # fmt: skip


def _model(tmp_path, template, name, **values):
    sm = build_scene_model(_scene(tmp_path, template, name, **values))
    return sm


PEND = dict(mass=1.0, lower=-0.4, upper=0.3, effort=5.0, damping=0.0)


@pytest.mark.parametrize("smoothing", [Exact(), Fixed(1e-6)], ids=repr)
def test_pendulum_swings_onto_its_limit_and_rests_there(tmp_path, smoothing):
    sm = _model(tmp_path, PENDULUM, "pendulum", **PEND)
    stepper = sm.stepper(smoothing=smoothing)
    assert stepper.limits.names == ("hinge.lower", "hinge.upper")
    x = np.array([0.0, 4.0])  # swinging towards the upper limit (0.3 rad) at 4 rad/s, with a
    xs, impulses = [x], []  # torque of -4 N m, more than gravity's pull back at the lower limit
    for _ in range(200):
        r = stepper.step(x[None], np.array([-4.0]))
        assert r.converged.all()
        x = r.x_next[0]
        xs.append(x)
        impulses.append(r.limit_impulse[0])
    xs, impulses = np.array(xs), np.array(impulses)
    assert xs[:, 0].max() <= 0.3 + 1e-9  # never past the limit
    assert impulses[:, 1].max() > 0.1 and impulses.min() >= 0  # the upper stop pushed back
    # the torque drives it onto the lower limit, where it comes to rest (the stops are inelastic)
    assert xs[:, 0].min() >= -0.4 - 1e-9 and impulses[-1, 0] > 0
    if smoothing.is_exact:
        assert xs[-1, 0] == pytest.approx(-0.4, abs=1e-9) and abs(xs[-1, 1]) < 1e-9


def test_limit_rows_are_pruned_far_from_the_limit_and_repaired_when_crossed(tmp_path):
    sm = _model(tmp_path, PENDULUM, "pendulum", **PEND)
    pruned, full = sm.stepper(), sm.stepper(activation_distance=float("inf"))
    # far from both limits: no limit row in play; then fast enough to cross within one step
    for x in (np.array([0.0, 0.5]), np.array([0.0, 60.0]), np.array([0.1, -80.0])):
        a, b = pruned.step(x[None], np.zeros(1)), full.step(x[None], np.zeros(1))
        np.testing.assert_allclose(a.x_next, b.x_next, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(a.limit_impulse, b.limit_impulse, rtol=1e-12, atol=1e-12)
        assert -0.4 - 1e-9 <= a.x_next[0, 0] <= 0.3 + 1e-9


@pytest.mark.parametrize(
    "smoothing", [Exact(), Fixed(1e-5), ContactAware(1e-3, 0.05)], ids=["exact", "bs", "abs"]
)
def test_step_jacobian_at_a_limit_matches_central_differences(tmp_path, smoothing):
    sm = _model(tmp_path, PENDULUM, "pendulum", **{**PEND, "damping": 0.7})
    stepper = sm.stepper(smoothing=smoothing)
    x, u = np.array([0.28, 3.0]), np.array([1.5])
    r = stepper.step(x[None], u)
    assert r.converged.all() and r.limit_impulse[0, 1] > 1e-3  # the upper stop acts

    def f(p):
        return stepper.step(p[None, :2], p[None, 2:], jacobians=False).x_next[0]

    fd = central_difference(f, np.concatenate([x, u]), eps=1e-7)
    analytic = np.concatenate([r.dx_dx[0], r.dx_du[0]], axis=1)
    np.testing.assert_allclose(analytic, fd, atol=1e-6 * (1 + np.abs(fd).max()))


@pytest.mark.parametrize("smoothing", [Exact(), ContactAware(1e-3, 0.05)], ids=["exact", "abs"])
def test_two_link_arm_with_damping_and_an_elbow_stop_matches_central_differences(
    tmp_path, smoothing
):
    """M(q) depends on the elbow angle: the damping's dW terms are exercised."""
    stepper = _model(tmp_path, ARM, "arm").stepper(smoothing=smoothing)
    x, u = np.array([0.3, 0.38, -1.0, 4.0]), np.array([2.0, 1.0])
    r = stepper.step(x[None], u)
    assert r.converged.all() and r.limit_impulse[0, 1] > 1e-3  # the elbow's upper stop acts

    def f(p):
        return stepper.step(p[None, :4], p[None, 4:], jacobians=False).x_next[0]

    fd = central_difference(f, np.concatenate([x, u]), eps=1e-7)
    analytic = np.concatenate([r.dx_dx[0], r.dx_du[0]], axis=1)
    np.testing.assert_allclose(analytic, fd, atol=1e-6 * (1 + np.abs(fd).max()))


def test_implicit_damping_decays_as_backward_euler_and_stays_stable(tmp_path):
    """Mass 1 kg on a rail, damping c: v_k = v_0 / (1 + h c / m)^k, for any h c / m (an
    explicit damping force diverges once h c / m > 2)."""
    for c in (2.0, 1e4):
        sm = _model(tmp_path, SLIDER, f"slider{int(c)}", mass=1.0, effort=10.0, damping=c)
        stepper = sm.stepper()
        x = np.array([0.0, 3.0])
        for k in range(1, 21):
            r = stepper.step(x[None], np.zeros(1))
            x = r.x_next[0]
            assert x[1] == pytest.approx(3.0 / (1 + H * c) ** k, rel=1e-12)
        undamped = sm.stepper(damping=False).step(np.array([[0.0, 3.0]]), np.zeros(1))
        assert undamped.x_next[0, 1] == pytest.approx(3.0)  # the switch turns it off


def test_damped_step_jacobians_and_mass_derivative_match_central_differences(tmp_path):
    c, m, eps = 5.0, 2.0, 1e-6
    stepper = _model(tmp_path, SLIDER, "slider", mass=m, effort=10.0, damping=c).stepper()
    x, u = np.array([0.2, 1.3]), np.array([4.0])
    r = stepper.step(x[None], u, parameters=True)

    def f(p):
        return stepper.step(p[None, :2], p[None, 2:], jacobians=False).x_next[0]

    fd = central_difference(f, np.concatenate([x, u]), eps=1e-7)
    np.testing.assert_allclose(np.concatenate([r.dx_dx[0], r.dx_du[0]], axis=1), fd, atol=1e-9)
    # v+ = (m v + h u) / (m + h c): its derivative in m, against re-built models
    column = r.theta_names.index("mass[block]")
    plus = _model(tmp_path, SLIDER, "slider_p", mass=m + eps, effort=10.0, damping=c).stepper()
    minus = _model(tmp_path, SLIDER, "slider_m", mass=m - eps, effort=10.0, damping=c).stepper()
    fd_m = (
        plus.step(x[None], u, jacobians=False).x_next[0]
        - minus.step(x[None], u, jacobians=False).x_next[0]
    ) / (2 * eps)
    closed = (x[1] * (m + H * c) - (m * x[1] + H * u[0])) / (m + H * c) ** 2
    assert fd_m[1] == pytest.approx(closed, rel=1e-6)
    np.testing.assert_allclose(r.dx_dtheta[0, :, column], fd_m, rtol=1e-6, atol=1e-10)


def test_effort_limits_clip_the_input_and_zero_its_derivative(tmp_path):
    stepper = _model(tmp_path, SLIDER, "slider", mass=1.0, effort=10.0, damping=0.0).stepper()
    x = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    u = np.array([[50.0], [10.0], [-3.0]])
    r = stepper.step(x, u)
    np.testing.assert_allclose(r.x_next[:, 1], [10.0 * H, 10.0 * H, -3.0 * H], rtol=1e-12)
    assert r.dx_du[0, 1, 0] == 0.0 and r.dx_du[2, 1, 0] == pytest.approx(H)
    free = _model(tmp_path, SLIDER, "slider2", mass=1.0, effort=10.0, damping=0.0)
    unlimited = free.stepper(joint_limits=False).step(x, u)
    assert unlimited.x_next[0, 1] == pytest.approx(50.0 * H)
