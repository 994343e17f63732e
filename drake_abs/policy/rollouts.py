"""The estimators' unit of work, its seed tree, and where it runs.

Every policy-gradient estimator (:mod:`drake_abs.policy.estimators`) describes the rollouts it
needs as :class:`RolloutJob` s (parameters theta, a noise key, and a range of rollout indices),
hands them to a runner, and reduces the per-rollout results (:class:`RolloutStats`) it gets
back. The runner decides where the rollouts run: :class:`LocalRunner` (this process, the
default) or :class:`drake_abs.parallel.RayRunner` (split over Ray actors). Both call the one
function :func:`rollout_stats`, and the reductions happen here in the estimator, over arrays in
rollout order, so a distributed estimate is the single-process one.

The seed tree: rollout m of the stream ``key`` draws its exploration noise xi (H, nu) from
``numpy.random.SeedSequence(key, spawn_key=(m,))``, whatever process runs it and whichever
rollouts share its batch. An estimator draws each key from its Generator
(:func:`noise_key`), so the same seed gives the same numbers for any number of workers.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from drake_abs._validation import as_finite_array

#: Keys are drawn below this bound (numpy's SeedSequence takes any non-negative integer).
KEY_BOUND = 2**63


def noise_key(rng: np.random.Generator) -> int:
    """A fresh noise-stream key drawn from ``rng`` (one draw: advances ``rng`` by one integer)."""
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy Generator; got {type(rng).__name__}")
    return int(rng.integers(KEY_BOUND))


def rollout_noise(key: int, start: int, stop: int, horizon: int, nu: int) -> np.ndarray:
    """Standard-normal exploration noise (stop - start, horizon, nu) of rollouts
    ``start..stop-1`` of stream ``key``: row m from ``SeedSequence(key, spawn_key=(m,))``, so a
    rollout's noise does not depend on how the rollouts are split."""
    _check_key(key)
    out = np.empty((stop - start, int(horizon), int(nu)))
    for i, m in enumerate(range(start, stop)):
        gen = np.random.default_rng(np.random.SeedSequence(key, spawn_key=(m,)))
        out[i] = gen.standard_normal((int(horizon), int(nu)))
    return out


def _check_key(key) -> None:
    if isinstance(key, bool) or not isinstance(key, int | np.integer) or key < 0:
        raise ValueError(f"key must be a non-negative integer (a noise stream); got {key!r}")


@dataclass(frozen=True)
class RolloutJob:
    """Rollouts ``start..stop-1`` of noise stream ``key``, all with policy parameters ``theta``
    (P,). An estimator's rollouts at one theta are one job; randomised smoothing, which perturbs
    theta per rollout, makes one job per rollout (rollout i of one stream each)."""

    theta: np.ndarray
    key: int
    start: int
    stop: int

    def __post_init__(self):
        object.__setattr__(self, "theta", as_finite_array(self.theta, "theta", ndim=(1,)))
        _check_key(self.key)
        for name in ("start", "stop"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer):
                raise ValueError(f"{name} must be an integer; got {value!r}")
        if not 0 <= self.start < self.stop:
            raise ValueError(
                f"a job needs 0 <= start < stop (a non-empty range of rollout indices); got "
                f"start={self.start}, stop={self.stop}"
            )

    @property
    def size(self) -> int:
        """Rollouts in the job."""
        return int(self.stop - self.start)

    def split(self, size: int) -> list[RolloutJob]:
        """The job as consecutive pieces of at most ``size`` rollouts."""
        return [
            RolloutJob(self.theta, self.key, a, min(a + size, self.stop))
            for a in range(self.start, self.stop, size)
        ]


@dataclass(frozen=True)
class RolloutStats:
    """What an estimator needs of n rollouts, in rollout order.

    Attributes:
        returns: (n,) returns (NaN for a rollout dropped for an unconverged step).
        used: (n,) the rollouts an estimator may average (see ``on_unconverged``).
        unconverged: (n,) unconverged solver steps of each rollout.
        horizon: H, steps per rollout.
        grad: (n, P) dJ/dtheta of each rollout (when gradients were asked for; NaN if dropped).
        score: (n, P) ``sum_t (xi_t / sigma) dpi/dtheta``, the likelihood-ratio score (when
            asked for).
        env_steps: (n,) steps that counted (H unless an episode ended: see
            :class:`~drake_abs.engine.protocols.TransitionReward`).
        warnings: (category, message) of the warnings the rollouts raised, for a runner in
            another process to raise again where the estimate is made.
    """

    returns: np.ndarray
    used: np.ndarray
    unconverged: np.ndarray
    horizon: int
    grad: np.ndarray | None = None
    score: np.ndarray | None = None
    env_steps: np.ndarray | None = None
    warnings: tuple = field(default=(), compare=False)

    @property
    def rollouts(self) -> int:
        return int(self.returns.size)

    @property
    def steps(self) -> int:
        return self.rollouts * int(self.horizon)

    @property
    def dropped(self) -> int:
        return int((~self.used).sum())

    @classmethod
    def concatenate(cls, parts: Sequence[RolloutStats]) -> RolloutStats:
        """The pieces of one job, in order, as one."""
        if not parts:
            raise ValueError("parts must hold at least one RolloutStats")
        if len(parts) == 1:
            return parts[0]

        def cat(name):
            values = [getattr(p, name) for p in parts]
            return None if values[0] is None else np.concatenate(values)

        return cls(
            cat("returns"), cat("used"), cat("unconverged"), parts[0].horizon, cat("grad"),
            cat("score"), cat("env_steps"), tuple(w for p in parts for w in p.warnings),
        )  # fmt: skip


