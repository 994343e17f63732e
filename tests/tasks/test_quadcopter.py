"""The 12-state quadcopter (paper 003 section 7): analytic Euler-step Jacobians against central
differences, its conventions against Drake's rotations, hover, batching, bad input, and the Drake
system in double and AutoDiffXd."""

import numpy as np
import pytest
from numdiff import central_difference
from pydrake.autodiffutils import InitializeAutoDiff
from pydrake.math import RollPitchYaw

from drake_abs.systems import autodiff
from drake_abs.systems.quadcopter_plant import QuadcopterPlant, QuadcopterPlant_
from drake_abs.tasks import quadcopter as qc

PRM = qc.QuadcopterParams()


def random_states(rng, n):
    x = rng.normal(size=(n, 12)) * np.r_[2, 2, 2, 1, 1, 1, 0.5, 0.5, 1.5, 0.4, 0.4, 0.4]
    u = PRM.hover_speed + rng.normal(size=(n, 4)) * 30.0
    return x, u


def test_step_jacobians_match_central_differences(rng):
    xs, us = random_states(rng, 6)
    for x, u in zip(xs, us, strict=True):
        s = qc.step(x, u, PRM, jacobians=True)
        fx = central_difference(lambda z, u=u: qc.step(z, u, PRM).x_next, x, 1e-6)
        fu = central_difference(lambda w, x=x: qc.step(x, w, PRM).x_next, u, 1e-4)
        np.testing.assert_allclose(s.dx_dx, fx, rtol=1e-7, atol=1e-8)
        np.testing.assert_allclose(s.dx_du, fu, rtol=1e-7, atol=1e-10)


def test_batched_step_equals_one_at_a_time(rng):
    xs, us = random_states(rng, 6)
    batch = qc.step(xs.reshape(2, 3, 12), us.reshape(2, 3, 4), PRM, jacobians=True)
    assert batch.dx_dx.shape == (2, 3, 12, 12) and batch.dx_du.shape == (2, 3, 12, 4)
    for i, (x, u) in enumerate(zip(xs, us, strict=True)):
        one = qc.step(x, u, PRM, jacobians=True)
        # the same arithmetic, vectorised: equal up to the last bit of summation order
        np.testing.assert_allclose(
            batch.x_next.reshape(6, 12)[i], one.x_next, rtol=1e-15, atol=1e-15
        )
        np.testing.assert_allclose(
            batch.dx_dx.reshape(6, 12, 12)[i], one.dx_dx, rtol=1e-15, atol=1e-15
        )


def test_hover_is_an_equilibrium_at_any_position_and_yaw():
    # the authors' model hovers at about 620.6 rad/s
    assert PRM.hover_speed == pytest.approx(620.61, abs=0.01)
    x = np.zeros(12)
    x[:3] = (-6.0, -3.5, 2.0)
    x[8] = 0.7
    np.testing.assert_allclose(qc.step(x, PRM.hover_input(), PRM).x_next, x, atol=1e-14)


def test_thrust_direction_is_drakes_roll_pitch_yaw_z_axis(rng):
    """v+ - v = dt (T/m R_WB e_z - g e_z) at zero velocity, with R_WB = RollPitchYaw(phi, theta,
    psi) (Z-Y-X)."""
    for _ in range(5):
        x = np.zeros(12)
        x[6:9] = rng.uniform(-1.0, 1.0, 3)
        u = np.full(4, 600.0)
        a = (qc.step(x, u, PRM).x_next[3:6]) / PRM.time_step
        thrust = PRM.thrust_coefficient * np.sum(u**2) / PRM.mass
        R = RollPitchYaw(*x[6:9]).ToRotationMatrix().matrix()
        np.testing.assert_allclose(a, thrust * R[:, 2] - [0, 0, PRM.gravity], atol=1e-12)


