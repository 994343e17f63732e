"""Training a policy on a locomotion task (:class:`~drake_abs.tasks.locomotion.LocomotionTask`) by
any method of the registry (:mod:`drake_abs.policy.methods`), each iteration scored on the true
system: the loop of the locomotion comparison (Zhang et al. 2023, Figure 4) and of model-based
FOPG.

- A gradient method (FOPG through any smoothing, ZOPG, AoBG, PIPPS) trains a linear policy of
  the task's observation (actions in [-1, 1]) with Adam on its estimate from ``rollouts``
  rollouts of ``horizon`` steps (exploration noise ``sigma``, action units). An iteration whose
  estimate has no usable rollout (every rollout took an unconverged solver step) or is not
  finite makes no update; its samples count as spent (the whole batch), and it is counted
  (``skipped``).
- ``ars``: ARS V2-t (Mania et al. 2018) with its published settings for the same body
  (:data:`ARS_SETTINGS`), on the full state normalised by running statistics (its own policy
  class), deterministic rollouts, the same total sample budget (:mod:`drake_abs.policy.ars_v2`).
- ``mbpo``: the MBPO-style loop (:mod:`drake_abs.policy.mbpo`), ``rollouts`` real rollouts per
  iteration, the policy improved inside the learned ensemble.

After every iteration the policy is scored by :func:`evaluate`: the mean deterministic return
(no exploration noise) on the true task from given initial states. The samples counted are the
environment steps that count (fewer when the Hopper falls).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from drake_abs.contact.unconverged import UnconvergedStepError
from drake_abs.engine import rollout
from drake_abs.policy.ars_v2 import PUBLISHED_SETTINGS, NormalizedLinearPolicy, ars_v2_train
from drake_abs.policy.estimators import PolicyObjective
from drake_abs.policy.mbpo import MbpoConfig, mbpo_train
from drake_abs.policy.methods import method as registry_method
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.training import Adam
from drake_abs.tasks.locomotion import LocomotionTask

__all__ = ["ARS_SETTINGS", "LocomotionTraining", "evaluate", "train_method"]

#: ARS V2-t's published settings (Mania et al. 2018) for the gymnasium task of the same body.
ARS_SETTINGS = {"hopper": "Hopper-v1", "half_cheetah": "HalfCheetah-v1"}


@dataclass(frozen=True)
class LocomotionTraining:
    """How a method trains: per iteration ``rollouts`` rollouts of ``horizon`` steps with
    exploration noise ``sigma`` (action units, actions in [-1, 1]), ``iterations`` iterations,
    Adam's ``learning_rate``; ``alpha`` the alpha-order mix; ``contact_aware`` = (mu_max, length
    in m) of the adaptive smoothing (larger mu is more smoothing); every iterate scored over
    ``eval_horizon`` steps; ``mbpo`` the MBPO-style loop's settings."""

    iterations: int = 60
    rollouts: int = 16
    horizon: int = 100
    sigma: float = 0.1
    learning_rate: float = 0.01
    alpha: float = 0.5
    contact_aware: tuple[float, float] = (1e-2, 0.05)
    eval_horizon: int = 100
    mbpo: MbpoConfig = MbpoConfig()


def evaluate(task: LocomotionTask, theta, x0s: np.ndarray, horizon: int, policy=None) -> float:
    """Mean deterministic return (no exploration noise) over ``horizon`` steps from the states
    x0s (E, nx) of the full-state ``policy`` (default: the task's linear policy of the
    observation); an unconverged step is kept (flagged)."""
    policy = task.policy(LinearPolicy(task.n_obs, task.nu)) if policy is None else policy
    noise = np.zeros((x0s.shape[0], horizon, task.nu))
    r = rollout(task.stepper, policy, theta, x0s, noise, task.reward, sigma=0.0, gradient=False,
                on_unconverged="flag")  # fmt: skip
    return float(np.mean(r.returns))


