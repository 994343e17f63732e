"""Complementarity-model-based FOPG (Zhang et al. 2023, Algorithm 2) in closed loop with MuJoCo:
learn our model's parameters from MuJoCo's Hopper, train a policy with FOPG-ABS in the learned
model, run it in MuJoCo, add what it saw to the data, and repeat.

Three arms train the same linear policy of gymnasium's observation with the same FOPG-ABS
settings and the same number of policy iterations, and are evaluated in MuJoCo's own
``Hopper-v5`` (frame skip chosen so that one MuJoCo step is one step of our scene):

- ``learned`` (Algorithm 2): the model's parameters theta (ground height, one friction
  coefficient, the masses, the damping of the damped joints) start off the model file's
  (seeded: the ground ``ground_offset`` m up, the others scaled within
  ``1 +- perturbation``). Round 0 collects ``initial_episodes`` MuJoCo episodes under random
  inputs. Each round then (1) fits theta to
  all the data so far (``fit``: the violation-implicit loss by L-BFGS-B, or random search on
  eq. 6.1 as in the paper), warm-started from the last round's; (2) runs
  ``policy_iterations`` FOPG-ABS iterations in the learned model, continuing from the last
  round's policy; (3) runs that policy with exploration noise in MuJoCo for
  ``episodes_per_round`` episodes, whose transitions join the data;
- ``file``: the same policy iterations in the model with the file's parameters (what a user
  with the right model gets);
- ``start``: the same in the model with the starting (wrong) parameters and no learning.

After every round each arm's deterministic policy is evaluated in MuJoCo (``eval_episodes``
episodes from gymnasium's resets, gymnasium's reward and termination, ``eval_steps`` steps) and
on our plant with the file's parameters. Outputs in ``out``: ``summary.json``,
``rounds.csv``, ``closed_loop.png``, ``policies/`` (the final policies, npz + json).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from drake_abs.contact.smoothing import ContactAware
from drake_abs.engine import open_loop, rollout
from drake_abs.experiments import outputs
from drake_abs.learning.scene_fits import FITS, fit_parameters, learned_names, perturbed_start
from drake_abs.learning.scene_losses import learned_values, stepper_at
from drake_abs.learning.transitions import Transitions
from drake_abs.policy.controls import TimeVaryingController, episode_seed, uniform_inputs
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.saving import save_policy
from drake_abs.reference.gymnasium_mujoco import reset_states, same_period_frame_skip
from drake_abs.tasks.episodes import episode_statistics, score_episodes
from drake_abs.tasks.locomotion import TASKS, locomotion_task
from drake_abs.tasks.locomotion_training import LocomotionTraining, train_method
from drake_abs.tasks.locomotion_training import evaluate as our_return

NAME = "model-based-fopg"
ARMS = ("learned", "file", "start")


@dataclass(frozen=True)
class Config:
    """Sizes. ``contact_aware`` is (mu_max, length m) of the adaptive smoothing the policy is
    trained through (larger mu: smoother); ``eps`` the violation loss's relaxation."""

    task: str = "hopper"
    rounds: int = 4
    initial_episodes: int = 4
    episodes_per_round: int = 4
    steps: int = 100
    policy_iterations: int = 15
    rollouts: int = 16
    horizon: int = 100
    sigma: float = 0.1
    learning_rate: float = 0.01
    contact_aware: tuple[float, float] = (1e-2, 0.05)
    fit: str = "violation_implicit"
    eps: float = 1e-3
    fit_iterations: int = 20
    search_directions: int = 4
    max_transitions: int = 800
    ground_offset: float = 0.02
    perturbation: float = 0.3
    eval_episodes: int = 4
    eval_steps: int = 200
    seed: int = 0

    @classmethod
    def test_size(cls) -> Config:
        return cls(rounds=1, initial_episodes=1, episodes_per_round=1, steps=10,
                   policy_iterations=1, rollouts=2, horizon=6, fit_iterations=2,
                   max_transitions=20, eval_episodes=1, eval_steps=10)  # fmt: skip

    def check(self) -> None:
        if self.task not in ("hopper", "half_cheetah"):
            raise ValueError(f"task must be 'hopper' or 'half_cheetah'; got {self.task!r}")
        if self.fit not in FITS:
            raise ValueError(f"fit must be one of {FITS}; got {self.fit!r}")
        for name in ("rounds", "initial_episodes", "steps", "policy_iterations", "rollouts",
                     "horizon", "fit_iterations", "eval_episodes", "eval_steps"):  # fmt: skip
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1; got {getattr(self, name)!r}")


