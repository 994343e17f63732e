"""The MPC as a Drake system and the quadcopter + MPC + cost diagram: outputs equal the core,
AutoDiffXd derivatives (injected from the KKT Jacobians) equal the core's and central
differences, the LQR closed loop's Jacobian, and the status port / rollout record of unsolved
QPs."""

import numpy as np
import pytest
from mpc_setup import (
    A_H,
    B_H,
    K_LQR,
    PRM,
    Q_D,
    R_D,
    THETA,
    U_MAX,
    U_MIN,
    U_REF,
    X_MAX,
    X_MIN,
    X_REF,
)
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from drake_abs.diagrams.quadcopter_mpc import (
    ClosedLoopCost_,
    make_quadcopter_mpc_diagram,
    simulate_closed_loop,
)
from drake_abs.mpc.graybox import TrackingCost, closed_loop
from drake_abs.mpc.qp_mpc import MpcSpec, MpcStatus, QpMpc
from drake_abs.systems import autodiff
from drake_abs.systems.mpc_controller import MpcController, MpcController_, status_name
from drake_abs.tasks import quadcopter as qc

P_C = np.diag(np.r_[np.ones(6), 1e3 * np.ones(3), np.ones(3)])
COST = TrackingCost(np.diag(Q_D), np.diag(R_D), P_C, X_REF, U_REF, X_MIN, X_MAX, 300.0)


def paper_spec(horizon=12, **kw):
    return MpcSpec(A_H, B_H, horizon, X_REF, U_REF, U_MIN, U_MAX, X_MIN, X_MAX, **kw)


quad_plant = qc.QuadcopterStepper(PRM)


def test_controller_outputs_the_core_solution_and_its_status():
    controller = MpcController(paper_spec(), THETA)
    context = controller.CreateDefaultContext()
    np.testing.assert_array_equal(controller.GetTheta(context), THETA)
    controller.x_port.FixValue(context, np.zeros(12))
    core = QpMpc(paper_spec(), THETA).solve(np.zeros(12))
    np.testing.assert_array_equal(controller.u_port.Eval(context), core.u0)
    status = controller.status_port.Eval(context)
    assert status_name(status[0]) == "SOLVED" and status[1] == 0.0 and status[2] > 0


