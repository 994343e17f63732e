"""The translating box on frictional ground as an LCS (drake_abs.tasks.box_lcs).

Checks: a sliding box stops where discrete Coulomb friction says (analytic); a push below the
friction threshold does not move it (static friction) and one above accelerates it at
(u - alpha m g) / m; the step Jacobians match central differences; and the LCS box follows the
rigid-body complementarity stepper on the same translating box (a MultibodyPlant with
prismatic x and z joints) step by step, Jacobians included, under exact contact, BS and ABS.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs.contact.smoothing import ContactAware, Fixed
from drake_abs.lcp.ipm import LCPConvergenceWarning
from drake_abs.tasks.box_lcs import TranslatingBox

G = 9.81


def coulomb_slide(v0: float, alpha: float, h: float, steps: int) -> tuple[float, float]:
    """Semi-implicit Euler with Coulomb friction at a resting normal impulse m g h."""
    p, v = 0.0, v0
    for _ in range(steps):
        v = max(v - alpha * G * h, 0.0)
        p += h * v
    return p, v


@pytest.mark.parametrize(("alpha", "h", "v0"), [(0.5, 0.01, 1.0), (0.2, 0.005, 2.3)])
def test_sliding_distance_is_the_discrete_coulomb_answer(alpha, h, v0):
    box = TranslatingBox(mass=2.0, friction=alpha, time_step=h)
    steps = int(1.2 * v0 / (alpha * G * h)) + 5
    x = box.resting_state(v_x=v0)[None]
    stepper = box.stepper()
    for _ in range(steps):
        r = stepper.step(x, np.zeros((1, 1)))
        assert r.converged.all()
        x = r.x_next
    p, v = coulomb_slide(v0, alpha, h, steps)
    assert v == 0.0
    assert x[0, 0] == pytest.approx(p, abs=1e-7)
    assert x[0, 2] == pytest.approx(0.0, abs=1e-7)
    assert x[0, 1] == pytest.approx(box.half_height, abs=1e-10)  # stays on the ground


def test_static_friction_holds_below_the_threshold_and_slides_above():
    box = TranslatingBox(mass=1.5, friction=0.4, time_step=0.01)
    threshold = box.friction * box.mass * G  # N
    stepper = box.stepper()
    pushes = np.array([[0.5 * threshold], [0.95 * threshold], [1.2 * threshold]])
    x = np.tile(box.resting_state(), (3, 1))
    for _ in range(40):
        r = stepper.step(x, pushes)
        x = r.x_next
    assert np.abs(x[:2, 0]).max() < 1e-9 and np.abs(x[:2, 2]).max() < 1e-9
    # the friction impulse balances the push exactly: beta_1 - beta_2 = -u h
    np.testing.assert_allclose(
        r.impulse[:2, 1] - r.impulse[:2, 2], -pushes[:2, 0] * 0.01, rtol=1e-6
    )
    accel = (pushes[2, 0] - threshold) / box.mass
    assert x[2, 2] == pytest.approx(accel * 40 * 0.01, rel=1e-6)


@pytest.mark.parametrize(
    ("contact", "gradient", "x"),
    [
        (None, "frozen", [0.0, 0.1, 0.8, 0.0]),  # sliding
        (None, "frozen", [0.0, 0.13, 0.8, -2.0]),  # landing within the step
        (Fixed(1e-5), "frozen", [0.0, 0.1, 0.3, 0.0]),
        (ContactAware(mu_max=1e-3, length=0.02), "total", [0.0, 0.115, 0.5, -0.5]),
    ],
)
def test_step_jacobians_match_central_differences(contact, gradient, x):
    box = TranslatingBox(mass=1.0, friction=0.5, time_step=0.01)
    stepper = box.stepper(contact, gradient)
    x = np.array(x)
    u = np.array([1.0])
    r = stepper.step(x[None], u[None])
    assert r.converged.all()
    fd_x = central_difference(lambda y: stepper.step(y[None], u[None]).x_next[0], x, eps=1e-7)
    fd_u = central_difference(lambda w: stepper.step(x[None], w[None]).x_next[0], u, eps=1e-7)
    np.testing.assert_allclose(r.dx_dx[0], fd_x, atol=2e-5)
    np.testing.assert_allclose(r.dx_du[0], fd_u, atol=2e-7)


def test_bad_parameters_raise():
    with pytest.raises(ValueError, match="mass"):
        TranslatingBox(mass=0.0)
    with pytest.raises(ValueError, match="friction"):
        TranslatingBox(friction=float("nan"))


@pytest.mark.parametrize(
    "contact", [None, Fixed(1e-4), ContactAware(mu_max=1e-3, length=0.02)], ids=str
)
def test_lcs_box_equals_the_rigid_body_stepper_on_the_translating_box(contact):
    from drake_abs.multibody import ComplementarityStepper
    from drake_abs.multibody.builder import build_scene_model
    from drake_abs.multibody.scene import Scene

    box = TranslatingBox()  # the SDF's 1 kg, 0.2 m tall box
    scene = Scene.from_dict(
        {
            "name": "box_translating",
            "time_step": box.time_step,
            "models": [{"file": "drake_abs:models/box_translating.sdf"}],
            "contacts": [
                {"body": "box", "points": [[0.0, 0.0, -box.half_height]], "friction": 0.5}
            ],
            "friction_directions": 2,
        }
    )
    rigid = ComplementarityStepper(build_scene_model(scene).contact_model, contact)
    lcs = box.stepper(contact)
    # dropped from 5 cm while sliding, pushed with a varying force (stick and slip both occur)
    x_r = x_l = np.array([[0.0, 0.15, 1.0, -0.5], [0.0, 0.1, 0.0, 0.0]])
    pushes = np.linspace(-3.0, 8.0, 50)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LCPConvergenceWarning)
        for f in pushes:
            u = np.array([[f], [0.5 * f]])
            a, b = rigid.step(x_r, u), lcs.step(x_l, u)
            np.testing.assert_array_equal(a.converged, b.converged)
            np.testing.assert_allclose(b.x_next, a.x_next, atol=1e-10)
            np.testing.assert_allclose(b.dx_dx, a.dx_dx, atol=1e-8)
            np.testing.assert_allclose(b.dx_du, a.dx_du, atol=1e-8)
            x_r, x_l = a.x_next, b.x_next
    assert x_l[0, 0] > 0.05  # the first box slid
    if contact is None:  # the second, pushed below the threshold, held (BS lets it creep)
        assert abs(x_l[1, 0]) < 1e-8
