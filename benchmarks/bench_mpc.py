"""Benchmark of the differentiable QP-MPC (Zuliani et al. 2025) against central finite differences.

Measured in one run, on the quadcopter MPC of Zuliani et al. 2025, section 7 (12 states, 4 inputs,
horizon N = 12, theta of size 94; prediction model: the hover linearisation), timed with
``time.perf_counter``, medians over repeats:

1. One MPC solve plus its Jacobians du0/dx (4 x 12) and du0/dtheta (4 x 94), from the KKT
   adjoint (4 right-hand sides), against the central finite-difference Jacobian of the same
   u0 (2 x 106 warm-started solves), and against OSQP's own adjoint derivative (one call per
   input). States: the origin (7 m from the target: input, state and slack constraints active)
   and a point near the target.
2. One closed-loop gradient d total / d theta over T = 200 steps on the nonlinear quadcopter
   (eq. 8 with the plant's Jacobians; core) against its central finite difference (2 x 94
   rollouts), plus the same gradient through the AutoDiffXd Drake diagram.

Usage::

    python benchmarks/bench_mpc.py             # T = 200 (about two minutes)
    python benchmarks/bench_mpc.py --steps 50  # shorter closed loop
    python benchmarks/bench_mpc.py --json results/bench_mpc.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from drake_abs.mpc.graybox import TrackingCost, closed_loop
from drake_abs.mpc.qp_mpc import MpcSpec, QpMpc, riccati_terminal_cost, theta_from_cost
from drake_abs.tasks import quadcopter as qc

PRM = qc.QuadcopterParams()
# the Zuliani et al. (2025) task of drake-abs experiment mpc-quadcopter
X_REF = np.array(qc.TRACKING_TARGET)
Q_D = np.array(qc.TRACKING_STAGE_Q)
R_D = np.array(qc.TRACKING_STAGE_R)


def setup():
    A, B = qc.hover_linearization(PRM)
    x_min, x_max = qc.QuadcopterConstraints().state_bounds()
    u_min, u_max = qc.QuadcopterConstraints().input_bounds()
    spec = MpcSpec(A, B, 12, X_REF, PRM.hover_input(), u_min, u_max, x_min, x_max)
    P, _ = riccati_terminal_cost(A, B, np.diag(Q_D), np.diag(R_D))
    theta = theta_from_cost(Q_D, R_D, P)
    P_c = np.diag(qc.TRACKING_TERMINAL_P)
    cost = TrackingCost(
        np.diag(Q_D), np.diag(R_D), P_c, X_REF, PRM.hover_input(), x_min, x_max,
        qc.TRACKING_PENALTY,
    )  # fmt: skip
    return spec, theta, cost


def timed(fn, repeats: int) -> tuple[float, object]:
    out = fn()  # warm-up
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times)), out


def fd_jacobian(f, x, eps):
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = eps
        cols.append((f(x + e) - f(x - e)) / (2 * eps))
    return np.stack(cols, axis=-1)


def bench_solve(spec, theta, x, repeats=20) -> dict:
    mpc = QpMpc(spec, theta)
    t_solve, _ = timed(lambda: mpc.solve(x), repeats)
    t_kkt, sol = timed(lambda: mpc.solve(x, jacobians=True), repeats)
    t_adj, adj = timed(lambda: mpc.solve(x, jacobians=True, method="osqp_adjoint"), 3)

    def fd():
        jx = fd_jacobian(lambda z: mpc.solve(z).u0, x, 1e-5)
        jt = fd_jacobian(lambda t: mpc.solve(x, t).u0, theta, 1e-6)
        mpc.set_theta(theta)
        return jx, jt

    t_fd, (jx, jt) = timed(fd, 3)
    scale = max(np.abs(jx).max(), np.abs(jt).max())
    return {
        "active_inequalities": sol.active,
        "max_slack": float(sol.slack.max()),
        "osqp_iterations_warm": sol.iterations,
        "t_solve_ms": 1e3 * t_solve,
        "t_solve_and_kkt_jacobians_ms": 1e3 * t_kkt,
        "t_solve_and_osqp_adjoint_jacobians_ms": 1e3 * t_adj,
        "t_central_fd_ms": 1e3 * t_fd,
        "fd_over_kkt": t_fd / t_kkt,
        "kkt_minus_fd_max_rel": float(
            max(np.abs(sol.du0_dx - jx).max(), np.abs(sol.du0_dtheta - jt).max()) / scale
        ),
        "osqp_adjoint_minus_kkt_max_rel": float(
            max(
                np.abs(adj.du0_dx - sol.du0_dx).max(),
                np.abs(adj.du0_dtheta - sol.du0_dtheta).max(),
            )
            / scale
        ),
    }


def bench_closed_loop(spec, theta, cost, steps: int) -> dict:
    mpc = QpMpc(spec, theta)
    x0 = np.zeros(12)

    plant = qc.QuadcopterStepper(PRM)

    t_value, base = timed(lambda: closed_loop(mpc, theta, x0, steps, plant, cost), 2)
    t_grad, res = timed(
        lambda: closed_loop(mpc, theta, x0, steps, plant, cost, gradient="exact"), 2
    )
    t0 = time.perf_counter()
    fd = fd_jacobian(
        lambda t: np.array(closed_loop(mpc, t, x0, steps, plant, cost).total), theta, 1e-6
    )
    t_fd = time.perf_counter() - t0

    from drake_abs.diagrams.quadcopter_mpc import (
        make_quadcopter_mpc_diagram,
        simulate_closed_loop,
    )

    diagram = make_quadcopter_mpc_diagram(spec, theta, cost, PRM)
    t_ad, ad = timed(lambda: simulate_closed_loop(diagram, theta, x0, steps, gradient="theta"), 1)
    scale = np.abs(fd).max()
    return {
        "steps": steps,
        "total": base.total,
        "fallback_steps": base.fallback_steps,
        "t_rollout_s": t_value,
        "t_rollout_and_gradient_core_s": t_grad,
        "t_gradient_autodiff_diagram_s": t_ad,
        "t_central_fd_s": t_fd,
        "fd_over_core_gradient": t_fd / t_grad,
        "fd_over_autodiff_diagram": t_fd / t_ad,
        "core_minus_fd_max_rel": float(np.abs(res.gradient - fd).max() / scale),
        "diagram_minus_core_max_rel": float(np.abs(ad.gradient - res.gradient).max() / scale),
    }


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=200, help="closed-loop steps T")
    parser.add_argument("--json", type=Path, default=Path("results/bench_mpc.json"))
    args = parser.parse_args(argv)
    spec, theta, cost = setup()
    results = {"solve": {}, "closed_loop": None}
    for name, x in (("origin", np.zeros(12)), ("near_target", X_REF + 0.3)):
        r = bench_solve(spec, theta, x)
        results["solve"][name] = r
        print(
            f"MPC solve + Jacobians at N = 12, x = {name}: {r['active_inequalities']} active rows;"
            f" solve {r['t_solve_ms']:.2f} ms, solve + KKT Jacobians "
            f"{r['t_solve_and_kkt_jacobians_ms']:.2f} ms, central FD "
            f"{r['t_central_fd_ms']:.0f} ms (ratio FD / ours {r['fd_over_kkt']:.0f}); OSQP "
            f"adjoint {r['t_solve_and_osqp_adjoint_jacobians_ms']:.1f} ms; |ours - FD| / max "
            f"{r['kkt_minus_fd_max_rel']:.1e}, |OSQP adjoint - ours| / max "
            f"{r['osqp_adjoint_minus_kkt_max_rel']:.1e}"
        )
    c = bench_closed_loop(spec, theta, cost, args.steps)
    results["closed_loop"] = c
    print(
        f"closed-loop gradient over T = {c['steps']}: rollout {c['t_rollout_s']:.2f} s, rollout + "
        f"gradient {c['t_rollout_and_gradient_core_s']:.2f} s (core), "
        f"{c['t_gradient_autodiff_diagram_s']:.2f} s (AutoDiffXd diagram); central FD "
        f"{c['t_central_fd_s']:.1f} s (ratio FD / core {c['fd_over_core_gradient']:.0f}, "
        f"FD / diagram {c['fd_over_autodiff_diagram']:.0f}); |core - FD| / max "
        f"{c['core_minus_fd_max_rel']:.1e}, |diagram - core| / max "
        f"{c['diagram_minus_core_max_rel']:.1e}"
    )
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=2, default=float) + "\n")
    print(f"Wrote {args.json}")
    return results


if __name__ == "__main__":
    main()
