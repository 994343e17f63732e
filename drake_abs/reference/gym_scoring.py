"""Scoring a policy where the community scores it: MuJoCo's own gymnasium environment at its
defaults (``gymnasium.make(env_id)``: v5's model, frame skip, reward, termination and
1000-step time limit), one episode per reset seed, and the two floors any policy should clear.

An episode: ``obs, _ = env.reset(seed=s)``, then ``a = clip(act(obs), low, high)`` (the action
space's bounds: users clip, and gymnasium charges the control cost on the action it is given,
before MuJoCo clamps ``ctrl``), ``env.step(a)``, until the environment terminates or truncates
it (its ``TimeLimit``) or ``max_steps`` steps have run. Its return is the sum of gymnasium's
rewards.

Floors (:func:`floors`), over the same reset seeds:

- ``zero``: every action 0;
- ``random``: every action uniform in the action space, drawn from
  ``numpy.random.default_rng(s)`` for the episode of reset seed s (``rng.uniform(low, high)``
  once per step; independent of gymnasium's own generator).

Measured here (gymnasium 1.4.0, mujoco 4.0.0, reset seeds 0 .. 9, 1000 steps): see
``docs/policy_files.md``.

Needs gymnasium and MuJoCo (``pip install 'drake-abs[mujoco]'``), imported when called.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

__all__ = ["floors", "reset_observations", "score_policy"]


def _seeds(seeds: Iterable[int]) -> list[int]:
    seeds = list(seeds)
    if not seeds or any(
        isinstance(s, bool) or not isinstance(s, int | np.integer) or s < 0 for s in seeds
    ):
        raise ValueError(f"seeds must be whole numbers >= 0, at least one; got {seeds!r}")
    return [int(s) for s in seeds]


def _max_steps(max_steps) -> int:
    if isinstance(max_steps, bool) or not isinstance(max_steps, int | np.integer) or max_steps < 1:
        raise ValueError(f"max_steps must be a whole number >= 1; got {max_steps!r}")
    return int(max_steps)


def _versions() -> dict[str, str]:
    import gymnasium
    import mujoco

    return {"gymnasium": gymnasium.__version__, "mujoco": mujoco.__version__}


def _run(env_id: str, actor: Callable[[int], Callable], seeds, max_steps) -> dict:
    """Episodes of ``actor(seed)`` (a function obs -> action) from each reset seed."""
    import gymnasium

    seeds, max_steps = _seeds(seeds), _max_steps(max_steps)
    if not isinstance(env_id, str) or not env_id:
        raise ValueError(f"env_id must be a gymnasium id such as 'Hopper-v5'; got {env_id!r}")
    env = gymnasium.make(env_id)
    try:
        low = np.asarray(env.action_space.low, dtype=float)
        high = np.asarray(env.action_space.high, dtype=float)
        returns, lengths, terminated = [], [], []
        for seed in seeds:
            act = actor(seed)
            obs, _ = env.reset(seed=seed)
            total, steps, ended = 0.0, 0, False
            while steps < max_steps:
                a = np.asarray(act(obs), dtype=float)
                if a.shape != low.shape or not np.all(np.isfinite(a)):
                    raise ValueError(
                        f"act must return a finite action of shape {low.shape} ({env_id}'s "
                        f"action space); got shape {a.shape} at step {steps} of seed {seed}"
                    )
                obs, reward, ended, truncated, _ = env.step(np.clip(a, low, high))
                total += float(reward)
                steps += 1
                if ended or truncated:
                    break
            returns.append(total)
            lengths.append(steps)
            terminated.append(bool(ended))
        limit = env.spec.max_episode_steps if env.spec is not None else None
    finally:
        env.close()
    r = np.array(returns)
    return {
        "env_id": env_id, "seeds": seeds, "max_steps": max_steps, "time_limit": limit,
        "returns": returns, "lengths": lengths, "terminated": terminated,
        "mean": float(r.mean()), "std": float(r.std()), "min": float(r.min()),
        "max": float(r.max()), "length_mean": float(np.mean(lengths)), **_versions(),
    }  # fmt: skip


def score_policy(
    act: Callable[[np.ndarray], np.ndarray],
    env_id: str,
    *,
    seeds: Iterable[int] = range(10),
    max_steps: int = 1000,
) -> dict:
    """Score ``act`` in MuJoCo's own ``gymnasium.make(env_id)`` (module docstring).

    Args:
        act: the policy, observation (n_obs,) -> action (nu,) (e.g. a
            :class:`~drake_abs.policy.policy_files.PolicyFile`'s ``act``); its action is
            clipped to the action space.
        env_id: the gymnasium id, e.g. ``"Hopper-v5"``.
        seeds: the reset seeds, one episode each (default 0 .. 9).
        max_steps: the most steps of an episode (the environment's own time limit, 1000 for
            the v5 locomotion tasks, ends it earlier if smaller); below 1000 only for tests.

    Returns:
        ``env_id``, ``seeds``, ``max_steps``, ``time_limit`` (the environment's), per episode
        ``returns``, ``lengths`` (steps) and ``terminated``; ``mean``, ``std`` (population, over
        the episodes), ``min``, ``max`` of the returns, ``length_mean``; the ``gymnasium`` and
        ``mujoco`` versions.
    """
    if not callable(act):
        raise ValueError(f"act must be a function observation -> action; got {act!r}")
    return _run(env_id, lambda seed: act, seeds, max_steps)


def floors(env_id: str, seeds: Iterable[int] = range(10), max_steps: int = 1000) -> dict:
    """The zero-action and uniform-random-action scores (:func:`score_policy`'s dict each) in
    ``gymnasium.make(env_id)`` over the reset ``seeds``: ``{"zero": ..., "random": ...}``; the
    random actions of the episode of seed s come from ``numpy.random.default_rng(s)``."""
    import gymnasium

    env = gymnasium.make(env_id)
    low = np.asarray(env.action_space.low, dtype=float)
    high = np.asarray(env.action_space.high, dtype=float)
    env.close()

    def zero(seed):
        return lambda obs: np.zeros(low.shape)

    def uniform(seed):
        rng = np.random.default_rng(seed)
        return lambda obs: rng.uniform(low, high)

    return {
        "zero": _run(env_id, zero, seeds, max_steps),
        "random": _run(env_id, uniform, seeds, max_steps),
    }


def reset_observations(env_id: str, seeds: Iterable[int]) -> np.ndarray:
    """(S, n_obs) the observations ``gymnasium.make(env_id).reset(seed=s)`` returns, one row
    per seed (to check that another model of the task observes the same thing)."""
    import gymnasium

    seeds = _seeds(seeds)
    env = gymnasium.make(env_id)
    try:
        return np.array([np.asarray(env.reset(seed=s)[0], dtype=float) for s in seeds])
    finally:
        env.close()