def test_autodiff_controller_injects_du0_dx_and_du0_dtheta(rng):
    x = X_REF + rng.normal(size=12) * 0.5
    theta = THETA + 0.05 * rng.normal(size=THETA.size)
    core = QpMpc(paper_spec(), theta).solve(x, jacobians=True)
    ad = MpcController(paper_spec(), THETA).ToAutoDiffXd()
    assert isinstance(ad, MpcController_[AutoDiffXd])
    context = ad.CreateDefaultContext()
    n = 12 + THETA.size
    seed = np.eye(n)
    ad.x_port.FixValue(context, InitializeAutoDiff(x.reshape(-1, 1), seed[:12]).ravel())
    ad.SetTheta(context, InitializeAutoDiff(theta.reshape(-1, 1), seed[12:]).ravel())
    (u,), (grad,) = autodiff.split([ad.u_port.Eval(context)])
    # Not bit-equal: the controller's OSQP instance was set up with THETA and updated to theta,
    # and OSQP recomputes its data scaling on update, so the two solves differ in roundoff
    # (1e-13 absolute on u0 ~ 600 rad/s seen with osqp 1.1.3). 1e-12 relative is ~5000 ulps.
    np.testing.assert_allclose(u, core.u0, rtol=1e-12, atol=0)
    np.testing.assert_allclose(grad[:, :12], core.du0_dx, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(grad[:, 12:], core.du0_dtheta, rtol=1e-10, atol=1e-10)
    # only theta carries derivatives (x is a plain value): d u / d theta alone
    context2 = ad.CreateDefaultContext()
    ad.x_port.FixValue(context2, np.array([AutoDiffXd(v) for v in x]))
    ad.SetTheta(context2, InitializeAutoDiff(theta.reshape(-1, 1)).ravel())
    (_,), (g2,) = autodiff.split([ad.u_port.Eval(context2)])
    np.testing.assert_allclose(g2, core.du0_dtheta, rtol=1e-10, atol=1e-10)


def test_status_port_reports_an_infeasible_qp_and_the_fallback_never_nan():
    x = X_REF.copy()
    x[3] = 5.0  # unreachable under the hard |v| <= 2 m/s constraint
    fallback = np.clip(U_REF, U_MIN, U_MAX)
    controller = MpcController(paper_spec(soft_state_constraints=False), THETA)
    context = controller.CreateDefaultContext()
    controller.x_port.FixValue(context, x)
    np.testing.assert_array_equal(controller.u_port.Eval(context), fallback)
    status = controller.status_port.Eval(context)
    assert status_name(status[0]) == "PRIMAL_INFEASIBLE" and status[1] == 1.0

    ad = controller.ToAutoDiffXd()
    context = ad.CreateDefaultContext()
    ad.x_port.FixValue(context, InitializeAutoDiff(x.reshape(-1, 1)).ravel())
    (u,), (grad,) = autodiff.split([ad.u_port.Eval(context)])
    np.testing.assert_array_equal(u, fallback)
    assert grad.shape == (4, 12) and not grad.any()
    status = ad.status_port.Eval(context)
    assert status_name(status[0].value()) == "PRIMAL_INFEASIBLE"


def test_controller_bad_input_raises_value_error_naming_it():
    controller = MpcController(paper_spec(), THETA)
    context = controller.CreateDefaultContext()
    controller.x_port.FixValue(context, np.r_[np.nan, np.zeros(11)])
    with pytest.raises(ValueError, match="x"):
        controller.u_port.Eval(context)
    with pytest.raises(ValueError, match="theta"):
        controller.SetTheta(context, np.zeros(3))


def test_diagram_equals_the_core_closed_loop_and_its_autodiff_gradient_equals_core_and_fd(rng):
    steps = 12
    spec = paper_spec(horizon=6)
    diagram = make_quadcopter_mpc_diagram(spec, THETA, COST, PRM)
    plain = simulate_closed_loop(diagram, THETA, np.zeros(12), steps)
    core = closed_loop(
        QpMpc(spec, THETA), THETA, np.zeros(12), steps, quad_plant, COST, gradient="exact"
    )
    # the diagram and the core loop drive the same solver through the same solves, but through
    # different drivers (Simulator events against a Python loop): roundoff-level agreement
    np.testing.assert_allclose(plain.x_final, core.x[-1], rtol=1e-12, atol=1e-12)
    assert plain.total == pytest.approx(core.total, rel=1e-13)
    assert plain.violation > 0 and plain.fallback_steps == 0
    np.testing.assert_array_equal(plain.status, np.zeros(steps, int))
    ad = simulate_closed_loop(diagram, THETA, np.zeros(12), steps, gradient="theta")
    assert ad.total == pytest.approx(core.total, rel=1e-13)
    np.testing.assert_allclose(ad.gradient, core.gradient, rtol=1e-9, atol=1e-9)
    for _ in range(2):  # central differences of the double diagram along random directions
        v = rng.normal(size=THETA.size)
        v /= np.linalg.norm(v)
        h = 1e-6
        up = simulate_closed_loop(diagram, THETA + h * v, np.zeros(12), steps).total
        down = simulate_closed_loop(diagram, THETA - h * v, np.zeros(12), steps).total
        fd = (up - down) / (2 * h)
        assert ad.gradient @ v == pytest.approx(fd, rel=1e-6, abs=1e-6 * np.abs(ad.gradient).sum())


def test_diagram_closed_loop_jacobian_equals_the_lqr_closed_loops():
    """Unconstrained MPC with P from the DARE is LQR: through the diagram, d x_T / d x_0 equals
    the product of (dx+/dx - dx+/du K) along the LQR flight of the nonlinear quadcopter."""
    spec = MpcSpec(A_H, B_H, 12, X_REF, U_REF)
    diagram = make_quadcopter_mpc_diagram(spec, THETA, COST, PRM)
    x0 = X_REF + np.r_[0.5, -0.4, 0.2, 0.1, 0.0, 0.0, 0.05, -0.05, 0.1, 0.0, 0.0, 0.0]
    steps = 10
    ad = simulate_closed_loop(diagram, THETA, x0, steps, gradient="x0")
    x, J = x0.copy(), np.eye(12)
    for _ in range(steps):
        u = U_REF - K_LQR @ (x - X_REF)
        s = qc.step(x, u, PRM, jacobians=True)
        J = (s.dx_dx - s.dx_du @ K_LQR) @ J
        x = s.x_next
    np.testing.assert_allclose(ad.x_final, x, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(ad.gradient, J, rtol=1e-7, atol=1e-9)


def test_diagram_records_unsolved_steps_in_the_rollout():
    spec = paper_spec(horizon=6)
    diagram = make_quadcopter_mpc_diagram(spec, THETA, COST, PRM, osqp_settings={"max_iter": 1})
    r = simulate_closed_loop(diagram, THETA, np.zeros(12), 4, gradient="theta")
    assert r.fallback_steps == 4 and np.all(r.status != int(MpcStatus.SOLVED))
    assert np.all(np.isfinite(r.x_final)) and np.all(np.isfinite(r.gradient))
    assert not r.gradient.any()  # the fallback (hover) does not depend on theta


def test_cost_system_converts_and_accumulates():
    builder = DiagramBuilder()
    cost = builder.AddSystem(ClosedLoopCost_[float](COST, 0.1))
    x = builder.AddSystem(ConstantVectorSource(X_REF + 1.0))
    u = builder.AddSystem(ConstantVectorSource(U_REF))
    s = builder.AddSystem(ConstantVectorSource(np.array([0.0, 1.0, 5.0])))
    builder.Connect(x.get_output_port(), cost.x_port)
    builder.Connect(u.get_output_port(), cost.u_port)
    builder.Connect(s.get_output_port(), cost.status_port)
    diagram = builder.Build()
    assert diagram.ToAutoDiffXd() is not None
    from pydrake.systems.analysis import Simulator

    sim = Simulator(diagram)
    sim.AdvanceTo(0.3)  # updates at 0, 0.1, 0.2
    out = cost.cost_port.Eval(cost.GetMyContextFromRoot(sim.get_context()))
    stage, _, _ = COST.stage(X_REF + 1.0, U_REF)
    term, _ = COST.terminal(X_REF + 1.0)
    viol, _ = COST.violation(X_REF + 1.0)
    np.testing.assert_allclose(out, [3 * stage + term, 4 * viol, 3 * stage + term + 1200 * viol, 3])


def test_simulate_closed_loop_bad_input():
    diagram = make_quadcopter_mpc_diagram(paper_spec(horizon=3), THETA, COST, PRM)
    with pytest.raises(ValueError, match="theta"):
        simulate_closed_loop(diagram, THETA[:5], np.zeros(12), 3)
    with pytest.raises(ValueError, match="x0"):
        simulate_closed_loop(diagram, THETA, np.full(12, np.nan), 3)
    with pytest.raises(ValueError, match="steps"):
        simulate_closed_loop(diagram, THETA, np.zeros(12), 0)
