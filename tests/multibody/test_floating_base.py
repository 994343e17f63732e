"""Floating bases that pass through every orientation, and energy over long rollouts.

The shipped ball floats on a quaternion floating joint (models/ball_floating.urdf): q = (qw, qx,
qy, qz, x, y, z), v = (w, v) in the world frame. Issue 13 item 4: on the Euler-angle chain
(models/ball.sdf, q = (x, y, z, yaw, pitch, roll)) a 1e-22 perturbation of the rolling ball's
yaw and pitch grew through the singularity at pitch = +-pi/2 until its energy jumped from
0.17 J to 1e214 J (step ~5100 at h = 0.01, ~260 at h = 0.05), every step converged. Contact here
is inelastic with Coulomb friction, and the semi-implicit step loses m g^2 h^2 / 2 per step in
flight: the energy (kinetic plus gravity's potential) may only fall, step after step.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs import ContactAware, Exact
from drake_abs.multibody import ModelSpec, Scene, build_scene_model
from drake_abs.multibody.drake_dynamics import MultibodyContactModel
from drake_abs.multibody.floating import normalize_quaternions
from drake_abs.multibody.pinocchio_dynamics import PinocchioContactModel

PROVIDERS = {"pinocchio": PinocchioContactModel, "drake": MultibodyContactModel}
#: J: rounding of one step's energy (about 1 J here) is ~1e-16; a real gain is far larger
ENERGY_TOL = 1e-12


def _rotation(axis, angle) -> np.ndarray:
    """The unit quaternion (qw, qx, qy, qz) of a rotation by ``angle`` about ``axis``."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


def _energy(model, x: np.ndarray) -> np.ndarray:
    """Kinetic plus gravity's potential energy (J) of each state (B, nx)."""
    plant = model.plant
    ctx = plant.CreateDefaultContext()
    out = np.empty(len(x))
    for b, xb in enumerate(x):
        plant.SetPositionsAndVelocities(ctx, xb)
        out[b] = plant.CalcKineticEnergy(ctx) + plant.CalcPotentialEnergy(ctx)
    return out


def _energy_rollout(model, x0: np.ndarray, steps: int, u=None, work=None):
    """Roll a batch from x0 (B, nx) with exact contact: (states (steps + 1, B, nx), energies
    (steps + 1, B), the largest energy gain of one step beyond ``work(x, x_next)`` (J), whether
    every step converged). Stops at a non-finite state or an energy above 1e6 J."""
    stepper = model.stepper(smoothing=Exact())
    nu = model.contact_model.nu
    u = np.zeros((len(x0), nu)) if u is None else u
    xs, energies = [x0], [_energy(model, x0)]
    gain, converged = -np.inf, True
    for _ in range(steps):
        r = stepper.step(xs[-1], u, jacobians=False)
        converged &= bool(r.converged.all())
        if not np.isfinite(r.x_next).all():
            return np.array(xs), np.array(energies), np.inf, converged
        e = _energy(model, r.x_next)
        spent = 0.0 if work is None else work(xs[-1], r.x_next)
        gain = max(gain, float(np.max(e - energies[-1] - spent)))
        xs.append(r.x_next)
        energies.append(e)
        if e.max() > 1e6:  # blown up: nothing more to learn
            break
    return np.array(xs), np.array(energies), gain, converged


def _perturbed_balls(model, scale: float) -> np.ndarray:
    """The shipped throw (from 0.5 m at 1 m/s along +y: it lands, slides, then rolls about x)
    with its orientation turned by ``scale`` rad about z (yaw), y (pitch) and a skew axis."""
    x0 = np.tile(model.x0, (3, 1))
    for b, axis in enumerate([(0, 0, 1), (0, 1, 0), (1, -1, 1)]):
        x0[b, :4] = _rotation(axis, scale)
    return x0


