"""The closed-loop engine: M rollouts of ``x_{t+1} = f(x_t, pi(x_t; theta) + sigma xi_t)`` through
any batched stepper, their returns, and their gradients by one reverse pass (docs/math.md
section 7; Zhang et al. 2023, eq. 4.1; Zuliani et al. 2025, eq. 8).

Every closed loop in drake-abs runs here: the policy-gradient estimators (a policy and a task
reward), the MPC's gray-box tuning (the MPC as a policy, its tracking cost as a negative reward),
open-loop input sequences (:func:`open_loop`: no policy) and model learning (derivatives with
respect to the stepper's model parameters, ``parameters=True``).

Forward pass: one ``stepper.step`` call per time step for the whole batch; it stores the states,
inputs and step Jacobians. Reverse pass: :func:`drake_abs.engine.adjoint.reverse_pass`.

Memory (stated and bounded): the forward pass stores per step the states, inputs and the step
Jacobians, ``8 M H (nx^2 + nx nu + 2 nx + 2 nu)`` bytes (:func:`rollout_memory_bytes`), plus
``8 M H nx T`` with T model parameters; for M = 1024, H = 1000 and the 2-D ball (nx = 4, nu = 2)
that is 0.29 GB. Policy Jacobians are not stored: the reverse pass recomputes the policy's
vector-Jacobian products from x_t (a :class:`~drake_abs.engine.protocols.PullbackPolicy`, e.g. an
MPC, keeps the products of its forward solves instead).

Unconverged steps: ``on_unconverged`` (:mod:`drake_abs.contact.unconverged`; default ``"drop"``:
a rollout with an unconverged step is marked unused, and its return and gradients are NaN).

Rewards of transitions and episodes that end: a
:class:`~drake_abs.engine.protocols.TransitionReward` is evaluated on (x_t, u_t, x_{t+1}), its
``dr/dx_{t+1}`` entering the reverse pass at t + 1. With ``terminated``, an episode ends with the
step that reached a terminal state: that step's reward counts, the later ones and the terminal
reward do not, and the ended rollout stays at its last state (it is still stepped, as part of the
batch, but its steps count for nothing: not in the return, not in ``converged``, not in the
gradient). ``Trajectory.alive`` says which steps counted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs._validation import as_finite_array
from drake_abs.contact.unconverged import (
    OnUnconverged,
    apply_on_unconverged,
    check_on_unconverged,
)
from drake_abs.engine.adjoint import reverse_pass
from drake_abs.engine.protocols import (
    Policy,
    PullbackPolicy,
    Reward,
    Stepper,
    TimeVaryingPolicy,
    TransitionReward,
    check_protocol,
    check_reward,
)

STEPPER_FORM = "step(x, u, *, jacobians, parameters) -> Step, parameter_names"


@dataclass(frozen=True)
class Trajectory:
    """M rollouts of H steps, what they returned and (where asked for) their derivatives.

    Attributes:
        x: (M, H + 1, nx) states; u: (M, H, nu) inputs applied (policy plus noise).
        impulse: (M, H, nc) contact impulses of each step; mu: (M, H, nc) central-path values.
        converged: (M, H) the step solver's flags (a rollout with a False is not exact).
        used: (M,) the rollouts estimators may use: all under ``on_unconverged="flag"``, those
            whose every step converged under ``"drop"``.
        returns: (M,) sum of stage rewards plus the terminal reward (None without a reward;
            NaN for a dropped rollout).
        alive: (M, H) whether step t's reward counts: all True unless the reward has
            ``terminated`` (a :class:`~drake_abs.engine.protocols.TransitionReward`), then False
            after the step that ended the episode. ``alive.sum(axis=1)`` are the episodes'
            environment steps.
        grad: (M, P) dJ_m/dtheta of the policy parameters (None unless gradients were asked
            for with a policy and a reward; NaN for a dropped rollout).
        grad_x0: (M, nx) dJ_m/dx_0 (as ``grad``).
        grad_model: (M, T) dJ_m/dphi of the stepper's model parameters, named by
            ``model_parameter_names`` (None unless ``parameters=True``).
        dxH_dx0: (M, nx, nx), dxH_du: (M, H, nx, nu) Jacobians of the final state (from
            :func:`open_loop` with ``jacobians=True``; NaN for a dropped rollout).
    """

    x: np.ndarray
    u: np.ndarray
    impulse: np.ndarray
    mu: np.ndarray
    converged: np.ndarray
    used: np.ndarray
    returns: np.ndarray | None = None
    grad: np.ndarray | None = None
    grad_x0: np.ndarray | None = None
    grad_model: np.ndarray | None = None
    model_parameter_names: tuple[str, ...] = ()
    dxH_dx0: np.ndarray | None = None
    dxH_du: np.ndarray | None = None
    alive: np.ndarray | None = None

    @property
    def dropped(self) -> int:
        """Rollouts left out because a step did not converge."""
        return int((~self.used).sum())


@dataclass(frozen=True)
class Tape:
    """What the forward pass stores for the reverse pass (see :func:`record` for the fields)."""

    x: np.ndarray
    u: np.ndarray
    impulse: np.ndarray
    mu: np.ndarray
    converged: np.ndarray
    dx_dx: np.ndarray | None
    dx_du: np.ndarray | None
    dx_dtheta: np.ndarray | None
    theta_names: tuple[str, ...]
    stage_returns: np.ndarray | None  # (M,) sum of the stage rewards
    rewards: np.ndarray | None  # (M, H) each step's reward (0 after an episode ended)
    stage_x: np.ndarray | None  # (M, H + 1, nx) dr/dx_t (row H: from the last transition)
    stage_u: np.ndarray | None  # (M, H, nu) dr/du_t
    vjps: list | None
    alive: np.ndarray  # (M, H + 1): the rewards of step t (t = H: the terminal one) count


def rollout_memory_bytes(M: int, H: int, nx: int, nu: int, n_model_params: int = 0) -> int:
    """Bytes the forward pass stores for the reverse pass (float64)."""
    return 8 * M * H * (nx * nx + nx * nu + 2 * nx + 2 * nu + nx * n_model_params) + 8 * M * nx


def rollout(
    stepper: Stepper,
    policy: Policy | None,
    theta,
    x0,
    noise,
    reward: Reward | None = None,
    *,
    sigma: float = 1.0,
    gradient: bool = True,
    parameters: bool = False,
    on_unconverged: OnUnconverged = "drop",
) -> Trajectory:
    """Roll out M noisy closed loops and (optionally) differentiate each return.

    Args:
        stepper: the batched dynamics (:class:`~drake_abs.engine.protocols.Stepper`).
        policy: a :class:`~drake_abs.engine.protocols.Policy`; None for open-loop inputs
            ``u_t = sigma xi_t`` (see :func:`open_loop`).
        theta: (P,) policy parameters (ignored without a policy).
        x0: (nx,) shared or (M, nx) initial states.
        noise: (M, H, nu) standard-normal exploration samples xi (the caller seeds them); the
            applied input is ``pi(x_t) + sigma xi_t``.
        reward: a :class:`~drake_abs.engine.protocols.Reward` (maximised); None for a rollout
            without an objective.
        sigma: exploration scale (units of u); 0 for the deterministic policy.
        gradient: run the reverse pass (needs a reward): ``grad``, ``grad_x0``.
        parameters: also differentiate with respect to the stepper's model parameters
            (``grad_model``; needs ``gradient``).
        on_unconverged: ``"drop"`` (default; marked unused, return and gradients NaN),
            ``"flag"`` or ``"raise"`` (:mod:`drake_abs.contact.unconverged` says why).
    """
    check_protocol(stepper, Stepper, "stepper", STEPPER_FORM)
    if getattr(policy, "time_varying", False):
        check_protocol(
            policy, TimeVaryingPolicy, "policy", "time_varying, nx, nu, act(theta, x, t)"
        )
    elif policy is not None:
        check_protocol(policy, Policy, "policy", "nx, nu, n_params, act, jacobians, vjp")
    if reward is not None:
        check_reward(reward)
    if gradient and reward is None:
        raise ValueError("gradient=True needs a reward (the objective to differentiate)")
    if parameters and not gradient:
        raise ValueError("parameters=True needs gradient=True")
    tape = _forward(stepper, policy, theta, x0, noise, reward, sigma, gradient, parameters,
                    on_unconverged)  # fmt: skip
    # a step after the episode ended does not count, converged or not
    used = apply_on_unconverged(tape.converged | ~tape.alive[:, :-1], on_unconverged)
    common = dict(
        x=tape.x, u=tape.u, impulse=tape.impulse, mu=tape.mu, converged=tape.converged,
        used=used, model_parameter_names=tape.theta_names, alive=tape.alive[:, :-1],
    )  # fmt: skip
    if reward is None:
        return Trajectory(**common)
    end = tape.alive[:, -1]
    r_T, dr_T = reward.terminal(tape.x[:, -1])
    r_T = np.where(end, r_T, 0.0)
    dr_T = np.where(end[:, None], dr_T, 0.0) + tape.stage_x[:, -1] if gradient else None
    returns = tape.stage_returns + r_T
    _check_finite(returns[used], "return")
    returns[~used] = np.nan  # a dropped rollout's states are not the model's either
    if not gradient:
        return Trajectory(returns=returns, **common)
    adj = reverse_pass(
        tape.dx_dx, tape.dx_du, dr_T[:, None, :],
        stage_x=tape.stage_x[:, :-1, None, :], stage_u=tape.stage_u[:, :, None, :],
        policy_vjps=tape.vjps, n_policy_params=np.size(theta) if policy is not None else 0,
        dx_dtheta=tape.dx_dtheta,
    )  # fmt: skip
    grad = adj.policy[:, 0] if adj.policy is not None else np.zeros((returns.size, 0))
    grads = {"grad": grad, "grad_x0": adj.x0[:, 0]}
    if adj.model is not None:
        grads["grad_model"] = adj.model[:, 0]
    for name, value in grads.items():
        _check_finite(value[used], f"gradient ({name})")
        value[~used] = np.nan  # never averaged in silently
    return Trajectory(returns=returns, **grads, **common)


def open_loop(
    stepper: Stepper,
    x0,
    u,
    *,
    jacobians: bool = True,
    on_unconverged: OnUnconverged = "drop",
) -> Trajectory:
    """Apply given inputs: ``x_{t+1} = f(x_t, u_t)`` for a batch, and (optionally) the Jacobians
    of the final state with respect to the initial state and every input, by the same reverse
    pass as the closed loop with K = nx objectives (the final state's coordinates).

    Args:
        stepper: the batched dynamics (e.g. ``LcsStepper(lcs, smoothing)``).
        x0: (nx,) or (B, nx) initial states.
        u: (N, nu) inputs shared by the batch, or (B, N, nu).
        jacobians: compute ``dxH_dx0`` (B, nx, nx) and ``dxH_du`` (B, N, nx, nu).
        on_unconverged: ``"drop"`` (default: a rollout with an unconverged step gets NaN
            Jacobians and ``used`` False), ``"flag"`` or ``"raise"``.
    """
    x0 = as_finite_array(x0, "x0", ndim=(1, 2))
    X0 = np.atleast_2d(x0)
    u = as_finite_array(u, "u", ndim=(2, 3))
    U = np.broadcast_to(u, (X0.shape[0],) + u.shape) if u.ndim == 2 else u
    if U.shape[0] != X0.shape[0]:
        raise ValueError(
            f"u must have shape (N, nu) or (B, N, nu) with B = {X0.shape[0]}; got {u.shape}"
        )
    tape = _forward(stepper, None, None, X0, U, None, 1.0, jacobians, False, on_unconverged)
    used = apply_on_unconverged(tape.converged, on_unconverged)
    dx0 = du = None
    if jacobians:
        nb, nx = X0.shape
        eye = np.broadcast_to(np.eye(nx), (nb, nx, nx))
        adj = reverse_pass(tape.dx_dx, tape.dx_du, eye, keep_inputs=True)
        dx0, du = adj.x0, adj.inputs
        dx0[~used] = np.nan  # never used silently
        du[~used] = np.nan
    return Trajectory(
        x=tape.x, u=tape.u, impulse=tape.impulse, mu=tape.mu, converged=tape.converged,
        used=used, dxH_dx0=dx0, dxH_du=du, alive=tape.alive[:, :-1],
    )  # fmt: skip


def record(stepper: Stepper, policy: Policy, theta, x0, noise, reward, *,
           sigma: float = 1.0) -> Tape:  # fmt: skip
    """The forward pass of :func:`rollout` with everything it stores, for estimators that need
    more than the totals (e.g. PIPPS: each step's reward and Jacobians). Fields: ``x`` (M, H +
    1, nx), ``u`` (M, H, nu), ``converged`` (M, H), ``dx_dx`` (M, H, nx, nx), ``dx_du`` (M, H,
    nx, nu), ``rewards`` (M, H) each step's reward, ``stage_x`` (M, H + 1, nx) and ``stage_u``
    (M, H, nu) the derivatives of the step rewards with respect to each state and input (a
    transition reward's dr/dx_{t+1} is in row t + 1), ``alive`` (M, H + 1) whether step t's
    reward counts (column H: the terminal reward). Ended episodes are held as in
    :func:`rollout`; the terminal reward is not included (``reward.terminal``)."""
    check_protocol(stepper, Stepper, "stepper", STEPPER_FORM)
    check_protocol(policy, Policy, "policy", "nx, nu, n_params, act, jacobians, vjp")
    check_reward(reward)
    return _forward(stepper, policy, theta, x0, noise, reward, sigma, True, False, "flag")


def _forward(stepper, policy, theta, x0, noise, reward, sigma, jacobians, parameters,
             on_unconverged) -> Tape:  # fmt: skip
    """The forward pass: check the inputs, step the batch H times, store what the reverse pass
    needs (step Jacobians when ``jacobians``; policy products for a pullback policy)."""
    check_on_unconverged(on_unconverged)
    noise = as_finite_array(noise, "noise", ndim=(3,))
    M, H, nu = noise.shape
    x0 = as_finite_array(x0, "x0", ndim=(1, 2))
    X0 = np.broadcast_to(x0, (M, x0.shape[-1])) if x0.ndim == 1 else x0
    nx = X0.shape[1]
    if X0.shape[0] != M:
        raise ValueError(f"x0 must have shape (nx,) or (M, nx) with M = {M}; got {x0.shape}")
    if policy is not None:
        theta = as_finite_array(theta, "theta", ndim=(1,))
        if nu != policy.nu or nx != policy.nx:
            raise ValueError(
                f"noise (M, H, nu) and x0 must match the policy's nu = {policy.nu}, "
                f"nx = {policy.nx}; got nu = {nu}, nx = {nx}"
            )
    if not (np.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"sigma must be a finite number >= 0; got {sigma!r}")
    names = tuple(stepper.parameter_names) if parameters else ()
    if parameters and not names:
        raise ValueError(f"parameters=True: {type(stepper).__name__} names no model parameters")
    xs = np.empty((M, H + 1, nx))
    us = np.empty((M, H, nu))
    conv = np.empty((M, H), dtype=bool)
    xs[:, 0] = X0
    impulse = mu = None
    Fx = np.empty((M, H, nx, nx)) if jacobians else None
    Fu = np.empty((M, H, nx, nu)) if jacobians else None
    Fth = np.empty((M, H, nx, len(names))) if parameters else None
    returns = np.zeros(M) if reward is not None else None
    step_r = np.zeros((M, H)) if reward is not None else None
    rx = np.zeros((M, H + 1, nx)) if (reward is not None and jacobians) else None
    ru = np.zeros((M, H, nu)) if rx is not None else None
    of_transition = reward is not None and isinstance(reward, TransitionReward)
    ends = of_transition and hasattr(reward, "terminated")
    alive = np.ones((M, H + 1), dtype=bool)
    timed = policy is not None and getattr(policy, "time_varying", False)
    if timed and jacobians:
        raise ValueError(
            f"{type(policy).__name__} is time-varying (act(theta, x, t)): it runs without "
            "gradients (gradient=False), as scripted and feedback controllers do"
        )
    pullback = jacobians and isinstance(policy, PullbackPolicy)
    vjps = [] if (jacobians and policy is not None) else None
    for t in range(H):
        x = xs[:, t]
        if policy is None:
            u = sigma * noise[:, t]
        elif pullback:
            u, vjp = policy.pullback(theta, x)
            u = u + sigma * noise[:, t]
            vjps.append(vjp)
        elif timed:
            u = policy.act(theta, x, t) + sigma * noise[:, t]
        else:
            u = policy.act(theta, x) + sigma * noise[:, t]
            if vjps is not None:
                vjps.append(_recomputed_vjp(policy, theta, x))
        us[:, t] = u
        if reward is not None and not of_transition:
            r, dr_dx, dr_du = reward.stage(x, u)
            returns += r  # in time order, one step at a time
            step_r[:, t] = r
            if rx is not None:
                rx[:, t], ru[:, t] = dr_dx, dr_du
        step = stepper.step(x, u, jacobians=jacobians, parameters=parameters)
        if impulse is None:
            nc = step.impulse.shape[-1]
            impulse, mu = np.empty((M, H, nc)), np.empty((M, H, nc))
        xs[:, t + 1], conv[:, t] = step.x_next, step.converged
        impulse[:, t], mu[:, t] = step.impulse, step.mu
        if jacobians:
            Fx[:, t], Fu[:, t] = step.dx_dx, step.dx_du
        if parameters:
            Fth[:, t] = step.dx_dtheta
        if of_transition:
            now = alive[:, t]
            extra = {"step": step} if getattr(reward, "uses_step", False) else {}
            r, dr_dx, dr_du, dr_dxn = reward.transition(x, u, xs[:, t + 1], **extra)
            step_r[:, t] = np.where(now, r, 0.0)  # a step after the end counts nothing
            returns += step_r[:, t]
            if rx is not None:
                rx[:, t] += np.where(now[:, None], dr_dx, 0.0)
                ru[:, t] = np.where(now[:, None], dr_du, 0.0)
                rx[:, t + 1] += np.where(now[:, None], dr_dxn, 0.0)
            alive[:, t + 1] = now & ~np.asarray(reward.terminated(xs[:, t + 1]), bool) if ends \
                else now  # fmt: skip
        if ends and not alive[:, t].all():  # an ended episode stays where it ended
            gone = ~alive[:, t]
            xs[gone, t + 1] = xs[gone, t]
            conv[gone, t] = True
            if jacobians:  # and carries no derivative
                Fx[gone, t], Fu[gone, t] = 0.0, 0.0
            if parameters:
                Fth[gone, t] = 0.0
    if impulse is None:  # H = 0
        impulse = mu = np.empty((M, 0, 0))
    return Tape(xs, us, impulse, mu, conv, Fx, Fu, Fth, names, returns, step_r, rx, ru, vjps,
                 alive)  # fmt: skip


def _recomputed_vjp(policy: Policy, theta: np.ndarray, x: np.ndarray):
    """The policy's vector-Jacobian product at (theta, x), evaluated when the reverse pass asks
    (nothing of the policy is stored but x, which the trajectory keeps anyway)."""
    return lambda g_u: policy.vjp(theta, x, g_u)


def _check_finite(values: np.ndarray, what: str) -> None:
    """A usable rollout (every step converged, or kept under "flag") must have a finite return
    and gradient: otherwise the state left the finite numbers, which is an error, not a result."""
    if not np.all(np.isfinite(values)):
        raise FloatingPointError(
            f"rollout: a rollout's {what} is not finite although its steps are usable "
            "(the state or the policy left the finite numbers)"
        )