def train_method(
    task: LocomotionTask,
    method: str,
    config: LocomotionTraining,
    seed: int,
    x_eval: np.ndarray,
    true_task: LocomotionTask | None = None,
    theta0: np.ndarray | None = None,
) -> dict:
    """One training run of ``method`` (a name of :mod:`drake_abs.policy.methods`) on ``task``
    (the method's model), seeded by ``seed``.

    Returns ``{"rows": [...], "theta": (P,), ...}``: per iteration (0 = the start) the
    cumulative ``samples`` and ``seconds`` and the ``return`` evaluated on ``true_task``
    (default: ``task``) from ``x_eval`` (E, nx); gradient methods add ``skipped`` (iterations
    without an update), ARS its own ``policy``. A gradient method starts from ``theta0``
    (default zeros)."""
    true_task = task if true_task is None else true_task
    m = registry_method(method)
    if m.estimator == "ars":
        return _train_ars(task, config, seed, x_eval, true_task)
    if m.estimator == "mbpo":
        return _train_mbpo(task, config, seed, x_eval, true_task)
    obj = task.objective(LinearPolicy(task.n_obs, task.nu), config.horizon, config.sigma)
    theta = np.zeros(obj.policy.n_params) if theta0 is None else np.array(theta0, dtype=float)
    if theta.shape != (obj.policy.n_params,):
        raise ValueError(f"theta0 must have shape ({obj.policy.n_params},); got {theta.shape}")
    optimizer = Adam(lr=config.learning_rate)
    rng = np.random.default_rng(seed)
    rows = [{"iteration": 0, "samples": 0, "seconds": 0.0,
             "return": evaluate(true_task, theta, x_eval, config.eval_horizon)}]  # fmt: skip
    samples, seconds, skipped = 0, 0.0, 0
    for k in range(config.iterations):
        start = time.perf_counter()
        try:
            est = m.estimate(obj, theta, rng, config.rollouts, alpha=config.alpha)
            if not np.all(np.isfinite(est.grad)):
                raise FloatingPointError("non-finite gradient estimate")
        except (UnconvergedStepError, FloatingPointError):
            skipped += 1
            seconds += time.perf_counter() - start
            samples += config.rollouts * config.horizon
            rows.append({"iteration": k + 1, "samples": samples, "seconds": seconds,
                         "return": rows[-1]["return"], "skipped": True})  # fmt: skip
            continue
        theta = optimizer.step(theta, est.grad)
        seconds += time.perf_counter() - start
        samples += est.env_steps
        rows.append({"iteration": k + 1, "samples": samples, "seconds": seconds,
                     "return": evaluate(true_task, theta, x_eval, config.eval_horizon),
                     "batch_return": est.value, "dropped": est.dropped,
                     "grad_norm": float(np.linalg.norm(est.grad))})  # fmt: skip
    return {"rows": rows, "theta": theta, "skipped": skipped}


def _train_ars(task, config: LocomotionTraining, seed: int, x_eval, true_task) -> dict:
    """ARS V2-t: as many iterations of 2 N rollouts as give ``iterations x rollouts x
    horizon`` samples (N its published number of directions)."""
    settings = dict(PUBLISHED_SETTINGS[ARS_SETTINGS[task.name]])
    policy = NormalizedLinearPolicy(task.nx, task.nu)
    obj = PolicyObjective(task.stepper, policy, task.reward, task.x0, config.horizon, 0.0)
    iterations = max(1, round(config.iterations * config.rollouts / (2 * settings["directions"])))
    theta0 = np.zeros(policy.n_params)
    start = evaluate(true_task, theta0, x_eval, config.eval_horizon, policy)
    rows = [{"iteration": 0, "samples": 0, "seconds": 0.0, "return": start}]
    totals = {"samples": 0, "seconds": 0.0}

    def log(j, theta, pol, row):
        totals["samples"] += row["env_steps"]
        totals["seconds"] += row["seconds"]
        score = evaluate(true_task, theta, x_eval, config.eval_horizon, pol)
        rows.append({"iteration": j + 1, **totals, "batch_return": row["return_mean"],
                     "return": score})  # fmt: skip

    run = ars_v2_train(obj, theta0, iterations=iterations, rng=np.random.default_rng(seed),
                       evaluate=False, callback=log, **settings)  # fmt: skip
    return {"rows": rows, "theta": run.theta, "policy": run.policy}


def _train_mbpo(task, config: LocomotionTraining, seed: int, x_eval, true_task) -> dict:
    """The MBPO-style loop, ``rollouts`` real rollouts per iteration on ``task``."""
    obj = task.objective(LinearPolicy(task.n_obs, task.nu), config.horizon, config.sigma)
    mbpo = replace(config.mbpo, iterations=config.iterations, real_rollouts=config.rollouts)
    theta0 = np.zeros(obj.policy.n_params)
    rows = [{"iteration": 0, "samples": 0, "seconds": 0.0,
             "return": evaluate(true_task, theta0, x_eval, config.eval_horizon)}]  # fmt: skip
    totals = {"samples": 0, "seconds": 0.0}

    def log(j, theta, row):
        totals["samples"] += row["real_steps"]
        totals["seconds"] += row["seconds"]
        score = evaluate(true_task, theta, x_eval, config.eval_horizon)
        rows.append({"iteration": j + 1, **totals, "batch_return": row["real_return"],
                     "model_error": row["model_error"], "return": score})  # fmt: skip

    run = mbpo_train(obj, theta0, mbpo, np.random.default_rng(seed), callback=log)
    return {"rows": rows, "theta": run.theta}