def test_rotor_layout_and_yaw_torque_signs():
    """Rotor 4 (+y) rolls positive, rotor 3 (-x) pitches positive, rotors 2 and 4 yaw positive."""
    base = qc.dynamics(np.zeros(12), PRM.hover_input(), PRM)[0]
    for rotor, axis, sign in ((3, 9, +1), (1, 9, -1), (2, 10, +1), (0, 10, -1)):
        u = PRM.hover_input()
        u[rotor] += 10.0
        f = qc.dynamics(np.zeros(12), u, PRM)[0]
        assert np.sign(f[axis] - base[axis]) == sign, (rotor, axis)
    for rotor, sign in ((0, -1), (1, +1), (2, -1), (3, +1)):
        u = PRM.hover_input()
        u[rotor] += 10.0
        assert np.sign(qc.dynamics(np.zeros(12), u, PRM)[0][11]) == sign


def test_paper_constraints():
    x_min, x_max = qc.QuadcopterConstraints().state_bounds()
    u_min, u_max = qc.QuadcopterConstraints().input_bounds()
    assert np.all(np.isinf(x_max[:3])) and np.all(x_max[3:6] == 2.0)
    np.testing.assert_allclose(x_max[6:9], np.pi / 4)
    np.testing.assert_allclose(x_max[9:], np.pi / 8)
    np.testing.assert_array_equal(x_min, -x_max)
    assert np.all(u_min == 0.0) and np.all(u_max == 630.0)


@pytest.mark.parametrize(
    ("x", "u", "name"),
    [
        (np.r_[np.nan, np.zeros(11)], np.zeros(4), "x"),
        (np.zeros(12), np.r_[np.inf, np.zeros(3)], "u"),
        (np.zeros(11), np.zeros(4), "x"),
        (np.zeros(12), np.zeros(3), "u"),
        (np.zeros((2, 12)), np.zeros((3, 4)), "x and u"),
    ],
)
def test_bad_input_raises_naming_the_argument(x, u, name):
    with pytest.raises(ValueError, match=name):
        qc.step(x, u, PRM)


def test_bad_params_raise():
    with pytest.raises(ValueError, match="mass"):
        qc.QuadcopterParams(mass=-1.0)
    with pytest.raises(ValueError, match="inertia"):
        qc.QuadcopterParams(inertia=(1.0, 1.0))


def test_inputs_are_not_mutated(rng):
    x, u = random_states(rng, 1)
    x0, u0 = x.copy(), u.copy()
    qc.step(x, u, PRM, jacobians=True)
    np.testing.assert_array_equal(x, x0)
    np.testing.assert_array_equal(u, u0)


def test_drake_plant_steps_the_core_in_double_and_autodiff(rng):
    (x,), (u,) = random_states(rng, 1)
    core = qc.step(x, u, PRM, jacobians=True)
    plant = QuadcopterPlant(PRM)
    context = plant.CreateDefaultContext()
    plant.SetInitialState(context, x)
    plant.u_port.FixValue(context, u)
    update = plant.EvalUniquePeriodicDiscreteUpdate(context)
    np.testing.assert_array_equal(update.get_vector(0).CopyToVector(), core.x_next)

    ad = plant.ToAutoDiffXd()
    assert isinstance(ad, QuadcopterPlant_[autodiff.AutoDiffXd])
    ctx = ad.CreateDefaultContext()
    seed = np.eye(16)
    ad.SetInitialState(ctx, InitializeAutoDiff(x.reshape(-1, 1), seed[:12]).ravel())
    ad.u_port.FixValue(ctx, InitializeAutoDiff(u.reshape(-1, 1), seed[12:]).ravel())
    out = ad.EvalUniquePeriodicDiscreteUpdate(ctx).get_vector(0).CopyToVector()
    (value,), (grad,) = autodiff.split([out])
    np.testing.assert_array_equal(value, core.x_next)
    np.testing.assert_array_equal(grad[:, :12], core.dx_dx)
    np.testing.assert_array_equal(grad[:, 12:], core.dx_du)
