"""Closed-loop cost of an MPC policy and its gray-box policy optimisation (Zuliani et al. 2025,
eqs. 5-10).

Closed loop (eq. 2): x_{t+1} = f(x_t, u_t), u_t = MPC(x_t, theta), t = 0..T-1, from a given x_0.
Cost (eq. 7, section 7)::

    C(theta)  = ||x_T - x_ref||_Pc^2 + sum_{t<T} ||x_t - x_ref||_Qc^2 + ||u_t - u_ref||_Rc^2
    P(theta)  = w dist_1(x(theta), X^{T+1}) = w sum_{t=0}^{T} sum_i max(0, x_t,i - x_max,i,
                                                                          x_min,i - x_t,i)
    total     = C + P                                                    (w = 300 in the paper)

Gradients (eq. 8): the closed loop runs in the one engine (:func:`drake_abs.engine.rollout`)
with the MPC as its policy (:class:`drake_abs.mpc.policy.MpcPolicy`, eq. 8b: du0/dx, du0/dtheta
of each solve) and the total cost as a negative reward (one sign convention: rewards are
maximised; :meth:`TrackingCost.reward`). The engine's reverse pass gives the same derivative as
the forward accumulation of eq. 8a-8c. J_g is either the identified linear model (A, B)
(``gradient="model"``: the model-based estimate of section 4.2, through
:class:`drake_abs.engine.ModelJacobians`) or the true plant's own Jacobians along the trajectory
(``gradient="exact"``: what tuning "with the exact model" uses). The penalty's conservative
Jacobian takes the subgradient 0 where a state sits exactly on its bound.

Zeroth order (eq. 9): J_zo = (n_theta / delta) [total(theta + delta v) - total(theta)] v with v
uniform on the unit sphere. Gray-box update (eq. 10): d_k = eta_k J_model + (1 - eta_k) J_zo,
theta_{k+1} = Proj_Theta(theta_k - alpha_k d_k), eta_k = 1 / (k + 1)^gamma, or a constant eta
(1: model only, 0: zeroth order only), k = 1, 2, ... (k starts at 1, where log k is defined).

Step size. The paper's extracted text prints
"alpha_k = 5e-5 log k + 2/(k+1)^0.75". Read literally, alpha_k grows like log k, which violates
the paper's own conditions (11a) (sum alpha_k^2 < inf), and alpha_1 = 1.19 against a closed-loop
gradient of norm ~600 moves theta by ~700 in the first step (measured: the total cost goes from
1.2e3 to 7e6). We read it as the fraction lost in extraction,

    alpha_k = 5e-5 (log k + 2) / (k + 1)^0.75                      (:func:`step_size`)

which satisfies (11a) and (11b) for gamma > 0.25. The literal reading is kept as
:func:`step_size_as_printed`.

Theta is a box ``|theta_i| <= bound`` (the paper does not state its compact convex set), so the
projection is a clip.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from drake_abs._validation import as_count, as_finite_array, check_shape
from drake_abs.contact.unconverged import OnUnconverged
from drake_abs.engine import ModelJacobians, Stepper, rollout
from drake_abs.mpc.policy import MpcPolicy
from drake_abs.mpc.qp_mpc import QpMpc, check_bounds

GradientSource = Literal["model", "exact"]


@dataclass(frozen=True)
class TrackingCost:
    """The upper-level cost of Zuliani et al. 2025, section 7 and its constraint penalty.

    Attributes:
        Q: (nx, nx), R: (nu, nu) stage weights; P: (nx, nx) terminal weight (Qc, Rc, Pc above).
        x_ref: (nx,), u_ref: (nu,).
        x_min, x_max: (nx,) state box (+-inf where unconstrained) of the penalty.
        penalty_weight: w of P(theta) = w dist_1 (300 in the paper).
    """

    Q: np.ndarray
    R: np.ndarray
    P: np.ndarray
    x_ref: np.ndarray
    u_ref: np.ndarray
    x_min: np.ndarray
    x_max: np.ndarray
    penalty_weight: float = 300.0

    def __post_init__(self):
        for name in ("Q", "R", "P", "x_ref", "u_ref"):
            arr = as_finite_array(getattr(self, name), name)
            object.__setattr__(self, name, arr.copy())
        nx, nu = self.x_ref.size, self.u_ref.size
        check_shape(self.Q, (nx, nx), "Q", "(nx, nx)")
        check_shape(self.P, (nx, nx), "P", "(nx, nx)")
        check_shape(self.R, (nu, nu), "R", "(nu, nu)")
        for name in ("x_min", "x_max"):
            arr = np.array(getattr(self, name), dtype=float)
            check_shape(arr, (nx,), name, "(nx,)")
            if np.any(np.isnan(arr)):
                raise ValueError(f"{name} contains NaN")
            object.__setattr__(self, name, arr)
        check_bounds(self.x_min, self.x_max, "x_min", "x_max")
        if not (np.isfinite(self.penalty_weight) and self.penalty_weight >= 0):
            raise ValueError(f"penalty_weight must be finite and >= 0; got {self.penalty_weight}")

    def stage(self, x: np.ndarray, u: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """||x - x_ref||_Q^2 + ||u - u_ref||_R^2 and its gradients (nx,), (nu,)."""
        ex, eu = x - self.x_ref, u - self.u_ref
        Qe, Re = self.Q @ ex, self.R @ eu
        return float(ex @ Qe + eu @ Re), (self.Q + self.Q.T) @ ex, (self.R + self.R.T) @ eu

    def terminal(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """||x - x_ref||_P^2 and its gradient (nx,)."""
        ex = x - self.x_ref
        return float(ex @ self.P @ ex), (self.P + self.P.T) @ ex

    def violation(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """dist_1(x, box) (sum of the componentwise violations, in the states' units) and its
        conservative gradient (+1 above, -1 below, 0 inside or on the bound)."""
        above = x - self.x_max
        below = self.x_min - x
        g = np.where(above > 0, 1.0, 0.0) - np.where(below > 0, 1.0, 0.0)
        return float(np.sum(np.maximum(0.0, above)) + np.sum(np.maximum(0.0, below))), g

    def reward(self) -> TrackingReward:
        """This cost plus its penalty as a :class:`~drake_abs.engine.Reward`: the negative of
        ``stage + w * violation`` per step and ``terminal + w * violation`` at the end."""
        return TrackingReward(self)


@dataclass(frozen=True)
class TrackingReward:
    """The reward form (maximised) of a :class:`TrackingCost`, batched over M rollouts:
    r_t = -(||x_t - x_ref||_Q^2 + ||u_t - u_ref||_R^2 + w dist_1(x_t)),
    r_T = -(||x_T - x_ref||_P^2 + w dist_1(x_T))."""

    cost: TrackingCost

    def stage(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w, M = self.cost.penalty_weight, len(x)
        r, dr_dx, dr_du = np.empty(M), np.empty(np.shape(x)), np.empty(np.shape(u))
        for m in range(M):
            c, gx, gu = self.cost.stage(x[m], u[m])
            v, gv = self.cost.violation(x[m])
            r[m], dr_dx[m], dr_du[m] = -(c + w * v), -(gx + w * gv), -gu
        return r, dr_dx, dr_du

    def terminal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w, M = self.cost.penalty_weight, len(x)
        r, dr_dx = np.empty(M), np.empty(np.shape(x))
        for m in range(M):
            c, gT = self.cost.terminal(x[m])
            v, gv = self.cost.violation(x[m])
            r[m], dr_dx[m] = -(c + w * v), -(gT + w * gv)
        return r, dr_dx


@dataclass(frozen=True)
class ClosedLoopResult:
    """One closed-loop rollout of T steps.

    Attributes:
        x: (T + 1, nx) states; u: (T, nu) applied inputs.
        tracking_cost: C(theta); violation: dist_1(x, X^{T+1}); penalty: w * violation;
            total: C + penalty.
        status: (T,) :class:`drake_abs.mpc.qp_mpc.MpcStatus` codes of the MPC solves; fallback:
            (T,) whether the fallback control was applied at that step.
        gradient: (n_theta,) d total / d theta (eq. 8), or None.
        gradient_source: "model", "exact" or None.
    """

    x: np.ndarray
    u: np.ndarray
    tracking_cost: float
    violation: float
    penalty: float
    total: float
    status: np.ndarray
    fallback: np.ndarray
    gradient: np.ndarray | None = None
    gradient_source: str | None = None

    @property
    def fallback_steps(self) -> int:
        return int(np.sum(self.fallback))


def closed_loop(
    controller: QpMpc,
    theta,
    x0,
    steps: int,
    plant: Stepper,
    cost: TrackingCost,
    *,
    gradient: GradientSource | None = None,
    model: tuple[np.ndarray, np.ndarray] | None = None,
    on_unconverged: OnUnconverged = "raise",
) -> ClosedLoopResult:
    """Roll the MPC policy out on ``plant`` for ``steps`` steps from ``x0`` and evaluate the cost,
    in the closed-loop engine.

    Args:
        controller: the MPC (its theta is set to ``theta``).
        theta: (n_theta,) cost parameters.
        x0: (nx,) initial state.
        steps: T >= 1.
        plant: a batched stepper (:class:`~drake_abs.engine.Stepper`, e.g.
            ``QuadcopterStepper`` or ``LinearStepper``).
        cost: the upper-level cost.
        gradient: None, "model" (J_g = ``model``) or "exact" (J_g = the plant's Jacobians).
        model: (A, B) of the prediction model, required for ``gradient="model"``; the
            controller's own (A, B) by default.
        on_unconverged: a plant step whose contact solve did not converge: ``"raise"``
            (default: one closed loop has nothing to average over), ``"drop"`` (NaN result,
            warned) or ``"flag"``.

    A fallback control (QP not solved) enters the gradient with zero Jacobians (it is a
    constant); the steps are counted in ``fallback``.
    """
    theta = as_finite_array(theta, "theta", ndim=(1,))
    x0 = as_finite_array(x0, "x0", ndim=(1,))
    spec = controller.spec
    check_shape(x0, (spec.nx,), "x0", "(nx,)")
    steps = as_count(steps, "steps", minimum=1)
    if gradient not in (None, "model", "exact"):
        raise ValueError(f"gradient must be None, 'model' or 'exact'; got {gradient!r}")
    stepper = plant
    if gradient == "model":
        Ag, Bg = model if model is not None else (spec.A, spec.B)
        Ag = as_finite_array(Ag, "model A", ndim=(2,))
        Bg = as_finite_array(Bg, "model B", ndim=(2,))
        stepper = ModelJacobians(plant, Ag, Bg)
    controller.set_theta(theta)
    policy = MpcPolicy(controller)
    T, nu = int(steps), spec.nu
    traj = rollout(
        stepper, policy, theta, x0, np.zeros((1, T, nu)), cost.reward(), sigma=0.0,
        gradient=gradient is not None, on_unconverged=on_unconverged,
    )  # fmt: skip
    xs, us = traj.x[0], traj.u[0]
    if not np.all(np.isfinite(xs)):
        raise FloatingPointError("the closed loop produced a non-finite state")
    C = viol = 0.0
    for t in range(T):
        C += cost.stage(xs[t], us[t])[0]
        viol += cost.violation(xs[t])[0]
    C += cost.terminal(xs[T])[0]
    viol += cost.violation(xs[T])[0]
    w = cost.penalty_weight
    return ClosedLoopResult(
        x=xs,
        u=us,
        tracking_cost=C,
        violation=viol,
        penalty=w * viol,
        total=C + w * viol,
        status=np.array([int(s.status) for s in policy.solutions], dtype=np.int8),
        fallback=np.array([s.fallback for s in policy.solutions], dtype=bool),
        gradient=-traj.grad[0] if gradient is not None else None,
        gradient_source=gradient,
    )


# ---------------------------------------------------------------------------------------------
# gray-box optimisation


def step_size(k: int) -> float:
    """alpha_k = 5e-5 (log k + 2) / (k + 1)^0.75, k >= 1 (see the module docstring)."""
    k = as_count(k, "k", minimum=1)
    return 5e-5 * (np.log(k) + 2.0) / (k + 1) ** 0.75


def step_size_as_printed(k: int) -> float:
    """alpha_k = 5e-5 log k + 2 / (k + 1)^0.75, the formula as the extracted text prints it
    (diverges on the quadcopter; see the module docstring), k >= 1."""
    k = as_count(k, "k", minimum=1)
    return 5e-5 * np.log(k) + 2.0 / (k + 1) ** 0.75


@dataclass(frozen=True)
class Schedule:
    """The model weight eta_k: ``1 / (k + 1)^gamma`` when ``gamma`` is given, else the constant
    ``eta`` (1: model-based only, eq. 8; 0: zeroth order only, eq. 9)."""

    gamma: float | None = None
    eta: float | None = None
    name: str = ""

    def __post_init__(self):
        if (self.gamma is None) == (self.eta is None):
            raise ValueError("give exactly one of gamma and eta")
        if self.eta is not None and not (0.0 <= self.eta <= 1.0):
            raise ValueError(f"eta must be in [0, 1]; got {self.eta}")
        if self.gamma is not None and not (np.isfinite(self.gamma) and self.gamma >= 0):
            raise ValueError(f"gamma must be finite and >= 0; got {self.gamma}")

    def weight(self, k: int) -> float:
        return float(self.eta) if self.gamma is None else 1.0 / (k + 1) ** self.gamma

    @property
    def label(self) -> str:
        if self.name:
            return self.name
        if self.gamma is not None:
            return f"gamma={self.gamma:g}"
        return {1.0: "model only (eta=1)", 0.0: "zeroth order only (eta=0)"}.get(
            float(self.eta), f"eta={self.eta:g}"
        )


def sample_unit_sphere(rng: np.random.Generator, n: int) -> np.ndarray:
    """v uniform on the unit sphere of R^n (a normalised Gaussian)."""
    v = rng.standard_normal(n)
    return v / np.linalg.norm(v)


def zeroth_order_estimate(total_at: float, total_perturbed: float, v, delta: float) -> np.ndarray:
    """The one-point estimate (eq. 9): (n / delta) [C(theta + delta v) - C(theta)] v."""
    v = np.asarray(v, dtype=float)
    return (v.size / delta) * (total_perturbed - total_at) * v


@dataclass(frozen=True)
class GrayBoxIterate:
    """The record of one iterate theta_k (k = 1 is the initial parameter)."""

    k: int
    tracking_cost: float
    violation: float
    total: float
    fallback_steps: int
    alpha: float = float("nan")  # step taken from this iterate (nan for the last)
    eta: float = float("nan")
    model_gradient_norm: float = float("nan")
    zeroth_order_norm: float = float("nan")
    direction_norm: float = float("nan")


@dataclass(frozen=True)
class GrayBoxResult:
    """theta after the last update, the per-iterate trace (iterations + 1 entries), all iterates
    (iterations + 1, n_theta) and the final closed loop."""

    theta: np.ndarray
    trace: list[GrayBoxIterate]
    thetas: np.ndarray
    final: ClosedLoopResult
    schedule: Schedule = field(default_factory=lambda: Schedule(eta=1.0))


Evaluate = Callable[[np.ndarray, bool], ClosedLoopResult]


def graybox_optimize(
    evaluate: Evaluate,
    theta0,
    *,
    iterations: int,
    schedule: Schedule,
    rng: np.random.Generator,
    delta: float = 1e-4,
    bound: float = 100.0,
    alpha: Callable[[int], float] = step_size,
    progress: Callable[[GrayBoxIterate], None] | None = None,
) -> GrayBoxResult:
    """The gray-box update (eq. 10) for ``iterations`` steps from ``theta0``.

    Args:
        evaluate: ``evaluate(theta, with_gradient)`` -> ClosedLoopResult on the true system,
            with the model-based gradient when asked (e.g. :func:`closed_loop` with
            ``gradient="model"``).
        theta0: (n_theta,) initial parameters (projected on the box first).
        iterations: number of updates K >= 0.
        schedule: eta_k.
        rng: the source of the directions v_k (one drawn every iteration, also when eta = 1,
            so that methods run with the same seed see the same directions).
        delta: smoothing radius of eq. 9 (1e-4 in the paper).
        bound: ``Theta = {|theta_i| <= bound}``.
        alpha: step size alpha_k (default :func:`step_size`).
        progress: called with each iterate's record.
    """
    theta = as_finite_array(theta0, "theta0", ndim=(1,))
    iterations = as_count(iterations, "iterations", minimum=0)
    if not (np.isfinite(delta) and delta > 0):
        raise ValueError(f"delta must be finite and > 0; got {delta!r}")
    if not (np.isfinite(bound) and bound > 0):
        raise ValueError(f"bound must be finite and > 0; got {bound!r}")
    theta = np.clip(theta, -bound, bound)
    n = theta.size
    trace: list[GrayBoxIterate] = []
    thetas = [theta.copy()]
    for k in range(1, int(iterations) + 2):
        eta = schedule.weight(k)
        last = k == int(iterations) + 1
        r = evaluate(theta, (not last) and eta > 0)
        if last:
            rec = GrayBoxIterate(k, r.tracking_cost, r.violation, r.total, r.fallback_steps)
            trace.append(rec)
            if progress:
                progress(rec)
            break
        v = sample_unit_sphere(rng, n)
        d = np.zeros(n)
        g_norm = zo_norm = float("nan")
        if eta > 0:
            d += eta * r.gradient
            g_norm = float(np.linalg.norm(r.gradient))
        if eta < 1:
            perturbed = evaluate(theta + delta * v, False)
            zo = zeroth_order_estimate(r.total, perturbed.total, v, delta)
            d += (1.0 - eta) * zo
            zo_norm = float(np.linalg.norm(zo))
        a = alpha(k)
        rec = GrayBoxIterate(
            k,
            r.tracking_cost,
            r.violation,
            r.total,
            r.fallback_steps,
            alpha=a,
            eta=eta,
            model_gradient_norm=g_norm,
            zeroth_order_norm=zo_norm,
            direction_norm=float(np.linalg.norm(d)),
        )
        trace.append(rec)
        if progress:
            progress(rec)
        theta = np.clip(theta - a * d, -bound, bound)
        thetas.append(theta.copy())
    return GrayBoxResult(
        theta=theta, trace=trace, thetas=np.asarray(thetas), final=r, schedule=schedule
    )
