"""Computations whose numbers the project promises to repeat bit for bit: the same call with
the same inputs, in the same process or in a new one, gives identical results.

Run as a script, it prints a SHA-256 digest of each case's output arrays (JSON), so that
``tests/test_determinism.py`` can compare a second process with its own results.
"""

from __future__ import annotations

import hashlib
import json
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def lcp_batch() -> str:
    """A batch of random PSD and frictional-like problems with Jacobians, mixed mu."""
    from drake_abs import solve_lcp

    rng = np.random.default_rng(1)
    B, d = 64, 6
    G = rng.standard_normal((B, d, d))
    F = G @ G.transpose(0, 2, 1) + 1e-3 * np.eye(d)
    q = rng.standard_normal((B, d))
    mu = 10.0 ** rng.uniform(-10, -2, size=(B, d))
    r = solve_lcp(F, q, mu=mu, jacobians=True)
    return _digest(r.lam, r.slack, r.dlam_dq, r.dlam_dmu, r.iterations, r.converged)


def lcs_rollout() -> str:
    """The point mass thrown at the ground under adaptive smoothing, with Jacobians."""
    from drake_abs import ContactAware, LcsStepper, open_loop, point_mass_lcs

    lcs = point_mass_lcs(2, time_step=0.01)
    x0 = np.array([[0.0, 0.25, 1.0, 0.3], [0.1, 0.05, -0.5, -1.0]])
    u = np.tile([0.2, -1.0], (60, 1))
    r = open_loop(LcsStepper(lcs, ContactAware(1e-2, 0.05), "total"), x0, u)
    return _digest(r.x, r.impulse, r.dxH_dx0)


def scene_step() -> str:
    """The frictional box scene (pinocchio dynamics): a batch and a single state, Jacobians."""
    from drake_abs.multibody import build_scene_model

    model = build_scene_model("box_push")
    stepper = model.stepper()
    rng = np.random.default_rng(2)
    x0 = model.x0
    x = x0 + 0.01 * rng.standard_normal((16, x0.size))
    u = rng.standard_normal((16, model.contact_model.nu))
    batch = stepper.step(x, u)
    one = stepper.step(x[:1], u[:1])
    return _digest(batch.x_next, batch.dx_dx, batch.dx_du, one.x_next, one.dx_dx)


def mpc_sequence() -> str:
    """A fresh QP-MPC (the paper's quadcopter set-up) through three warm-started solves with
    Jacobians, the same call sequence every time."""
    from mpc_setup import A_H, B_H, THETA, U_MAX, U_MIN, U_REF, X_MAX, X_MIN, X_REF

    from drake_abs.mpc.qp_mpc import MpcSpec, QpMpc

    mpc = QpMpc(MpcSpec(A_H, B_H, 12, X_REF, U_REF, U_MIN, U_MAX, X_MIN, X_MAX), THETA)
    rng = np.random.default_rng(3)
    out = []
    for _ in range(3):
        sol = mpc.solve(X_REF + 0.5 * rng.standard_normal(12), jacobians=True)
        out += [sol.u0, sol.du0_dx, sol.du0_dtheta]
    return _digest(*out)


def policy_gradient() -> str:
    """A seeded first-order estimate on the bouncing point mass under adaptive smoothing."""
    from drake_abs import ContactAware, point_mass_lcs
    from drake_abs.contact.lcs import LcsStepper
    from drake_abs.policy.estimators import PolicyObjective, first_order
    from drake_abs.policy.policies import LinearPolicy
    from drake_abs.policy.rewards import QuadraticReward

    lcs = point_mass_lcs(2, time_step=0.02)
    reward = QuadraticReward(np.diag([0.0, 1.0, 0.0, 0.01]), 0.01 * np.eye(2), np.r_[1, 0.2, 0, 0])
    stepper = LcsStepper(lcs, ContactAware(1e-2, 0.05), "total")
    obj = PolicyObjective(stepper, LinearPolicy(4, 2), reward, np.array([0, 0.3, 1, -1.0]), 30, 0.2)
    g = first_order(obj, 0.1 * np.ones(LinearPolicy(4, 2).n_params), np.random.default_rng(4), 32)
    return _digest(np.atleast_1d(g.grad), np.atleast_1d(g.value))


CASES = {
    "lcp_batch": lcp_batch,
    "lcs_rollout": lcs_rollout,
    "scene_step": scene_step,
    "mpc_sequence": mpc_sequence,
    "policy_gradient": policy_gradient,
}


def compute() -> dict[str, str]:
    return {name: case() for name, case in CASES.items()}


if __name__ == "__main__":
    print(json.dumps(compute()))