@pytest.mark.parametrize(("h", "steps"), [(0.01, 10_000), (0.05, 400)])
def test_the_rolling_ball_never_gains_energy(h, steps):
    """Issue 13 item 4 on the quaternion floating base: 1e-22 rad perturbations of the rolling
    ball's orientation (and larger ones), 10^4 steps at h = 0.01 and 400 at h = 0.05 (past the
    step where the Euler chain blew up): every step converges, the energy never rises, the
    quaternion stays unit, and the ball rolls on at 5/7 of its throwing speed."""
    model = build_scene_model(replace(Scene.load("ball_throw"), time_step=h))
    assert model.contact_model.quaternion_starts == (0,)
    x0 = np.concatenate([_perturbed_balls(model, 1e-22), _perturbed_balls(model, 1e-3)])
    xs, energies, gain, converged = _energy_rollout(model, x0, steps)
    assert len(xs) == steps + 1 and converged
    assert gain <= ENERGY_TOL, f"the energy rose by {gain:.3g} J in one step"
    np.testing.assert_allclose(np.linalg.norm(xs[..., :4], axis=-1), 1.0, rtol=0, atol=1e-12)
    r = 0.05  # rolling along +y about the world x axis: v_y = -r w_x = 5/7 m/s, on the ground
    w, v = xs[-1, :, 7:10], xs[-1, :, 10:]
    np.testing.assert_allclose(v[:, 1], 5 / 7, atol=1e-6)
    np.testing.assert_allclose(v[:, 1] + r * w[:, 0], 0, atol=1e-6)
    np.testing.assert_allclose(xs[-1, :, 6], r, atol=1e-9)
    rolling = 0.2 * 9.81 * r + 0.5 * 0.2 * (5 / 7) ** 2 * (1 + 2 / 5)  # 0.17 J
    np.testing.assert_allclose(energies[-1], rolling, rtol=1e-6)


def test_the_energy_check_catches_the_euler_chain_blowing_up():
    """The same check on ball.sdf's Euler-angle floating base (pinocchio, fast) at h = 0.05:
    the 1e-22 perturbation grows through pitch = +-pi/2 and the energy explodes (measured:
    step ~260), every step still converged; the check above would fail there."""
    euler = replace(
        Scene.load("ball_throw"),
        models=(ModelSpec("drake_abs:models/ball.sdf"),),
        time_step=0.05,
        initial_state={"q": [0, 0, 0.5, 1e-22, 1e-22, 0], "v": [0, 1.0, 0, 0, 0, 0]},
        dynamics="auto",
    )
    model = build_scene_model(euler)
    assert model.contact_model.quaternion_starts == ()
    with np.errstate(over="ignore", invalid="ignore"):
        _, energies, gain, converged = _energy_rollout(model, model.x0[None], 400)
    assert converged
    assert gain > 1.0 and energies.max() > 1e3


def test_energy_check_in_a_long_box_push():
    """The pushed box (2 N against 0.5 m g = 4.9 N of friction) for 10^4 steps: it slides, stops
    and stays stuck; the energy never rises by more than the push's work over the step."""
    model = build_scene_model("box_push")
    assert model.contact_model.nu == 1
    B = model.plant.MakeActuationMatrix()
    u = np.array([[2.0]])
    nq = model.contact_model.nq

    def work(x, x_next):  # generalized force times the displacement (qdot = v here)
        return (x_next[:, :nq] - x[:, :nq]) @ (B @ u[0])

    xs, energies, gain, converged = _energy_rollout(model, model.x0[None], 10_000, u, work)
    assert len(xs) == 10_001 and converged
    assert gain <= 1e-9, f"the energy rose by {gain:.3g} J beyond the push's work"
    assert energies[-1, 0] < energies[0, 0]
    np.testing.assert_allclose(xs[-1000:, 0, nq:], 0, atol=1e-9)  # at rest


# --- the projection and the step's Jacobians -------------------------------------------------


def _contact_state(model) -> np.ndarray:
    """Tilted and spinning, the ball 0.5 mm above the ground, landing at 0.3 m/s while moving
    at 1 m/s: it slides (too little normal impulse to stop the slip)."""
    x = model.x0.copy()
    x[:4] = _rotation((0.3, -0.4, 0.2), 2.0)
    x[4:7] = [0.1, -0.2, 0.0505]
    x[7:] = [0.5, -0.3, 2.0, 0.2, 1.0, -0.3]
    return x