def noisy_feedback(task, inner, theta, sigma: float, effort: np.ndarray, seeds, steps: int):
    """The task's policy of the observation with Gaussian exploration noise ``sigma`` (action
    units), as torques: ``u_t = clip(gears (inner(obs(x_t)) + sigma xi_t), -effort, effort)``,
    one row per episode, its noise xi (steps, nu) drawn by ``default_rng(seed)`` of the
    episode's seed: a :class:`~drake_abs.policy.controls.TimeVaryingController`. Each row is
    evaluated by itself (a batched matrix product rounds otherwise than one row's)."""
    policy, gears = task.policy(inner), np.asarray(task.stepper.scale, float)
    noise = np.stack([np.random.default_rng(s).standard_normal((steps, task.nu)) for s in seeds])

    def control(t: int, x: np.ndarray) -> np.ndarray:
        a = np.concatenate([policy.act(theta, x[m : m + 1]) for m in range(x.shape[0])])
        return np.clip(gears * (a + sigma * noise[:, t]), -effort, effort)

    return TimeVaryingController(control, task.nx, task.nu)


def mujoco_episodes(source, task, episodes: int, steps: int, seed: int, controls):
    """``episodes`` MuJoCo episodes (``source``) of at most ``steps`` steps as transitions:
    episode e from gymnasium's reset of the seed ``episode_seed(seed, e)``, under
    ``controls(seeds)``: inputs (episodes, steps, nu) or a time-varying policy, ending where the
    task terminates (the Hopper falls)."""
    seeds = [episode_seed(seed, e) for e in range(episodes)]
    x0, made = reset_states(task.env_id, seeds), controls(seeds)
    if isinstance(made, np.ndarray):
        run = open_loop(source.stepper, x0, made, jacobians=False)
    else:
        run = rollout(source.stepper, made, np.zeros(0), x0, np.zeros((episodes, steps, task.nu)),
                      sigma=0.0, gradient=False, on_unconverged="flag")  # fmt: skip
    return Transitions.from_trajectory(run, source=source.name, time_step=source.time_step,
                                       terminated=task.reward.terminated)  # fmt: skip