def rollout_stats(objective, job: RolloutJob, *, gradient: bool, score: bool) -> RolloutStats:
    """Run ``job`` on ``objective`` (a :class:`~drake_abs.policy.estimators.PolicyObjective`)
    in this process: its noise from the seed tree, one batched closed-loop rollout, and the
    per-rollout returns, gradients (``gradient``) and likelihood-ratio scores (``score``)."""
    noise = rollout_noise(job.key, job.start, job.stop, objective.horizon, objective.policy.nu)
    traj = objective.rollout(job.theta, noise, gradient=gradient)
    sc = likelihood_score(objective, job.theta, traj.x, noise) if score else None
    return RolloutStats(
        returns=np.asarray(traj.returns, float), used=np.asarray(traj.used, bool),
        unconverged=(~traj.converged).sum(axis=1), horizon=int(objective.horizon),
        grad=traj.grad if gradient else None, score=sc, env_steps=traj.alive.sum(axis=1),
    )  # fmt: skip


def likelihood_score(objective, theta, x: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """``sum_t grad_theta log pi(u_t | x_t)`` per rollout (M, P): ``(xi_t / sigma) dpi/dtheta``
    along the states x (M, H + 1, nx) the rollouts visited with noise (M, H, nu)."""
    if objective.sigma <= 0:
        raise ValueError("the likelihood-ratio estimator needs exploration noise: sigma > 0")
    out = np.zeros((noise.shape[0], np.size(theta)))
    for t in range(noise.shape[1]):
        out += objective.policy.vjp(theta, x[:, t], noise[:, t] / objective.sigma)[1]
    return out


@runtime_checkable
class Runner(Protocol):
    """Runs estimators' rollout jobs: ``run(objective, jobs, gradient=, score=)`` returns one
    :class:`RolloutStats` per job, in order, each equal (to rounding) to
    ``rollout_stats(objective, job, ...)`` computed in this process."""

    def run(
        self, objective, jobs: Sequence[RolloutJob], *, gradient: bool, score: bool
    ) -> list[RolloutStats]: ...


class LocalRunner:
    """Every job in this process, one batched rollout per job (the default runner)."""

    def run(
        self, objective, jobs: Sequence[RolloutJob], *, gradient: bool, score: bool
    ) -> list[RolloutStats]:
        return [rollout_stats(objective, j, gradient=gradient, score=score) for j in jobs]

    def __repr__(self) -> str:
        return "LocalRunner()"


_default: list[Runner] = [LocalRunner()]


def default_runner() -> Runner:
    """The runner estimators use when given none (:class:`LocalRunner` unless
    :func:`use_runner` set another)."""
    return _default[-1]


class use_runner:  # noqa: N801 - used as a context manager, like a function
    """Make ``runner`` the estimators' default within a ``with`` block (or, called without
    ``with``, until its ``close()``), e.g. to send an experiment's rollouts to Ray without
    changing its code."""

    def __init__(self, runner: Runner):
        if not isinstance(runner, Runner):
            raise ValueError(
                f"runner must have run(objective, jobs, *, gradient, score); got "
                f"{type(runner).__name__}"
            )
        self.runner = runner
        _default.append(runner)

    def close(self) -> None:
        if self.runner in _default[1:]:
            _default.reverse()
            _default.remove(self.runner)  # the innermost occurrence
            _default.reverse()

    def __enter__(self) -> Runner:
        return self.runner

    def __exit__(self, *exc) -> None:
        self.close()


def reraise_warnings(stats: Sequence[RolloutStats]) -> None:
    """Raise here the warnings rollouts raised in another process (see
    :attr:`RolloutStats.warnings`)."""
    for category, message in (w for s in stats for w in s.warnings):
        warnings.warn(message, category, stacklevel=3)
