"""Generalisation bounds of the three losses on the 1-D toy (Bianchini et al. 2022, section 3,
Theorem 1 and Table 1), in closed form and measured from drake-abs's implementation.

Theorem 1 (their eq. 10): with probability at least ``1 - delta``, for a loss bounded by ``B``
and ``L``-Lipschitz in k parameters bounded by ``B_theta``, the generalisation error (population
risk minus empirical risk on n i.i.d. points) is at most ::

    44 L B_theta sqrt(k / n) + B sqrt(log(1 / delta) / (2 n)).

The losses' Lipschitz constants in theta (their eqs. 11-13): ::

    L_exp  = 2 B_exp L_f,theta
    L_nimp = 2 B_nimp (L_g,lam L_lam,theta^nimp + L_g,theta)
    L_vimp = 2 B_nimp (L_g,lam L_lam,theta^vimp + L_g,theta)
             + (1 / eps) (L_h,lam L_lam,theta^vimp + L_h,theta)

For the toy the constituent constants are (our derivation, which agrees with their Appendix B
except in the last line) ::

    L_f,theta = 1 / dt            L_g,lam = 1 / m        L_g,theta = 0
    L_h,lam = L_h,theta = max(phi_max, lam_max)
    L_lam,theta^nimp = max(m dt / (m^2 + dt^2), m / dt)
    L_lam,theta^vimp = m^2 / (2 eps)

The last: in the region ``lam > 0, phi > 0`` the violation objective is
``(r - lam / m)^2 + phi lam / eps`` with ``phi = z + y dt - theta``, whose minimiser is
``lam* = m r - m^2 phi / (2 eps)``, so ``d lam* / d theta = m^2 / (2 eps)``: 2 at the paper's
``eps = 1/4, m = 1``. Their Table 1 prints 1 (what ``m^2 / (2 eps)`` gives at ``eps = 1/2``).

The bounds B of the losses and of theta are not printed in the paper; :func:`toy_bounds`
states the ones used here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs.lcp.ipm import solve_lcp
from drake_abs.learning.ground_toy import GroundToy


def generalization_bound(L: float, B_theta: float, B: float, n, k: int = 1, delta: float = 0.05):
    """Their eq. 10: the bound on the generalisation error for n data points (scalar or
    array), a loss bounded by B and L-Lipschitz in k parameters of norm <= B_theta, failure
    probability delta in (0, 1)."""
    if not 0 < delta < 1:
        raise ValueError(f"delta must be in (0, 1); got {delta!r}")
    n = np.asarray(n, dtype=float)
    if np.any(n < 1):
        raise ValueError("n must be >= 1")
    return 44.0 * L * B_theta * np.sqrt(k / n) + B * np.sqrt(np.log(1.0 / delta) / (2.0 * n))


@dataclass(frozen=True)
class ToyBounds:
    """Bounds on the toy's domain: B_theta (m), B_exp = B_nimp (the prediction losses, (m/s)^2)
    and B_vimp."""

    B_theta: float
    B_exp: float
    B_nimp: float
    B_vimp: float


def toy_bounds(toy: GroundToy, eps: float) -> ToyBounds:
    """The bounds used for Theorem 1 on the toy (not printed in the paper; ours):

    - ``B_theta = phi_max``: the ground height is searched within the data's height range;
    - ``B_exp = B_nimp = (2 v_max + a dt)^2``: outputs lie in ``[-v_max - a dt, v_max]``, so a
      squared prediction error is at most the square of that range;
    - ``B_vimp = B_nimp + ((v_max + a dt) dt)^2 / (2 eps)``: the violation loss is at most its
      value at ``lam = 0``, whose violation term is ``neg(phi)^2 / 2`` with
      ``phi >= -(v_max + a dt) dt`` on the domain.
    """
    b = (2.0 * toy.v_max + toy.a * toy.dt) ** 2
    sink = (toy.v_max + toy.a * toy.dt) * toy.dt
    return ToyBounds(toy.phi_max, b, b, b + sink**2 / (2.0 * eps))


def lipschitz_table(toy: GroundToy, eps: float) -> dict[str, float]:
    """The constituent constants of the module docstring, in closed form."""
    m, dt = toy.m, toy.dt
    top = max(toy.phi_max, toy.lambda_max)
    return {
        "L_f,theta": 1.0 / dt,
        "L_g,lambda": 1.0 / m,
        "L_g,theta": 0.0,
        "L_h,lambda": top,
        "L_h,theta": top,
        "L_lambda,theta^nimp": max(m * dt / (m * m + dt * dt), m / dt),
        "L_lambda,theta^vimp": m * m / (2.0 * eps),
    }


#: Bianchini et al.'s Table 1, as printed (numerical column).
PAPER_TABLE_1 = {
    "L_f,theta": 200.0,
    "L_g,lambda": 1.0,
    "L_g,theta": 0.0,
    "L_h,lambda": 15.05,
    "L_h,theta": 15.05,
    "L_lambda,theta^nimp": 200.0,
    "L_lambda,theta^vimp": 1.0,
}


def loss_lipschitz(table: dict[str, float], bounds: ToyBounds, eps: float) -> dict[str, float]:
    """Their eqs. 11-13 from the constituent constants ``table`` and the bounds."""
    t = table
    return {
        "exp": 2.0 * bounds.B_exp * t["L_f,theta"],
        "nimp": 2.0 * bounds.B_nimp * (t["L_g,lambda"] * t["L_lambda,theta^nimp"] + t["L_g,theta"]),
        "vimp": 2.0 * bounds.B_nimp * (t["L_g,lambda"] * t["L_lambda,theta^vimp"] + t["L_g,theta"])
        + (t["L_h,lambda"] * t["L_lambda,theta^vimp"] + t["L_h,theta"]) / eps,
    }  # fmt: skip


def measured_lipschitz(
    toy: GroundToy, eps: float, rng: np.random.Generator, n: int = 20000, step: float = 1e-7
) -> dict[str, float]:
    """The constituent constants measured from the implementation: the largest central
    difference quotient (step ``step``) over n random points of the domain (heights above the
    ground in [0, phi_max], speeds in [-v_max, v_max], observed outputs in the output range,
    impulses in [-lam_max, lam_max], theta = 0), with the solver's implicit derivative for f
    and the naive-implicit impulse, and the violation loss's minimiser for the last."""
    theta = 0.0
    z = rng.uniform(0.0, toy.phi_max, n)
    v = rng.uniform(-toy.v_max, toy.v_max, n)
    y = rng.uniform(-toy.v_max - toy.a * toy.dt, toy.v_max, n)
    lam = rng.uniform(-toy.lambda_max, toy.lambda_max, n)
    # points near contact, where the steep parts are: heights within one step's travel
    near = rng.random(n) < 0.5
    z[near] = rng.uniform(0.0, 2 * toy.v_max * toy.dt, near.sum())

    def quotient(fun, x):
        return np.abs(fun(x + step) - fun(x - step)) / (2 * step)

    _, df, _ = toy.predict(theta, z, v)
    F, q = toy.lcp(theta, z, v)
    r = solve_lcp(F, q, 0.0, jacobians=True)
    dlam_nimp = np.abs(r.dlam_dq[:, 0, 0])  # |d lam* / d theta| = |d lam* / d q|
    h_lam = quotient(lambda s: toy.h(theta, z, v, y, s), lam)
    h_theta = quotient(lambda s: toy.h(s, z, v, y, lam), np.full(n, theta))
    lam_v = quotient(lambda s: toy.violation_implicit_loss(float(s[0]), z, v, y, eps).lam[:, 0],
                     np.array([theta]))  # fmt: skip
    return {
        "L_f,theta": float(np.abs(df).max()),
        "L_g,lambda": float(quotient(lambda s: toy.g(z, v, s), lam).max()),
        "L_g,theta": 0.0,  # g does not take theta
        "L_h,lambda": float(h_lam.max()),
        "L_h,theta": float(h_theta.max()),
        "L_lambda,theta^nimp": float(dlam_nimp.max()),
        "L_lambda,theta^vimp": float(lam_v.max()),
    }


def data_ratio(lip: dict[str, float], bounds: ToyBounds, n0: float, delta: float = 0.05) -> float:
    """How many times more data than ``n0`` the explicit loss's bound needs to fall to the
    violation loss's bound at ``n0``, for the losses' Lipschitz constants ``lip`` (keys "exp"
    and "vimp", :func:`loss_lipschitz`): the bounds fall monotonically in n, so a root search
    in log n (up to e^60 times n0)."""
    from scipy.optimize import brentq

    if not (np.isfinite(n0) and n0 >= 1):
        raise ValueError(f"n0 must be a finite number of data points >= 1; got {n0!r}")
    target = float(generalization_bound(lip["vimp"], bounds.B_theta, bounds.B_vimp, n0,
                                        delta=delta))  # fmt: skip

    def gap(log_n):
        return float(generalization_bound(lip["exp"], bounds.B_theta, bounds.B_exp,
                                          np.exp(log_n), delta=delta)) - target  # fmt: skip

    return float(np.exp(brentq(gap, np.log(n0), np.log(n0) + 60.0)) / n0)
