"""Scoring a policy by deterministic episodes of a locomotion task, on any stepper, in the engine:
the task's reward (gymnasium v5's terms at the stepper's own time step), termination and time
limit, one episode per initial state, and their statistics.

An episode is one :func:`drake_abs.engine.rollout` of a batch of one (the policy sees one state
at a time, as a user's ``env.step`` loop does: a batched policy's matrix products round
differently, and a chaotic episode carries the last bit to visible differences). It ends where
the task terminates it (the Hopper's unhealthy state: that step's reward counts, the later ones
do not) or after ``steps`` steps. With :class:`~drake_abs.reference.mujoco_plant.MujocoStepper`
(``from_gymnasium``) and gymnasium's reset states
(:func:`drake_abs.reference.gymnasium_mujoco.reset_states`), the returns are those of
gymnasium's own ``env.step`` loop: gymnasium adds its reward's terms in another order ((forward +
survive) - control against forward - control + survive), so the returns agree to rounding
(about 1e-16 relative per step), every term to the bit.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from drake_abs._validation import as_count, as_finite_array
from drake_abs.engine import Policy, Stepper, rollout
from drake_abs.tasks.locomotion import LocomotionTask

__all__ = ["TERMS", "episode_statistics", "score_episodes"]

#: The reward's terms an episode sums (gymnasium's ``info`` names; 0 where a task has none).
TERMS = ("reward_forward", "reward_ctrl", "reward_survive")


def score_episodes(
    task: LocomotionTask,
    policy: Policy,
    theta,
    x0s,
    steps: int,
    *,
    stepper: Stepper | None = None,
    time_step: float | None = None,
) -> list[dict]:
    """One deterministic episode (no exploration noise) of ``policy`` per initial state.

    Args:
        task: the task: its reward (forward velocity over ``time_step``), termination and, by
            default, its stepper.
        policy: a policy of the full state x (e.g. ``task.policy(inner)``, a saved policy's
            ``policy``), with parameters ``theta``.
        x0s: (E, nx) initial states.
        steps: the most steps of an episode (the time limit), >= 1.
        stepper: what steps the state (default ``task.stepper``; e.g. a MuJoCo stepper, whose
            x = (qpos, qvel, act) is the task's x when the model has no actuator state).
        time_step: seconds per step (default: ``stepper.time_step`` if it has one, else
            ``task.dt``).

    Returns:
        Per episode: ``return``, ``length`` (steps that counted) and ``seconds``,
        ``forward_distance`` (m) and ``forward_velocity`` (m/s), the sums of the reward's
        :data:`TERMS`, ``terminated``, ``unconverged_steps`` (contact solves that did not
        converge), ``action_rms`` and ``saturated_fraction`` (action entries beyond [-1, 1]).
    """
    steps = as_count(steps, "steps", minimum=1)
    x0s = as_finite_array(x0s, "x0s", ndim=(2,))
    stepper = task.stepper if stepper is None else stepper
    if time_step is None:
        time_step = getattr(stepper, "time_step", task.dt)
    if not (np.isfinite(time_step) and time_step > 0):
        raise ValueError(f"time_step must be a finite number of seconds > 0; got {time_step!r}")
    reward = replace(task.reward, dt=float(time_step))
    noise = np.zeros((1, steps, task.nu))
    out = []
    for x0 in x0s:
        r = rollout(stepper, policy, theta, x0[None], noise, reward, sigma=0.0, gradient=False,
                    on_unconverged="flag")  # fmt: skip
        n = int(r.alive[0].sum())
        x, u = r.x[0, : n + 1], r.u[0, :n]
        terms = reward.terms(x[:-1], u, x[1:])
        distance = float(x[-1, 0] - x[0, 0])
        seconds = n * float(time_step)
        out.append({
            "return": float(r.returns[0]), "length": n, "seconds": seconds,
            "forward_distance": distance, "forward_velocity": distance / seconds,
            "terminated": bool(reward.terminated(x[-1:])[0]),
            "unconverged_steps": int((~r.converged[0, :n]).sum()),
            # summed in time order, as an episode's loop adds them
            **{key: float(np.cumsum(terms[key])[-1]) if key in terms else 0.0 for key in TERMS},
            "action_rms": float(np.sqrt(np.mean(np.square(u)))),
            "saturated_fraction": float(np.mean(np.abs(u) > 1.0)),
        })  # fmt: skip
    return out


def episode_statistics(episodes: list[dict]) -> dict:
    """Mean and std (over the episodes of :func:`score_episodes`) of the return, length (steps
    and s), forward distance (m) and velocity (m/s), the reward's terms and the actions' RMS and
    saturated share; the per-episode returns and lengths; the fraction terminated; the steps
    whose contact solve did not converge."""
    if not episodes:
        raise ValueError("episodes must hold at least one episode")
    out: dict = {"episodes": len(episodes)}
    for key in ("return", "length", "seconds", "forward_distance", "forward_velocity", *TERMS,
                "action_rms", "saturated_fraction"):  # fmt: skip
        values = np.array([e[key] for e in episodes], dtype=float)
        out[f"{key}_mean"] = float(values.mean())
        out[f"{key}_std"] = float(values.std())
    out["returns"] = [float(e["return"]) for e in episodes]
    out["lengths"] = [int(e["length"]) for e in episodes]
    out["terminated_fraction"] = float(np.mean([e["terminated"] for e in episodes]))
    out["unconverged_steps"] = int(sum(e["unconverged_steps"] for e in episodes))
    return out
