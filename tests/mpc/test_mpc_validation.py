"""Silent wrong answers of the MPC found from outside (issue 13, item 4): absurd but finite states,
a stale plan after a rejected update, infinite bounds on the wrong side, a missing horizon and
empty batches. A solution labelled solved satisfies the hard input box on the current data."""

import numpy as np
import pytest
from mpc_setup import A_H, B_H, THETA, U_MAX, U_MIN, U_REF, X_MAX, X_MIN, X_REF

from drake_abs.engine import LinearStepper
from drake_abs.mpc.graybox import Schedule, TrackingCost, closed_loop, graybox_optimize, step_size
from drake_abs.mpc.policy import MpcPolicy
from drake_abs.mpc.qp_mpc import USABLE, MpcSpec, MpcStatus, QpMpc


def spec(**kw) -> MpcSpec:
    base = {
        "A": A_H, "B": B_H, "horizon": 12, "x_ref": X_REF, "u_ref": U_REF,
        "u_min": U_MIN, "u_max": U_MAX, "x_min": X_MIN, "x_max": X_MAX,
    }  # fmt: skip
    return MpcSpec(**{**base, **kw})


def absurd_state(size: float) -> np.ndarray:
    x = np.zeros(12)
    x[0], x[3] = size, -size  # far away and moving further
    return x


def assert_in_input_box(sol, tol=1e-3):
    """A usable solution's whole input plan lies in the hard box (rad/s; OSQP's tolerance on
    the quadcopter's bounds is ~1e-4 rad/s)."""
    assert sol.status in USABLE and not sol.fallback
    assert np.all(sol.u_plan >= U_MIN - tol) and np.all(sol.u_plan <= U_MAX + tol), sol.u_plan


@pytest.mark.parametrize("size", [1e3, 1e6, 1e10, 1e15, 1e20, 1e25, 1e29])
def test_a_solution_labelled_solved_satisfies_the_input_box_at_any_finite_state(size):
    """At |x| = 1e15 OSQP reported SOLVED with u0 66 rad/s below the lower bound (its criterion
    is relative to |G z|); such a solution is now FAILED with the fallback control."""
    mpc = QpMpc(spec(), THETA)
    sol = mpc.solve(absurd_state(size), jacobians=True)
    if sol.fallback:
        assert sol.status == MpcStatus.FAILED
        np.testing.assert_array_equal(sol.u0, np.clip(U_REF, U_MIN, U_MAX))
        assert sol.u_plan is None and not sol.du0_dx.any() and not sol.du0_dtheta.any()
    else:
        assert_in_input_box(sol)
    if size >= 1e15:  # reproduced: these were SOLVED outside the box
        assert sol.fallback


@pytest.mark.parametrize("size", [1e31, 1e100, 1e300])
def test_a_state_beyond_osqps_infinity_never_returns_the_previous_plan(size):
    """|x| ~ 1e31: OSQP rejected the update and returned the previous problem's plan as
    SOLVED."""
    mpc = QpMpc(spec(), THETA)
    previous = mpc.solve(np.zeros(12))
    sol = mpc.solve(absurd_state(size), jacobians=True)
    assert sol.status == MpcStatus.FAILED and sol.fallback
    assert not np.array_equal(sol.u0, previous.u0)
    np.testing.assert_array_equal(sol.u0, np.clip(U_REF, U_MIN, U_MAX))
    assert sol.u_plan is None and sol.x_plan is None
    again = mpc.solve(np.zeros(12))  # the controller is still usable
    assert again.status == MpcStatus.SOLVED
    np.testing.assert_allclose(again.u0, previous.u0, rtol=1e-8, atol=1e-8)


class _IgnoresUpdates:
    """An OSQP whose data updates are silently dropped (as OSQP does when it rejects them)."""

    def __init__(self, inner):
        self.inner = inner

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def update(self, **kwargs):
        pass


def test_a_stale_solution_of_a_previous_problem_is_not_reported_as_solved():
    """The re-check on the current data catches a stale solution whatever made it stale."""
    mpc = QpMpc(spec(), THETA)
    previous = mpc.solve(np.zeros(12))
    mpc._osqp = _IgnoresUpdates(mpc._osqp)
    x = np.zeros(12)
    x[2] = 1.0
    sol = mpc.solve(x)
    assert sol.status == MpcStatus.FAILED and sol.fallback
    assert not np.array_equal(sol.u0, previous.u0)