def _tangent_basis(quat: np.ndarray) -> np.ndarray:
    """(4, 3): an orthonormal basis of the unit sphere's tangent space at ``quat``."""
    return np.linalg.svd(np.eye(4) - np.outer(quat, quat))[0][:, :3]


@pytest.mark.parametrize("dynamics", ["pinocchio", "drake"])
@pytest.mark.parametrize("smoothing", [Exact(), ContactAware(1e-3, 0.02)], ids=["exact", "abs"])
def test_step_jacobians_match_central_differences_along_the_unit_sphere(smoothing, dynamics):
    """dx+/dx, dx+/dtheta with the projection: against central differences of the step along
    the quaternion's tangent directions (states on the unit sphere), the position and the
    velocity; the quaternion's rows are tangent to the sphere at q+, and a radial change of q
    changes nothing (the step depends on the orientation only). With either provider."""
    model = build_scene_model(replace(Scene.load("ball_throw"), dynamics=dynamics))
    assert isinstance(model.contact_model, PROVIDERS[dynamics])
    stepper = model.stepper(smoothing=smoothing)
    x = _contact_state(model)
    r = stepper.step(x[None], np.zeros((1, 0)), parameters=True)
    assert r.converged.all() and r.impulse[0, 0] > 1e-4
    q_next = r.x_next[0, :4]
    assert np.linalg.norm(q_next) == pytest.approx(1.0, abs=1e-15)
    T = _tangent_basis(x[:4])

    # coordinates: (3 tangent, 3 position, 6 velocity) -> x, a retraction onto the sphere
    def chart(z):
        quat = x[:4] + T @ z[:3]
        return np.concatenate([quat / np.linalg.norm(quat), z[3:6], z[6:]])

    z0 = np.concatenate([np.zeros(3), x[4:]])

    def step(z):
        return stepper.step(chart(z)[None], np.zeros((1, 0)), jacobians=False).x_next[0]

    fd = central_difference(step, z0, eps=1e-7)
    dchart = np.zeros((13, 12))
    dchart[:4, :3] = T  # the chart's derivative at z0 (x[:4] is unit)
    dchart[4:, 3:] = np.eye(9)
    analytic = r.dx_dx[0] @ dchart
    np.testing.assert_allclose(analytic, fd, atol=1e-6 * (1 + np.abs(fd).max()))
    # the quaternion rows of every Jacobian lie in the tangent space at q+
    for jac in (r.dx_dx[0], r.dx_dtheta[0]):
        assert np.abs(q_next @ jac[:4]).max() < 1e-12
    # q -> c q changes nothing
    assert np.abs(r.dx_dx[0] @ np.concatenate([x[:4], np.zeros(9)])).max() < 1e-12


def test_without_the_projection_the_quaternion_leaves_the_sphere():
    """Why the projection is there: q + h N(q) v moves along the tangent (|N v| = |w| / 2), so
    a unit norm grows to sqrt(1 + h^2 |w|^2 / 4), about 1 + h^2 |w|^2 / 8 (here 20 rad/s at
    10 ms: 5e-3) per step."""
    model = build_scene_model("ball_throw")
    cm = model.contact_model
    x = model.x0.copy()
    x[7:10] = [20.0, 0.0, 0.0]
    quant = cm.quantities(x[None, :7], x[None, 7:], np.zeros((1, 0)), np.array([], int),
                          derivatives=False)  # fmt: skip
    v_next = quant.v_free[0]  # in flight
    raw = x[:4] + cm.h * quant.N[0][:4] @ v_next
    assert np.linalg.norm(raw) == pytest.approx(np.sqrt(1 + cm.h**2 * 20.0**2 / 4), abs=1e-14)
    r = model.stepper().step(x[None], np.zeros((1, 0)))
    np.testing.assert_allclose(r.x_next[0, :4], raw / np.linalg.norm(raw), rtol=0, atol=1e-15)


