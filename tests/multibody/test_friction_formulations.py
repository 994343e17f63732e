"""The two friction formulations (docs/math.md sections 6 and 6b) against Coulomb's laws on a
planar box (1 kg, friction 0.5, h = 0.01): sticking below mu m g, sliding at (F - mu m g) / m,
sticking and sliding on an incline; Stewart-Trinkle to rounding, Anitescu within its measured
artefact (a sliding contact lifts off at alpha |v_t|), which is checked too. Rolling at 5/7 of
the landing speed is checked for both on the shipped ball. Step Jacobians under both
formulations are checked against central differences in test_multibody_contact.py and
tests/contact/test_contact_lcp.py."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from drake_abs.contact.smoothing import ContactAware, Fixed
from drake_abs.multibody import Scene, build_scene_model

G, MU, H = 9.81, 0.5, 0.01
FORMULATIONS = ("stewart_trinkle", "anitescu")


def _box(friction: str, normal=(0.0, 0.0, 1.0)):
    scene = Scene.from_dict({
        "name": "coulomb_box", "time_step": H,
        "models": [{"file": "drake_abs:models/box_planar.sdf"}],
        "contacts": [{"body": "box", "points": [[-0.2, 0, -0.1], [0.2, 0, -0.1]], "friction": MU}],
        "friction_directions": 2, "ground_normal": list(normal), "friction_model": friction,
    })  # fmt: skip
    return build_scene_model(scene)


def _run(model, x, push, steps, smoothing=None):
    stepper = model.stepper() if smoothing is None else model.stepper(smoothing=smoothing)
    xs = [np.asarray(x, float)]
    for _ in range(steps):
        r = stepper.step(xs[-1][None], np.array([push]), jacobians=False)
        assert r.converged.all()
        xs.append(r.x_next[0])
    return np.array(xs)


# how close each formulation is to Coulomb's law on a sliding box (relative speed error), and
# its lift: Stewart-Trinkle is exact to rounding; Anitescu's sliding contact separates at
# alpha |v_t| (measured: 0.25 % slower after 1 s, lift alpha |v_t| h)
SPEED_RTOL = {"stewart_trinkle": 1e-9, "anitescu": 1e-2}


@pytest.mark.parametrize("friction", FORMULATIONS)
def test_box_sticks_below_and_slides_above_the_friction_force(friction):
    model = _box(friction)
    rest = np.array([0.0, 0.1, 0.0, 0.0, 0.0, 0.0])
    held = _run(model, rest, 3.0, 100)  # 3 N < mu m g = 4.905 N: static friction holds it
    assert np.abs(held[:, 3]).max() < 1e-8 and np.abs(held[:, 0]).max() < 1e-8
    assert np.abs(held[:, 1] - 0.1).max() < 1e-9  # no lift at a sticking contact
    pushed = _run(model, rest, 8.0, 100)  # slides: a = (F - mu m g) / m
    expected = (8.0 - MU * G) * H * np.arange(101)
    np.testing.assert_allclose(pushed[-1, 3], expected[-1], rtol=SPEED_RTOL[friction])
    if friction == "stewart_trinkle":
        np.testing.assert_allclose(pushed[1:, 3], expected[1:], rtol=1e-9)
    else:  # a transient of a few steps as the contact lifts off, then Coulomb's acceleration
        np.testing.assert_allclose(np.diff(pushed[50:, 3]), (8.0 - MU * G) * H, rtol=1e-6)
    lift = pushed[:, 1] - 0.1
    if friction == "stewart_trinkle":
        assert np.abs(lift).max() < 1e-9
    else:  # the artefact: lift of about alpha |v_t| h at each step, never more
        assert lift.max() <= 1.01 * MU * np.abs(pushed[:, 3]).max() * H
        assert lift[-1] >= 0.9 * MU * pushed[-1, 3] * H  # and it is there (the test can fail)


@pytest.mark.parametrize("friction", FORMULATIONS)
@pytest.mark.parametrize("degrees", [20.0, 30.0])
def test_box_on_an_incline_sticks_or_slides_at_g_sin_minus_mu_g_cos(friction, degrees):
    """tan 20 deg < 0.5: it sticks; tan 30 deg > 0.5: it slides at g (sin - mu cos)."""
    th = np.radians(degrees)
    normal = (-np.sin(th), 0.0, np.cos(th))
    model = _box(friction, normal)
    poses = [np.array([0.1 * normal[0], 0.1 * normal[2], p]) for p in (th, -th)]
    q0 = next(q for q in poses if np.abs(model.contact_model.distances(q[None])).max() < 1e-12)
    xs = _run(model, np.concatenate([q0, np.zeros(3)]), 0.0, 100)
    speed = np.hypot(xs[:, 3], xs[:, 4])
    accel = max(G * (np.sin(th) - MU * np.cos(th)), 0.0)
    if accel == 0.0:
        assert speed.max() < 1e-8
    else:
        np.testing.assert_allclose(speed[-1], accel * 1.0, rtol=SPEED_RTOL[friction])


@pytest.mark.parametrize("friction", FORMULATIONS)
def test_ball_lands_then_rolls_at_five_sevenths(friction):
    """A solid ball thrown horizontally lands, slides and rolls on at 5/7 of its speed (the
    angular momentum about the contact point is kept), under either formulation."""
    scene = replace(Scene.load("ball_throw"), friction_model=friction)
    model = build_scene_model(scene)
    xs = _run(model, model.x0, 0.0, 100)
    v0 = np.linalg.norm(model.v0[-3:-1]) if model.plant.num_positions() == 7 else 1.0
    plant, ctx = model.plant, model.plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(ctx, xs[-1])
    body = plant.GetBodyByName("ball")
    vel = body.EvalSpatialVelocityInWorld(ctx)
    speed = np.hypot(*vel.translational()[:2])
    assert speed == pytest.approx(5 / 7 * v0, rel=1e-6)
    # rolling: the contact point (0.05 m below the centre) does not slip
    contact_point = vel.translational() + np.cross(vel.rotational(), [0.0, 0.0, -0.05])
    assert np.abs(contact_point).max() < 1e-6


@pytest.mark.parametrize("smoothing", [Fixed(1e-4), ContactAware(1e-3, 0.02)], ids=repr)
def test_anitescu_steps_converge_under_smoothing_where_stewart_trinkle_need_not(smoothing):
    """solo12 standing under its posture controller: the Anitescu formulation converges on
    every step (the benchmark bench_convergence.py measures both over 10^4 steps)."""
    from drake_abs.multibody.posture import STANDING_GAINS, standing_controller

    model = build_scene_model("solo12_drop")
    feet, kp, kd = STANDING_GAINS["solo12_drop"]
    hold, _ = standing_controller(model, feet, kp, kd)
    stepper = model.stepper(smoothing=smoothing, friction="anitescu")
    rng = np.random.default_rng(3)
    x = np.tile(model.x0, (8, 1))
    x[:, model.contact_model.nq :] += 0.1 * rng.standard_normal((8, model.contact_model.nv))
    for _ in range(150):
        r = stepper.step(x, hold(x) + rng.normal(0.0, 0.2, (8, model.contact_model.nu)),
                         jacobians=False)  # fmt: skip
        assert r.converged.all()
        x = r.x_next
    assert model.contact_model.distances(x[:, : model.contact_model.nq]).min() > -1e-3


def test_pruning_leaves_an_exact_anitescu_step_unchanged():
    """Far candidates left out of the LCP change nothing under exact contact: the generator
    rows' regularization is local to each row (a mean over the rows in play would move the
    others' by ~1e-10 when a far contact is pruned)."""
    model = build_scene_model(replace(Scene.load("box_push"), friction_model="anitescu"))
    rng = np.random.default_rng(5)
    x = np.tile(model.x0, (6, 1))
    x[:, 2] = rng.uniform(-0.2, 0.2, 6)  # tilted: one bottom corner down, the top ones far
    x[:, 1] = 0.1 + 0.2 * np.abs(np.sin(x[:, 2])) + rng.uniform(0.0, 0.003, 6)
    x[:, 3:] = rng.normal(0.0, 0.5, (6, 3))
    u = rng.uniform(-5.0, 5.0, (6, 1))
    pruned = model.stepper().step(x, u)
    full = model.stepper(activation_distance=float("inf")).step(x, u)
    assert not pruned.active.all() and pruned.impulse.max() > 1e-3  # pruned, and in contact
    assert pruned.converged.all() and full.converged.all()
    np.testing.assert_allclose(pruned.x_next, full.x_next, rtol=0, atol=1e-13)
    np.testing.assert_allclose(pruned.dx_dx, full.dx_dx, rtol=0, atol=1e-9)
