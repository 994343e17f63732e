"""Short-horizon actor-critic (SHAC) through a differentiable stepper, and plain first-order
policy gradients over whole episodes as its special case (Xu et al. 2022, "Accelerated Policy
Learning with Parallel Differentiable Simulation"; the ABS paper, Zhang et al. 2023, names a
critic as the tail estimate among the modifications FOPG takes naturally).

N environments persist across iterations. Iteration k:

1. every environment whose episode ended (terminated, reached ``episode_length`` steps, or was
   given up after an unconverged step) is reset with the environment's reset noise
   (``env.initial_states``);
2. the observation normaliser (mean, std of every observation seen so far, std floored at
   ``obs_min_std``) is frozen; the policy is ``u = pi((obs(x) - mean) / std; theta) + sigma xi``
   (``xi`` standard normal, sigma in action units, constant or decayed linearly over the
   environment steps);
3. all N environments are rolled forward for a window of h steps (fewer where an episode ends:
   ``L_m`` counted steps for environment m) and the window objective is differentiated by one
   reverse pass through the step Jacobians (:func:`drake_abs.engine.reverse_pass`)::

       J = 1/N_used sum_m [ sum_{t < L_m} gamma^t r_t  +  gamma^(L_m) V(x_(L_m)) ]

   the tail V only where the episode did not terminate (0 after termination; a window cut by
   the episode length or by h is bootstrapped), V the target critic of the normalised
   observation (as SHAC does). The discount folds into the reward derivatives of each step, the
   tail's gradient enters at x_(L_m);
4. ``theta`` takes one Adam step (ascent) on ``dJ/dtheta / h`` (SHAC's per-step normalisation),
   its norm clipped at ``max_grad_norm``;
5. the critic is fitted to the window's TD(lambda) targets (computed with the target critic;
   :func:`~drake_abs.policy.value_function.td_lambda_targets`) for ``critic_epochs`` passes of
   ``critic_minibatches`` minibatches; the target critic moves towards it, ``target <- alpha
   target + (1 - alpha) critic``;
6. the normaliser takes the window's observations (the states where the policy acted).

**Plain FOPG on the same footing** (:meth:`ShacConfig.fopg`): the window is the whole episode
(h = ``episode_length``), no critic (V = 0) and gamma = 1: each iteration rolls N fresh
episodes from the reset noise to their end and steps on the mean return's gradient.

**Unconverged steps** (``on_unconverged``, :mod:`drake_abs.contact.unconverged`): ``"drop"``
(default) leaves an environment whose window took an unconverged solver step out of the
gradient, the critic's data and the normaliser, and resets it (its state is not the model's);
``"flag"`` keeps it; ``"raise"`` raises. Every iteration logs how many windows were dropped.

**Environment steps** are the control periods stepped by live environments: the ``L_m`` counted
steps of each window (an environment held after its episode ended, or stepped past its episode's
length to fill the batch, counts nothing). The forward pass runs in chunks of ``chunk`` steps
over the environments still live (an environment whose episode ended leaves the batch).

**Checkpoints**: :meth:`ShacTrainer.save` writes the whole training state (policy and critic
parameters, both optimisers, the normaliser, the environments' states and episode counters,
the step counts, the log and the random generator) to one file; :meth:`ShacTrainer.load`
continues from it, bit for bit the numbers of an uninterrupted run (the wall seconds aside).
A checkpoint is a pickle for this library's own use (it is not a published format and should
only be loaded from a trusted source).

The environment (:class:`TrainingEnvironment`) is anything with a ``stepper``, a ``reward`` (a
:class:`~drake_abs.engine.protocols.TransitionReward`, with ``terminated`` where episodes
end, or a stage :class:`~drake_abs.engine.protocols.Reward`; terminal rewards are not used),
an ``observation`` map, ``n_obs``, ``nu``, ``initial_states(rng, M)`` and ``policy(inner)`` (the
full-state policy ``inner(obs(x))``): a :class:`drake_abs.tasks.locomotion.LocomotionTask`.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal, Protocol, runtime_checkable

import numpy as np

from drake_abs._validation import as_count, as_finite_array
from drake_abs.contact.unconverged import (
    OnUnconverged,
    apply_on_unconverged,
    check_on_unconverged,
)
from drake_abs.engine import record, reverse_pass
from drake_abs.engine.protocols import Policy, TransitionReward, check_reward
from drake_abs.policy.checkpoints import read_checkpoint, train_resumable, write_checkpoint
from drake_abs.policy.methods import method as registry_method
from drake_abs.policy.observation_normalizer import NormalizedPolicy, RunningMeanStd
from drake_abs.policy.policies import LinearPolicy, MLPPolicy
from drake_abs.policy.training import Adam
from drake_abs.policy.value_function import StateValue, ValueFunction, td_lambda_targets

__all__ = [
    "CHECKPOINT_FORMAT",
    "ShacConfig",
    "ShacState",
    "ShacTrainer",
    "TrainingEnvironment",
    "Window",
    "window_gradient",
]

#: The ``format`` entry of a checkpoint file.
CHECKPOINT_FORMAT = "drake-abs shac checkpoint"
_CHECKPOINT_VERSION = 1


@runtime_checkable
class TrainingEnvironment(Protocol):
    """What :class:`ShacTrainer` trains in (see the module docstring)."""

    stepper: object
    reward: object
    observation: object

    @property
    def n_obs(self) -> int: ...

    @property
    def nu(self) -> int: ...

    def initial_states(self, rng: np.random.Generator, M: int) -> np.ndarray: ...

    def policy(self, inner: Policy) -> Policy: ...


@dataclass(frozen=True)
class ShacConfig:
    """SHAC's settings (defaults after Xu et al. 2022 where they apply to a linear or small
    policy).

    Attributes:
        envs: N, environments rolled in parallel (persisting across iterations).
        window: h, steps per window; None: the whole episode (``episode_length``).
        episode_length: steps after which an episode is truncated (gymnasium's 1000).
        critic: learn a value function as the window's tail; False: V = 0.
        gamma: discount per step; lam: TD(lambda)'s lambda.
        sigma: exploration noise std (action units) added to the policy's action.
        sigma_end: if given, sigma decays linearly to it over ``sigma_decay_steps`` environment
            steps (then stays).
        sigma_decay_steps: environment steps of that decay (> 0 with ``sigma_end``).
        actor_lr_decay_steps: if > 0, the policy's step size decays linearly from ``actor_lr``
            to 0 over this many environment steps (SHAC's linear schedule, Xu et al. 2022);
            0: constant.
        policy: ``"linear"`` (u = W z + b) or ``"mlp"`` (tanh hidden layers ``hidden``).
        hidden: the MLP policy's hidden widths.
        actor_lr: Adam's step size for the policy.
        max_grad_norm: clip the policy gradient (of J / h) at this norm; None: no clipping.
        critic_hidden: the critic's hidden widths (tanh).
        critic_lr: Adam's step size for the critic.
        critic_epochs: passes over a window's samples per critic fit.
        critic_minibatches: minibatches per pass.
        target_critic_alpha: alpha of ``target <- alpha target + (1 - alpha) critic``.
        obs_min_std: floor of the normaliser's std (units of each observation entry).
        chunk: forward steps per engine call (environments whose episode ended leave the batch
            between chunks).
        on_unconverged: ``"drop"``, ``"flag"`` or ``"raise"`` (module docstring).
        recent_episodes: the log's ``recent_return`` averages this many last completed
            episodes.
    """

    envs: int = 64
    window: int | None = 32
    episode_length: int = 1000
    critic: bool = True
    gamma: float = 0.99
    lam: float = 0.95
    sigma: float = 0.1
    sigma_end: float | None = None
    sigma_decay_steps: int = 0
    actor_lr_decay_steps: int = 0
    policy: Literal["linear", "mlp"] = "linear"
    hidden: tuple[int, ...] = (64, 64)
    actor_lr: float = 2e-3
    max_grad_norm: float | None = 1.0
    critic_hidden: tuple[int, ...] = (64, 64)
    critic_lr: float = 1e-3
    critic_epochs: int = 16
    critic_minibatches: int = 4
    target_critic_alpha: float = 0.2
    obs_min_std: float = 1e-2
    chunk: int = 32
    on_unconverged: OnUnconverged = "drop"
    recent_episodes: int = 50

    def __post_init__(self):
        as_count(self.envs, "envs", minimum=1)
        as_count(self.episode_length, "episode_length", minimum=1)
        if self.window is not None:
            as_count(self.window, "window", minimum=1)
        as_count(self.chunk, "chunk", minimum=1)
        as_count(self.critic_epochs, "critic_epochs", minimum=1)
        as_count(self.critic_minibatches, "critic_minibatches", minimum=1)
        as_count(self.recent_episodes, "recent_episodes", minimum=1)
        as_count(self.sigma_decay_steps, "sigma_decay_steps", minimum=0)
        as_count(self.actor_lr_decay_steps, "actor_lr_decay_steps", minimum=0)
        for name in ("gamma", "lam", "target_critic_alpha"):
            v = getattr(self, name)
            if not (np.isfinite(v) and 0 <= v <= 1):
                raise ValueError(f"{name} must be in [0, 1]; got {v!r}")
        for name in ("sigma", "actor_lr", "critic_lr", "obs_min_std"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0) or (name != "sigma" and v == 0):
                raise ValueError(f"{name} must be a finite number > 0 (>= 0 for sigma); got {v!r}")
        if self.sigma_end is not None:
            if not (np.isfinite(self.sigma_end) and self.sigma_end >= 0):
                raise ValueError(f"sigma_end must be a finite number >= 0; got {self.sigma_end!r}")
            if self.sigma_decay_steps == 0:
                raise ValueError("sigma_end needs sigma_decay_steps > 0 (the decay's length)")
        if self.max_grad_norm is not None and not (
            np.isfinite(self.max_grad_norm) and self.max_grad_norm > 0
        ):
            raise ValueError(f"max_grad_norm must be > 0 or None; got {self.max_grad_norm!r}")
        if self.policy not in ("linear", "mlp"):
            raise ValueError(f"policy must be 'linear' or 'mlp'; got {self.policy!r}")
        for name in ("hidden", "critic_hidden"):
            widths = getattr(self, name)
            if not widths or any(int(w) < 1 for w in widths):
                raise ValueError(f"{name} must be one or more widths >= 1; got {widths!r}")
            object.__setattr__(self, name, tuple(int(w) for w in widths))
        check_on_unconverged(self.on_unconverged)

    @classmethod
    def fopg(cls, **overrides) -> ShacConfig:
        """Plain first-order policy gradients over whole episodes: window = the episode, no
        critic, gamma = 1 (``overrides`` replace any setting)."""
        return cls(**({"window": None, "critic": False, "gamma": 1.0} | overrides))

    @classmethod
    def for_method(cls, name: str, **overrides) -> ShacConfig:
        """The settings of a registered method (:mod:`drake_abs.policy.methods`) this trainer
        runs: ``"shac"`` methods (``shac_abs``, ``shac_exact``) SHAC's, ``"fopg_episode"``
        methods :meth:`fopg`'s; ``overrides`` replace any. The method's smoothing is the
        model's (``method(name).make_smoothing(...)``), not a setting here."""
        m = registry_method(name)
        if m.estimator == "shac":
            return cls(**overrides)
        if m.estimator == "fopg_episode":
            return cls.fopg(**overrides)
        raise ValueError(
            f"name must be a method this trainer runs ('shac' or 'fopg_episode'); {name!r} is "
            f"{m.estimator!r}"
        )

    @property
    def horizon(self) -> int:
        """h: the window's length in steps."""
        return self.episode_length if self.window is None else min(self.window, self.episode_length)

    def actor_lr_at(self, env_steps: int) -> float:
        """The policy's step size after ``env_steps`` environment steps."""
        if self.actor_lr_decay_steps == 0:
            return float(self.actor_lr)
        return float(self.actor_lr * max(0.0, 1.0 - env_steps / self.actor_lr_decay_steps))

    def sigma_at(self, env_steps: int) -> float:
        """The exploration std after ``env_steps`` environment steps."""
        if self.sigma_end is None:
            return float(self.sigma)
        frac = min(1.0, env_steps / self.sigma_decay_steps)
        return float(self.sigma + (self.sigma_end - self.sigma) * frac)


@dataclass(frozen=True)
class Window:
    """One differentiated window of N environments (:func:`window_gradient`).

    Attributes:
        objective: J, the mean over the used environments of their discounted window objective
            (NaN if none was used).
        grad: (P,) dJ/dtheta (zeros if no environment was used).
        objectives: (N,) each environment's discounted window objective (NaN where dropped).
        returns: (N,) each environment's undiscounted sum of counted rewards.
        lengths: (N,) L_m, the counted steps.
        terminated: (N,) the episode terminated within the window (at step L_m).
        truncated: (N,) the episode reached its length (L_m == remaining_m).
        used: (N,) the environment's window counts (no unconverged step, or ``"flag"``).
        unconverged: the number of counted steps whose solver did not converge.
        x: (N, H + 1, nx) states (held after an environment left the batch).
        u: (N, H, nu) actions applied.
        rewards: (N, H) each counted step's reward (0 elsewhere).
        tail: (N,) V(x_(L_m)) where it was added (bootstrapped), 0 elsewhere.
        bootstrap: (N,) whether the tail was added.
        scores: (N,) the score reward summed over the counted steps (0 without one).
    """

    objective: float
    grad: np.ndarray
    objectives: np.ndarray
    returns: np.ndarray
    lengths: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    used: np.ndarray
    unconverged: int
    x: np.ndarray
    u: np.ndarray
    rewards: np.ndarray
    tail: np.ndarray
    bootstrap: np.ndarray
    scores: np.ndarray


class _WindowReward:
    """The reward of one chunk of a window as the engine's forward pass sees it: step t's
    reward and its derivatives times ``w_m(t) = gamma^t`` while t < ``remaining_m`` (0 after:
    the episode was truncated), so that the tape's reward rows are the window objective's
    discounted ones. It keeps each step's undiscounted rewards (and a score reward's) as it is
    called, once per step in order (``t`` counts the calls). A stage reward is taken as a
    transition reward with no ``x_next`` term; termination is the inner reward's."""

    def __init__(self, reward, gamma: float, t0: int, remaining: np.ndarray, score=None):
        self.reward, self.gamma, self.t, self.remaining = reward, gamma, t0, remaining
        self.score = score
        self.uses_step = any(getattr(r, "uses_step", False) for r in (reward, score))
        self.raw: list[np.ndarray] = []
        self.scores: list[np.ndarray] = []

    @staticmethod
    def _terms(reward, x, u, x_next, extra):
        if isinstance(reward, TransitionReward):
            if not getattr(reward, "uses_step", False):
                extra = {}
            return reward.transition(x, u, x_next, **extra)
        r, dr_dx, dr_du = reward.stage(x, u)
        return r, dr_dx, dr_du, np.zeros_like(x_next)

    def transition(self, x, u, x_next, **extra):
        r, dr_dx, dr_du, dr_dxn = self._terms(self.reward, x, u, x_next, extra)
        self.raw.append(np.asarray(r, dtype=float))
        if self.score is not None:
            self.scores.append(np.asarray(self._terms(self.score, x, u, x_next, extra)[0]))
        w = np.where(self.t < self.remaining, self.gamma**self.t, 0.0)
        self.t += 1
        live = (w > 0)[:, None]
        return (np.where(w > 0, w * r, 0.0), np.where(live, w[:, None] * dr_dx, 0.0),
                np.where(live, w[:, None] * dr_du, 0.0),
                np.where(live, w[:, None] * dr_dxn, 0.0))  # fmt: skip

    def terminal(self, x):
        x = np.asarray(x, dtype=float)
        return np.zeros(x.shape[0]), np.zeros(x.shape)

    def terminated(self, x_next) -> np.ndarray:
        if hasattr(self.reward, "terminated"):
            return np.asarray(self.reward.terminated(x_next), dtype=bool)
        return np.zeros(np.shape(x_next)[0], dtype=bool)


def window_gradient(
    stepper,
    policy: Policy,
    theta,
    x0,
    noise,
    reward,
    *,
    sigma: float,
    remaining,
    gamma: float,
    value: StateValue | None = None,
    chunk: int = 32,
    on_unconverged: OnUnconverged = "drop",
    score_reward=None,
) -> Window:
    """Roll N environments through one window and differentiate its objective (module
    docstring, step 3).

    Args:
        stepper: the batched dynamics.
        policy: the full-state policy ``u = pi(x; theta)``.
        theta: (P,) its parameters.
        x0: (N, nx) the environments' states at the window's start.
        noise: (N, H, nu) standard-normal exploration samples (H the window's length).
        reward: a transition (with ``terminated`` where episodes end) or stage reward.
        sigma: exploration std (action units).
        remaining: (N,) steps left in each episode (>= 1): a window is cut there (truncated,
            bootstrapped).
        gamma: discount in [0, 1].
        value: the tail ``V(x)`` with dV/dx
            (:class:`~drake_abs.policy.value_function.StateValue`); None: V = 0.
        chunk: forward steps per engine call.
        on_unconverged: ``"drop"``, ``"flag"`` or ``"raise"``.
        score_reward: another reward summed over the same counted steps (``Window.scores``),
            not differentiated.
    """
    check_reward(reward)
    if score_reward is not None:
        check_reward(score_reward, "score_reward")
    check_on_unconverged(on_unconverged)
    theta = as_finite_array(theta, "theta", ndim=(1,))
    x0 = as_finite_array(x0, "x0", ndim=(2,))
    noise = as_finite_array(noise, "noise", ndim=(3,))
    N, H, nu = noise.shape
    nx = x0.shape[1]
    if x0.shape[0] != N:
        raise ValueError(f"x0 must have shape (N, nx) with N = {N} (noise's); got {x0.shape}")
    remaining = np.asarray(remaining)
    if remaining.shape != (N,) or not np.issubdtype(remaining.dtype, np.integer):
        raise ValueError(f"remaining must be whole numbers of shape (N,) = ({N},)")
    if np.any(remaining < 1):
        raise ValueError("remaining must be >= 1 for every environment (reset ended episodes)")
    if not (np.isfinite(gamma) and 0 <= gamma <= 1):
        raise ValueError(f"gamma must be in [0, 1]; got {gamma!r}")
    chunk = as_count(chunk, "chunk", minimum=1)

    xs = np.empty((N, H + 1, nx))
    xs[:, 0] = x0
    us = np.zeros((N, H, nu))
    Fx = np.zeros((N, H, nx, nx))
    Fu = np.zeros((N, H, nx, nu))
    S_x = np.zeros((N, H + 1, nx))  # d(discounted rewards)/dx_t
    S_u = np.zeros((N, H, nu))
    disc_r = np.zeros((N, H))  # gamma^t r_t on the counted steps
    raw_r = np.zeros((N, H))
    score_r = np.zeros((N, H))
    counted = np.zeros((N, H), dtype=bool)  # step t's reward counts for environment m
    converged = np.ones((N, H), dtype=bool)
    terminated = np.zeros(N, dtype=bool)
    live = np.arange(N)
    t0 = 0
    while t0 < H and live.size:
        t1 = min(H, t0 + chunk)
        wrapped = _WindowReward(reward, gamma, t0, remaining[live], score_reward)
        tape = record(stepper, policy, theta, xs[live, t0], noise[live, t0:t1], wrapped,
                      sigma=sigma)  # fmt: skip
        if wrapped.t != t1:  # the engine evaluates each step's reward once, in order
            raise RuntimeError(f"the reward was called {wrapped.t - t0} times for {t1 - t0} steps")
        xs[live, t0 : t1 + 1] = tape.x
        us[live, t0:t1] = tape.u
        Fx[live, t0:t1], Fu[live, t0:t1] = tape.dx_dx, tape.dx_du
        S_x[live, t0 : t1 + 1] += tape.stage_x  # row t1: the last transition's x_next term
        S_u[live, t0:t1] = tape.stage_u
        disc_r[live, t0:t1] = tape.rewards
        steps = t0 + np.arange(t1 - t0)
        in_episode = steps[None, :] < remaining[live, None]
        count = tape.alive[:, :-1] & in_episode
        raw_r[live, t0:t1] = np.where(count, np.stack(wrapped.raw, axis=1), 0.0)
        if score_reward is not None:
            score_r[live, t0:t1] = np.where(count, np.stack(wrapped.scores, axis=1), 0.0)
        counted[live, t0:t1] = count
        converged[live, t0:t1] = tape.converged | ~count
        # terminated at a counted step of this chunk: alive before it, not after
        term = np.any(count & ~tape.alive[:, 1:], axis=1)
        terminated[live] |= term
        bad = ~converged[live, t0:t1].all(axis=1) if on_unconverged == "drop" else False
        go = ~term & (t1 < remaining[live]) & ~bad
        gone = live[~go]
        xs[gone, t1 + 1 :] = xs[gone, t1][:, None]  # held where they left the batch
        live = live[go]
        t0 = t1
    used = apply_on_unconverged(converged, on_unconverged)
    lengths = counted.sum(axis=1)
    truncated = lengths == remaining
    bootstrap = used & ~terminated & (value is not None)
    n_unconverged = int((~converged).sum())

    rows = np.arange(N)
    x_end = xs[rows, lengths]
    tail = np.zeros(N)
    dtail = np.zeros((N, nx))
    if value is not None and bootstrap.any():
        v, dv = value.value_and_gradient(x_end[bootstrap])
        tail[bootstrap], dtail[bootstrap] = v, dv
    end_disc = gamma ** lengths.astype(float)
    objectives = disc_r.sum(axis=1) + end_disc * tail
    n_used = int(used.sum())
    objective = float(objectives[used].mean()) if n_used else float("nan")
    objectives = np.where(used, objectives, np.nan)

    P = theta.size
    if n_used == 0:
        grad = np.zeros(P)
    else:
        w = np.where(used, 1.0 / n_used, 0.0)  # the mean over the used environments
        S_x[rows, lengths] += end_disc[:, None] * dtail
        S_x = np.where(used[:, None, None], w[:, None, None] * S_x, 0.0)
        S_u = np.where(used[:, None, None], w[:, None, None] * S_u, 0.0)
        keep = (counted & used[:, None])[:, :, None, None]
        Fx, Fu = np.where(keep, Fx, 0.0), np.where(keep, Fu, 0.0)
        vjps = [(lambda g, x=xs[:, t]: policy.vjp(theta, x, g)) for t in range(H)]
        adj = reverse_pass(Fx, Fu, S_x[:, H, None], stage_x=S_x[:, :H, None],
                           stage_u=S_u[:, :, None], policy_vjps=vjps,
                           n_policy_params=P)  # fmt: skip
        grad = adj.policy[:, 0].sum(axis=0)
        if not np.all(np.isfinite(grad)):
            raise FloatingPointError(
                "window_gradient: the gradient is not finite although every used step "
                "converged (the state or the policy left the finite numbers)"
            )
    return Window(
        objective=objective, grad=grad, objectives=objectives, returns=raw_r.sum(axis=1),
        lengths=lengths, terminated=terminated, truncated=truncated & ~terminated, used=used,
        unconverged=n_unconverged, x=xs, u=us, rewards=raw_r, tail=np.where(bootstrap, tail, 0.0),
        bootstrap=bootstrap, scores=score_r.sum(axis=1),
    )  # fmt: skip


@dataclass
class ShacState:
    """Everything a training run carries from one iteration to the next (a checkpoint).

    Attributes:
        iteration: iterations done.
        theta: (P,) the policy's parameters (of the normalised observation).
        phi, phi_target: (Q,) the critic's and the target critic's parameters (empty without a
            critic).
        actor_opt, critic_opt: the two Adam optimisers (their moments and step counts).
        normalizer: the observations' running statistics.
        x: (N, nx) the environments' states.
        episode_step: (N,) steps taken in each environment's episode.
        episode_return: (N,) each episode's undiscounted training return so far.
        episode_score: (N,) its return under the score reward (if given), else 0.
        needs_reset: (N,) the environment is reset before the next window.
        env_steps: environment steps so far; seconds: wall seconds of training so far.
        episodes: completed episodes so far.
        recent: the last completed episodes' (return, score) pairs.
        rng: the one random generator (resets, exploration, critic minibatches).
        rows: the log, one dict per iteration.
    """

    iteration: int
    theta: np.ndarray
    phi: np.ndarray
    phi_target: np.ndarray
    actor_opt: Adam
    critic_opt: Adam
    normalizer: RunningMeanStd
    x: np.ndarray
    episode_step: np.ndarray
    episode_return: np.ndarray
    episode_score: np.ndarray
    needs_reset: np.ndarray
    env_steps: int
    seconds: float
    episodes: int
    recent: deque
    rng: np.random.Generator
    rows: list = field(default_factory=list)


class ShacTrainer:
    """SHAC (or plain FOPG, :meth:`ShacConfig.fopg`) on an environment; see the module
    docstring.

    Args:
        env: the :class:`TrainingEnvironment` (e.g. a locomotion task).
        config: the settings.
        seed: seeds everything (one generator: resets, exploration, critic minibatches, initial
            weights).
        theta0: (P,) initial policy parameters (default: zeros for a linear policy; Glorot
            weights with the last layer scaled by 0.01 for an MLP).
        score_reward: optional reward logged beside the training reward (e.g. gymnasium's own
            when the training reward has a smooth survive term); not differentiated.
    """

    def __init__(
        self,
        env: TrainingEnvironment,
        config: ShacConfig,
        seed: int,
        *,
        theta0=None,
        score_reward=None,
    ):
        if not isinstance(env, TrainingEnvironment):
            raise TypeError(
                "env must have stepper, reward, observation, n_obs, nu, initial_states(rng, M) "
                f"and policy(inner); got {type(env).__name__}"
            )
        if not isinstance(config, ShacConfig):
            raise TypeError(f"config must be a ShacConfig; got {type(config).__name__}")
        check_reward(env.reward, "env.reward")
        if score_reward is not None:
            check_reward(score_reward, "score_reward")
        self.env, self.config, self.seed = env, config, int(seed)
        self.score_reward = score_reward
        self.inner = self._inner_policy()
        self.critic = ValueFunction(env.n_obs, config.critic_hidden) if config.critic else None
        rng = np.random.default_rng(self.seed)
        theta = self._theta0(rng) if theta0 is None else np.array(theta0, dtype=float)
        if theta.shape != (self.inner.n_params,):
            raise ValueError(f"theta0 must have shape ({self.inner.n_params},); got {theta.shape}")
        phi = self.critic.init(rng) if self.critic is not None else np.zeros(0)
        N, n = config.envs, env.n_obs
        nx = env.policy(NormalizedPolicy(self.inner, np.zeros(n), np.ones(n))).nx
        self.state = ShacState(
            iteration=0, theta=theta, phi=phi, phi_target=phi.copy(),
            actor_opt=Adam(lr=config.actor_lr), critic_opt=Adam(lr=config.critic_lr),
            normalizer=RunningMeanStd(env.n_obs), x=np.zeros((N, nx)),
            episode_step=np.zeros(N, dtype=np.int64), episode_return=np.zeros(N),
            episode_score=np.zeros(N), needs_reset=np.ones(N, dtype=bool), env_steps=0,
            seconds=0.0, episodes=0, recent=deque(maxlen=config.recent_episodes), rng=rng,
        )  # fmt: skip

    def _inner_policy(self) -> LinearPolicy | MLPPolicy:
        c, n, nu = self.config, self.env.n_obs, self.env.nu
        return LinearPolicy(n, nu) if c.policy == "linear" else MLPPolicy(n, nu, c.hidden)

    def _theta0(self, rng: np.random.Generator) -> np.ndarray:
        if isinstance(self.inner, LinearPolicy):
            return np.zeros(self.inner.n_params)
        theta = self.inner.init(rng)
        last = self.inner.nu * (self.inner.sizes[-2] + 1)  # the output layer's W and b
        theta[-last:] *= 0.01  # near-zero actions at the start
        return theta

    # -- the policy and the critic at the current statistics --------------------------------

    def normalizer_stats(self) -> tuple[np.ndarray, np.ndarray]:
        """(mean, std) the policy and the critic divide by now (std floored)."""
        stats = self.state.normalizer
        return stats.mean, stats.floored_std(self.config.obs_min_std)

    def normalized_policy(self) -> NormalizedPolicy:
        """The policy of the raw observation, ``inner((o - mean) / std)``, at the current
        statistics (use it with ``state.theta``)."""
        mean, std = self.normalizer_stats()
        return NormalizedPolicy(self.inner, mean, std)

    def full_state_policy(self) -> Policy:
        """``env.policy(normalized_policy())``: the policy of the full state."""
        return self.env.policy(self.normalized_policy())

    def policy_arrays(self) -> dict[str, np.ndarray]:
        """The current policy as plain arrays of the observation: a linear policy as ``W``
        (nu, n_obs), ``b``, ``obs_mean``, ``obs_std`` (action = clip(W (obs - obs_mean) /
        obs_std + b)); an MLP as ``W0, b0, W1, b1, ...`` (the last layer linear),
        ``obs_mean``, ``obs_std`` and ``activation`` ("tanh")."""
        mean, std = self.normalizer_stats()
        theta, inner = self.state.theta, self.inner
        out: dict[str, np.ndarray] = {}
        if isinstance(inner, LinearPolicy):
            P = inner.nu * inner.nx
            out["W"] = theta[:P].reshape(inner.nu, inner.nx).copy()
            out["b"] = theta[P:].copy()
        else:
            sizes, o = inner.sizes, 0
            for i in range(len(sizes) - 1):
                n_w = sizes[i + 1] * sizes[i]
                out[f"W{i}"] = theta[o : o + n_w].reshape(sizes[i + 1], sizes[i]).copy()
                out[f"b{i}"] = theta[o + n_w : o + n_w + sizes[i + 1]].copy()
                o += n_w + sizes[i + 1]
            out["activation"] = np.array("tanh")
        out["obs_mean"], out["obs_std"] = mean, std
        return out

    def _value(self, phi) -> StateValue | None:
        if self.critic is None:
            return None
        mean, std = self.normalizer_stats()
        return StateValue(self.critic, phi, self.env.observation, mean, std)

    # -- one iteration ----------------------------------------------------------------------

    def iterate(self) -> dict:
        """One iteration (module docstring); returns its log row (also appended to
        ``state.rows``)."""
        s, c, env = self.state, self.config, self.env
        start = time.perf_counter()
        reset = np.flatnonzero(s.needs_reset)
        if reset.size:
            s.x[reset] = env.initial_states(s.rng, reset.size)
            s.episode_step[reset] = 0
            s.episode_return[reset] = 0.0
            s.episode_score[reset] = 0.0
            s.needs_reset[reset] = False
        remaining = c.episode_length - s.episode_step
        H = int(min(c.horizon, remaining.max()))
        noise = s.rng.standard_normal((c.envs, H, env.nu))
        sigma = c.sigma_at(s.env_steps)
        mean, std = self.normalizer_stats()  # frozen for the window
        policy = self.full_state_policy()
        target = self._value(s.phi_target)
        win = window_gradient(
            env.stepper, policy, s.theta, s.x, noise, env.reward, sigma=sigma,
            remaining=remaining, gamma=c.gamma, value=target, chunk=c.chunk,
            on_unconverged=c.on_unconverged, score_reward=self.score_reward,
        )  # fmt: skip
        grad = win.grad / H
        grad_norm = float(np.linalg.norm(grad))
        if c.max_grad_norm is not None and grad_norm > c.max_grad_norm:
            grad = grad * (c.max_grad_norm / grad_norm)
        if win.used.any():
            s.actor_opt.lr = c.actor_lr_at(s.env_steps)
            s.theta = s.actor_opt.step(s.theta, grad)

        counted = np.arange(H)[None, :] < win.lengths[:, None]
        data = counted & win.used[:, None]  # the steps the critic and the normaliser learn from
        critic_loss = None
        if self.critic is not None and data.any():
            z = (env.observation(win.x.reshape(-1, win.x.shape[-1])) - mean) / std
            z = z.reshape(c.envs, H + 1, -1)
            values = self.critic(s.phi_target, z.reshape(-1, z.shape[-1])).reshape(c.envs, H + 1)
            G = td_lambda_targets(win.rewards, values, win.lengths,
                                  ~win.terminated, c.gamma, c.lam)  # fmt: skip
            s.phi, critic_loss = self.critic.fit(
                s.phi, z[:, :H][data], G[data], s.critic_opt, s.rng,
                epochs=c.critic_epochs, minibatches=c.critic_minibatches,
            )  # fmt: skip
            a = c.target_critic_alpha
            s.phi_target = a * s.phi_target + (1 - a) * s.phi
        if data.any():
            o = env.observation(win.x[:, :H][data])
            s.normalizer.push(o)

        # the environments' bookkeeping
        steps = int(win.lengths.sum())
        s.env_steps += steps
        s.x = win.x[np.arange(c.envs), win.lengths].copy()
        s.episode_step += win.lengths
        s.episode_return += win.returns
        s.episode_score += win.scores
        done = win.used & (win.terminated | win.truncated)
        for m in np.flatnonzero(done):
            s.recent.append((float(s.episode_return[m]), float(s.episode_score[m])))
        s.episodes += int(done.sum())
        s.needs_reset |= done | ~win.used
        s.iteration += 1
        s.seconds += time.perf_counter() - start
        recent = np.array(s.recent) if s.recent else None  # (episodes, 2): return, score
        row = {
            "iteration": s.iteration,
            "env_steps": s.env_steps,
            "seconds": s.seconds,
            "window": H,
            "sigma": sigma,
            "objective": win.objective,
            "recent_return": None if recent is None else float(recent[:, 0].mean()),
            "recent_score": None
            if recent is None or self.score_reward is None
            else float(recent[:, 1].mean()),
            "episodes": s.episodes,
            "critic_loss": critic_loss,
            "grad_norm": grad_norm,
            "dropped": int((~win.used).sum()),
            "unconverged_steps": win.unconverged,
        }
        s.rows.append(row)
        return row

    def train(
        self,
        iterations: int,
        *,
        checkpoint: str | Path | None = None,
        checkpoint_every: int = 10,
        max_seconds: float | None = None,
        callback=None,
    ) -> list[dict]:
        """Iterate until ``state.iteration == iterations`` (a resumed run continues to the same
        total) or ``max_seconds`` of wall time in this call have passed; save a checkpoint every
        ``checkpoint_every`` iterations and at the end (with ``checkpoint``). ``callback(row)``
        after each iteration. Returns the whole log
        (:func:`~drake_abs.policy.checkpoints.train_resumable`)."""
        return train_resumable(
            self, iterations, checkpoint=checkpoint, checkpoint_every=checkpoint_every,
            max_seconds=max_seconds, callback=callback,
        )  # fmt: skip

    # -- checkpoints ------------------------------------------------------------------------

    def save(self, path: str | Path) -> Path:
        """Write the whole training state to ``path`` (:mod:`drake_abs.policy.checkpoints`)."""
        payload = {"config": asdict(self.config), "seed": self.seed, "state": self.state}
        return write_checkpoint(path, payload, kind=CHECKPOINT_FORMAT,
                                version=_CHECKPOINT_VERSION)  # fmt: skip

    @classmethod
    def load(cls, path: str | Path, env: TrainingEnvironment, *, score_reward=None) -> ShacTrainer:
        """A trainer continuing from the checkpoint at ``path`` in ``env`` (the same
        environment the run was started in: it is not stored)."""
        payload = read_checkpoint(path, kind=CHECKPOINT_FORMAT, version=_CHECKPOINT_VERSION)
        config = ShacConfig(**payload["config"])
        trainer = cls(env, config, payload["seed"], score_reward=score_reward)
        state = payload["state"]
        if state.x.shape != trainer.state.x.shape or state.theta.shape != trainer.state.theta.shape:
            raise ValueError(
                "the checkpoint does not fit env: its states or policy have other sizes"
            )
        trainer.state = state
        return trainer