def with_model(task, names, theta):
    """The locomotion task with its stepper's learned parameters ``names`` set to ``theta``."""
    return task.with_plant(stepper_at(task.plant, names, theta))


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    from drake_abs.multibody import build_scene_model
    from drake_abs.reference.mujoco_plant import MujocoStepper
    from drake_abs.reference.scene_sources import mujoco_source

    config = Config() if config is None else config
    config.check()
    folder = outputs.results_dir(NAME, out)
    start_time = time.perf_counter()
    scene = TASKS[config.task].scene
    env_id = TASKS[config.task].env_id
    smoothing = ContactAware(*config.contact_aware)
    base = locomotion_task(config.task, smoothing=smoothing)
    true_task = locomotion_task(config.task)  # exact contact, the file's parameters
    model = base.plant
    names = learned_names(model)
    truth = learned_values(model, names)
    theta_start, scale, lo, hi = perturbed_start(
        names, truth, ground_offset=config.ground_offset, perturbation=config.perturbation,
        rng=np.random.default_rng(config.seed),
    )  # fmt: skip

    frame = same_period_frame_skip(env_id, base.dt)
    mujoco = MujocoStepper.from_gymnasium(env_id, frame_skip=frame["frame_skip"])
    inner = LinearPolicy(base.n_obs, base.nu)
    eval_seeds = [10_000 + i for i in range(config.eval_episodes)]
    x_mujoco = reset_states(env_id, eval_seeds)
    # our plant (exact contact, the file's parameters) from gymnasium's reset noise
    x_ours = true_task.initial_states(np.random.default_rng([config.seed, 3]), config.eval_episodes)

    def evaluate(theta_pi) -> dict:
        policy = true_task.policy(inner)
        episodes = score_episodes(true_task, policy, theta_pi, x_mujoco, config.eval_steps,
                                  stepper=mujoco)  # fmt: skip
        st = episode_statistics(episodes)
        ours = our_return(true_task, theta_pi, x_ours, config.eval_steps)
        return {"mujoco_return": st["return_mean"], "mujoco_return_std": st["return_std"],
                "mujoco_length": st["length_mean"], "our_return": ours}  # fmt: skip

    # round 0: random inputs in MuJoCo
    source, effort = mujoco_source(build_scene_model(scene)), model.effort

    def random_inputs(seeds):
        return np.stack([uniform_inputs(config.steps, -effort, effort, seed=[config.seed, s])
                         for s in seeds])  # fmt: skip

    data = mujoco_episodes(source, base, config.initial_episodes, config.steps, config.seed,
                           random_inputs)  # fmt: skip
    loc = LocomotionTraining(
        iterations=config.policy_iterations, rollouts=config.rollouts, horizon=config.horizon,
        sigma=config.sigma, learning_rate=config.learning_rate,
        contact_aware=config.contact_aware, eval_horizon=1,
    )  # fmt: skip
    x_eval = base.initial_states(np.random.default_rng([config.seed, 2]), 1)
    tasks = {"file": base, "start": with_model(base, names, theta_start)}
    theta_pi = {arm: np.zeros(inner.n_params) for arm in ARMS}
    theta_model = theta_start.copy()
    rows, fits = [], []

    def record(k: int, seconds: dict | None = None) -> None:
        for arm in ARMS:
            rows.append({"round": k, "arm": arm, "transitions": len(data),
                         **({"train_seconds": seconds[arm]} if seconds else {}),
                         **evaluate(theta_pi[arm])})  # fmt: skip

    record(0)
    for k in outputs.progress(range(1, config.rounds + 1), desc=NAME):
        # (1) the model update on all data so far, from the last round's theta
        t0 = time.perf_counter()
        result = fit_parameters(
            model, data.x, data.u, data.x_next, config.fit, names, theta_model, scale, lo, hi,
            eps=config.eps, search_iterations=config.fit_iterations,
            search_directions=config.search_directions, gradient_iterations=config.fit_iterations,
            max_transitions=config.max_transitions, seed=config.seed + k,
        )  # fmt: skip
        theta_model = result.theta
        fits.append({"round": k, "theta": theta_model.tolist(), "loss": result.loss,
                     "seconds": time.perf_counter() - t0,
                     "unconverged_evaluations": result.unconverged_evaluations})  # fmt: skip
        tasks["learned"] = with_model(base, names, theta_model)
        # (2) the policy update in each arm's model
        seconds = {}
        for arm in ARMS:
            t0 = time.perf_counter()
            run_k = train_method(tasks[arm], "fopg_abs", loc, config.seed * 100 + k, x_eval,
                                 theta0=theta_pi[arm])  # fmt: skip
            theta_pi[arm] = run_k["theta"]
            seconds[arm] = time.perf_counter() - t0
        # (3) the learned arm's policy, with exploration noise, in MuJoCo: new data
        theta = theta_pi["learned"]

        def explore(seeds, theta=theta):
            return noisy_feedback(base, inner, theta, config.sigma, effort, seeds, config.steps)

        new = mujoco_episodes(source, base, config.episodes_per_round, config.steps,
                              config.seed * 100 + k, explore)  # fmt: skip
        data = data.concatenate(new)
        record(k, seconds)
    saved = {arm: str(save_policy(folder / "policies" / f"{config.task}_{arm}",
                                  base.policy(inner), theta_pi[arm], task=config.task,
                                  config={"arm": arm, **asdict(config)})["json"])
             for arm in ARMS}  # fmt: skip
    keys = ["round", "arm", "transitions", "mujoco_return", "mujoco_return_std",
            "mujoco_length", "our_return", "train_seconds"]  # fmt: skip
    files = {"rounds": outputs.write_csv(folder / "rounds.csv",
                                         [[r.get(k, "") for k in keys] for r in rows], keys),
             "plot": _plot(folder / "closed_loop.png", rows, config)}  # fmt: skip
    summary = {
        "experiment": NAME, "config": asdict(config), "names": names, "file": truth.tolist(),
        "start": theta_start.tolist(), "learned": theta_model.tolist(), "fits": fits,
        "rows": rows, "frame": frame, "policies": saved,
        "seconds": time.perf_counter() - start_time, "files": outputs.file_list(files),
    }  # fmt: skip
    path = outputs.write_json(folder / "summary.json", summary, indent=1)
    summary["files"]["summary"] = str(path)
    return summary


def _plot(path: Path, rows: list[dict], config: Config) -> Path:
    fig, ax = outputs.pyplot().subplots(figsize=(5, 3.4))
    for arm in ARMS:
        mine = [r for r in rows if r["arm"] == arm]
        ax.plot([r["round"] for r in mine], [r["mujoco_return"] for r in mine], "o-", label=arm)
    ax.set(xlabel="round (model fit + policy iterations + MuJoCo episodes)",
           ylabel=f"MuJoCo return ({config.eval_steps} steps)")  # fmt: skip
    ax.set_title(f"Algorithm 2 in closed loop: {config.task}", fontsize=9)
    ax.legend(fontsize=8)
    return outputs.save_figure(fig, path, dpi=110)


def report(summary: dict) -> str:
    lines = [f"# Model-based FOPG in closed loop with MuJoCo ({summary['seconds']:.0f} s)", ""]
    lines += outputs.markdown_table(["parameter", "file", "start", "learned"], [
        [name, *(f"{summary[k][j]:.4g}" for k in ("file", "start", "learned"))]
        for j, name in enumerate(summary["names"])])  # fmt: skip
    lines += [""] + outputs.markdown_table(
        ["round", "arm", "MuJoCo return", "our plant's return"],
        [[r["round"], r["arm"], f"{r['mujoco_return']:.1f} ± {r['mujoco_return_std']:.1f}",
          f"{r['our_return']:.1f}"] for r in summary["rows"]])  # fmt: skip
    return "\n".join(lines)