def test_ordinary_states_are_still_solved_and_unchanged_by_the_check(rng):
    mpc = QpMpc(spec(), THETA)
    for _ in range(50):
        x = rng.normal(size=12) * rng.choice([0.1, 1.0, 3.0])
        sol = mpc.solve(x)
        assert sol.status == MpcStatus.SOLVED
        assert_in_input_box(sol)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"u_min": np.full(4, np.inf), "u_max": np.full(4, np.inf)}, "u_min"),
        ({"u_min": np.full(4, -np.inf), "u_max": np.full(4, -np.inf)}, "u_max"),
        ({"x_min": np.full(12, np.inf), "x_max": np.full(12, np.inf)}, "x_min"),
        ({"x_min": np.full(12, -np.inf), "x_max": np.full(12, -np.inf)}, "x_max"),
        ({"horizon": None}, "horizon"),
        ({"horizon": True}, "horizon"),
        ({"horizon": 2.5}, "horizon"),
        ({"horizon": "12"}, "horizon"),
        ({"horizon": -3}, "horizon"),
    ],
)
def test_bad_bounds_and_horizons_raise_value_error_naming_the_field(kwargs, name):
    with pytest.raises(ValueError, match=name):
        spec(**kwargs)


def test_infinite_bounds_on_the_open_side_mean_unbounded():
    unbounded = QpMpc(spec(u_min=np.full(4, -np.inf), u_max=np.full(4, np.inf)), THETA)
    sol = unbounded.solve(np.zeros(12))
    assert sol.status == MpcStatus.SOLVED
    assert np.any(sol.u_plan > U_MAX[0] + 1.0)  # the 630 rad/s bound is gone
    half = QpMpc(spec(u_min=U_MIN, u_max=np.full(4, np.inf)), THETA).solve(np.zeros(12))
    assert half.status == MpcStatus.SOLVED and np.all(half.u_plan >= U_MIN - 1e-6)
    assert np.array_equal(spec(horizon=np.int64(3)).horizon, 3)


def test_tracking_cost_and_closed_loop_arguments_name_the_argument():
    with pytest.raises(ValueError, match="x_min"):
        TrackingCost(np.eye(12), np.eye(4), np.eye(12), X_REF, U_REF, np.full(12, np.inf), X_MAX)
    cost = TrackingCost(np.eye(12), np.eye(4), np.eye(12), X_REF, U_REF, X_MIN, X_MAX)
    mpc = QpMpc(spec(), THETA)
    for steps in (None, True, 2.5):
        with pytest.raises(ValueError, match="steps"):
            closed_loop(mpc, THETA, np.zeros(12), steps, LinearStepper(A_H, B_H), cost)
    with pytest.raises(ValueError, match="iterations"):
        graybox_optimize(
            lambda theta, grad: None, THETA, iterations=None, schedule=Schedule(eta=1.0),
            rng=np.random.default_rng(0),
        )  # fmt: skip
    with pytest.raises(ValueError, match="k"):
        step_size(None)


def test_empty_batches_give_empty_arrays_of_the_right_shapes():
    policy = MpcPolicy(QpMpc(spec(), THETA))
    x = np.zeros((0, 12))
    n = policy.n_params
    assert policy.act(THETA, x).shape == (0, 4)
    du_dx, du_dth = policy.jacobians(THETA, x)
    assert du_dx.shape == (0, 4, 12) and du_dth.shape == (0, 4, n)
    g_x, g_th = policy.vjp(THETA, x, np.zeros((0, 4)))
    assert g_x.shape == (0, 12) and g_th.shape == (0, n)
    u, vjp = policy.pullback(THETA, x)
    assert u.shape == (0, 4)
    assert [a.shape for a in vjp(np.zeros((0, 4)))] == [(0, 12), (0, n)]
    assert policy.solutions == []


def test_vjp_cotangent_of_the_wrong_shape_names_g_u():
    policy = MpcPolicy(QpMpc(spec(), THETA))
    with pytest.raises(ValueError, match="g_u"):
        policy.vjp(THETA, np.zeros((2, 12)), np.zeros((3, 4)))