def test_normalize_quaternions_chains_the_jacobians(rng):
    """The projection alone, two quaternion blocks of a random map g (B = 2): the chained
    Jacobian is that of x -> P(g(x)), central differences agree."""
    A = rng.standard_normal((11, 5))
    b = rng.standard_normal(11)
    starts = (0, 6)

    def g(p):
        return np.tanh(A @ p) + b

    def projected(p):
        out = {"x_next": g(p)[None].copy()}
        normalize_quaternions(out, starts)
        return out["x_next"][0]

    p = rng.standard_normal((2, 5))
    jac = np.stack([(1 - np.tanh(A @ pb) ** 2)[:, None] * A for pb in p])
    out = {"x_next": np.stack([g(pb) for pb in p]), "dx_dx": jac.copy(), "dx_du": jac[..., :2]}
    normalize_quaternions(out, starts)
    for k in range(2):
        fd = central_difference(projected, p[k])
        np.testing.assert_allclose(out["dx_dx"][k], fd, atol=1e-8)
        np.testing.assert_allclose(out["dx_du"][k], fd[:, :2], atol=1e-8)
        for s in starts:
            assert np.linalg.norm(out["x_next"][k, s : s + 4]) == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_array_equal(out["x_next"][:, 4:6], np.stack([g(pb) for pb in p])[:, 4:6])


def test_two_free_balls_each_keep_a_unit_quaternion():
    """Any number of free bodies: two balls (two model instances of the URDF), one landing and
    one in the air, both spinning; each quaternion block is found and kept unit (the provider:
    pinocchio, which evaluates quaternion floating joints in Drake's coordinates)."""
    scene = replace(
        Scene.load("ball_throw"),
        models=(
            ModelSpec("drake_abs:models/ball_floating.urdf", name="a"),
            ModelSpec("drake_abs:models/ball_floating.urdf", name="b"),
        ),
        contacts=tuple(replace(Scene.load("ball_throw").contacts[0], model=m) for m in "ab"),
        initial_state={},
        dynamics="auto",
    )
    model = build_scene_model(scene)
    cm = model.contact_model
    assert isinstance(cm, PinocchioContactModel)
    assert cm.nq == 14 and cm.nv == 12 and cm.quaternion_starts == (0, 7)
    np.testing.assert_array_equal(model.q0[[0, 7]], 1.0)  # the default: upright, at the origin
    x = np.concatenate([model.q0, np.zeros(12)])
    x[6], x[13] = 0.06, 1.0  # heights
    x[14:17], x[17:20] = [3.0, -1.0, 2.0], [0.0, 1.0, -1.0]  # ball a: spinning, landing
    x[20:23] = [0.0, 5.0, 5.0]  # ball b: spinning in the air
    stepper = model.stepper()
    for _ in range(30):
        r = stepper.step(x[None], np.zeros((1, 0)), jacobians=False)
        assert r.converged.all()
        x = r.x_next[0]
        assert np.linalg.norm(x[0:4]) == pytest.approx(1.0, abs=1e-14)
        assert np.linalg.norm(x[7:11]) == pytest.approx(1.0, abs=1e-14)
    assert cm.distances(x[None, :14])[0, 0] == pytest.approx(0.0, abs=1e-9)  # a on the ground


def test_a_scene_quaternion_must_be_unit():
    scene = Scene.load("ball_throw")
    bad = replace(scene, initial_state=replace(scene.initial_state, q=[2, 0, 0, 0, 0, 0, 0.5]))
    with pytest.raises(ValueError, match="unit quaternion"):
        build_scene_model(bad)
    near_q = [0.7071, 0.7071, 0, 0, 0, 0, 0.5]
    near = replace(scene, initial_state=replace(scene.initial_state, q=near_q))
    assert np.linalg.norm(build_scene_model(near).q0[:4]) == pytest.approx(1.0, abs=1e-15)
