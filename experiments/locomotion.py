"""Learning locomotion through contact: return against samples and wall time on gymnasium's Hopper
and HalfCheetah on our plant (Zhang et al. 2023, Figure 4, measured there in Dojo).

Every method trains the same policy class (linear in gymnasium's v5 observation, actions in
[-1, 1], :mod:`drake_abs.tasks.locomotion`) on the same task, from the same initial parameters
(zeros), with the same sample budget per iteration (``rollouts`` rollouts of ``horizon`` steps;
the samples counted are the environment steps that count, fewer when the Hopper falls), for
``iterations`` iterations and every seed of ``seeds``:

- ``fopg_abs``: first-order policy gradient (Zhang et al. 2023, eq. 4.1) through contact-aware
  adaptive barrier smoothing (ours);
- ``fopg_exact``: the same through exact (hard) contact;
- ``fopg_bs_1e-10`` and ``fopg_bs_1e-2``: the same with a fixed central-path value mu;
- ``zopg``: the likelihood-ratio (zeroth-order) gradient with a leave-one-out baseline;
- ``aobg``: the alpha-order gradient (Suh et al. 2022), ``alpha g_FO + (1 - alpha) g_ZO`` from
  the same rollouts with a fixed ``alpha`` (Suh et al. choose alpha per step from the two
  estimates' variances; the fixed alpha is a simplification, stated here);
- ``pipps``: PIPPS total propagation (Parmas et al. 2018) through exact contact,
  :mod:`drake_abs.policy.pipps`;
- ``ars``: ARS V2-t (Mania et al. 2018) with its published settings for the same body, on the
  full state normalised by running statistics (its own policy class), deterministic rollouts,
  the same total sample budget; :mod:`drake_abs.policy.ars_v2`;
- ``mbpo``: an MBPO-style loop (Janner et al. 2019, without SAC: the policy is improved by
  first-order gradients inside a learned ensemble of neural-network models),
  :mod:`drake_abs.policy.mbpo`.

Each baseline module states where it follows its paper and where it departs.

The gradient methods step with Adam (``learning_rate``). An iteration whose estimate has no
usable rollout (every rollout took an unconverged solver step) or is not finite makes no update;
its samples count as spent, and the summary counts such iterations (``skipped_iterations``).
After every iteration the policy is evaluated on the true system (exact contact, whatever model
the method trains on), deterministically (no exploration noise), from ``eval_episodes`` of
gymnasium's reset states (drawn once per task with ``eval_seed``) over ``eval_horizon`` steps;
the curves are that return against cumulative training samples and against wall time, mean and
spread (min-max) over the seeds. Every final policy is saved in ``policies/`` (npz + json) and
can be replayed (``drake-abs replay``).

Outputs in ``out``: ``figure4_<task>.png`` (return against samples and against seconds),
``curves.csv`` (every evaluation), ``summary.json``, ``policies/``.
"""

from __future__ import annotations

import csv
import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from drake_abs.contact.smoothing import ContactAware, Exact, Fixed, SmoothingPolicy
from drake_abs.contact.unconverged import UnconvergedStepError
from drake_abs.experiments._common import file_list, progress, results_dir
from drake_abs.policy.ars_v2 import PUBLISHED_SETTINGS, NormalizedLinearPolicy, ars_v2_train
from drake_abs.policy.estimators import PolicyObjective, alpha_order, first_order, zeroth_order
from drake_abs.policy.mbpo import MbpoConfig, mbpo_train
from drake_abs.policy.pipps import pipps
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.training import Adam

NAME = "locomotion"
TASKS = ("hopper", "half_cheetah")
GRADIENT_METHODS = ("fopg_abs", "fopg_exact", "fopg_bs_1e-10", "fopg_bs_1e-2", "zopg", "aobg",
                    "pipps")  # fmt: skip
METHODS = (*GRADIENT_METHODS, "ars", "mbpo")
#: ARS V2-t's published settings (Mania et al. 2018) for the gymnasium task of the same body.
ARS_SETTINGS = {"hopper": "Hopper-v1", "half_cheetah": "HalfCheetah-v1"}


@dataclass(frozen=True)
class Config:
    """Sizes. Per iteration every method uses ``rollouts`` rollouts of ``horizon`` steps;
    ``sigma`` is the exploration noise (action units, actions in [-1, 1]); ``contact_aware`` is
    (mu_max, length in m) of the adaptive design."""

    tasks: tuple[str, ...] = TASKS
    methods: tuple[str, ...] = METHODS
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    iterations: int = 60
    rollouts: int = 16
    horizon: int = 100
    sigma: float = 0.1
    learning_rate: float = 0.01
    alpha: float = 0.5
    contact_aware: tuple[float, float] = (1e-2, 0.05)
    eval_episodes: int = 4
    eval_horizon: int = 100
    eval_seed: int = 12345
    mbpo: MbpoConfig = MbpoConfig()

    @classmethod
    def test_size(cls) -> Config:
        small = MbpoConfig(ensemble_size=2, hidden=(8,), model_epochs=2, branches=8,
                           policy_updates=2, rollout_length=3)  # fmt: skip
        return cls(seeds=(0, 1), iterations=3, rollouts=4, horizon=8, eval_episodes=2,
                   eval_horizon=8, mbpo=small)  # fmt: skip


def smoothing_of(method: str, config: Config) -> SmoothingPolicy:
    """The contact smoothing a method's model uses (larger mu: more smoothing)."""
    if method == "fopg_abs":
        return ContactAware(*config.contact_aware)
    if method.startswith("fopg_bs_"):
        return Fixed(float(method.removeprefix("fopg_bs_")))
    if method in ("zopg", "aobg", "fopg_exact", "pipps", "ars", "mbpo"):
        return Exact()  # the baselines' models (and MBPO's and ARS's real system): hard contact
    raise ValueError(f"unknown method {method!r}; known: {METHODS}")


def _estimator(method: str, config: Config) -> Callable:
    M = config.rollouts
    if method.startswith("fopg"):
        return lambda obj, th, rng: first_order(obj, th, rng, M)
    if method == "zopg":
        return lambda obj, th, rng: zeroth_order(obj, th, rng, M)
    if method == "aobg":
        return lambda obj, th, rng: alpha_order(obj, th, rng, M, config.alpha)
    if method == "pipps":
        return lambda obj, th, rng: pipps(obj, th, rng, M)
    raise ValueError(f"unknown gradient method {method!r}; known: {GRADIENT_METHODS}")


def evaluate(task, theta, x0s: np.ndarray, horizon: int, policy=None) -> float:
    """Mean deterministic return (no exploration noise) from the states x0s (E, nx) of the
    full-state ``policy`` (default: the task's linear policy of the observation)."""
    from drake_abs.engine import rollout

    policy = task.policy(LinearPolicy(task.n_obs, task.nu)) if policy is None else policy
    noise = np.zeros((x0s.shape[0], horizon, task.nu))
    r = rollout(task.stepper, policy, theta, x0s, noise, task.reward, sigma=0.0, gradient=False,
                on_unconverged="flag")  # fmt: skip
    return float(np.mean(r.returns))


def train_method(task, method: str, config: Config, seed: int, x_eval: np.ndarray,
                 true_task=None, theta0: np.ndarray | None = None) -> dict:  # fmt: skip
    """One training run on ``task`` (the method's model): per-iteration samples, seconds and the
    return evaluated on ``true_task`` (default: ``task``); the final theta. A gradient method
    starts from ``theta0`` (default zeros)."""
    true_task = task if true_task is None else true_task
    if method == "ars":
        return _train_ars(task, config, seed, x_eval, true_task)
    if method == "mbpo":
        return _train_mbpo(task, config, seed, x_eval, true_task)
    inner = LinearPolicy(task.n_obs, task.nu)
    obj = task.objective(inner, config.horizon, config.sigma)
    theta = np.zeros(obj.policy.n_params) if theta0 is None else np.array(theta0, dtype=float)
    if theta.shape != (obj.policy.n_params,):
        raise ValueError(f"theta0 must have shape ({obj.policy.n_params},); got {theta.shape}")
    estimator = _estimator(method, config)
    optimizer = Adam(lr=config.learning_rate)
    rng = np.random.default_rng(seed)
    rows = [{"iteration": 0, "samples": 0, "seconds": 0.0,
             "return": evaluate(true_task, theta, x_eval, config.eval_horizon)}]  # fmt: skip
    samples, seconds = 0, 0.0
    skipped = 0
    for k in range(config.iterations):
        start = time.perf_counter()
        try:
            est = estimator(obj, theta, rng)
            if not np.all(np.isfinite(est.grad)):
                raise FloatingPointError("non-finite gradient estimate")
        except (UnconvergedStepError, FloatingPointError):
            # no usable rollout (every one took an unconverged step) or a non-finite estimate:
            # the iteration's samples are spent (counted as the whole batch), theta is kept
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


def _train_ars(task, config: Config, seed: int, x_eval, true_task) -> dict:
    """ARS V2-t with its published settings for this body, on the full state normalised by its
    running statistics (ARS's own policy class; the other methods act on gymnasium's
    observation, which is the state without the forward position), deterministic rollouts
    (ARS's are), and the others' sample budget: as many iterations as give ``iterations x
    rollouts x horizon`` samples at 2 N rollouts per iteration."""
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

    run_ = ars_v2_train(obj, theta0, iterations=iterations, rng=np.random.default_rng(seed),
                        evaluate=False, callback=log, **settings)  # fmt: skip
    return {"rows": rows, "theta": run_.theta, "policy": run_.policy}


def _train_mbpo(task, config: Config, seed: int, x_eval, true_task) -> dict:
    """The MBPO-style loop (:mod:`drake_abs.policy.mbpo`): ``rollouts`` real rollouts per
    iteration on the true system, the policy improved inside the learned ensemble."""
    from dataclasses import replace

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

    run_ = mbpo_train(obj, theta0, mbpo, np.random.default_rng(seed), callback=log)
    return {"rows": rows, "theta": run_.theta}


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Train every method on every task for every seed; write the figures, the curves and
    summary.json to ``out`` (default results/locomotion)."""
    from drake_abs.tasks.locomotion import locomotion_task

    config = config or Config()
    for name in config.tasks:
        if name not in TASKS:
            raise ValueError(f"tasks must be among {TASKS}; got {name!r}")
    for method in config.methods:
        smoothing_of(method, config)  # unknown methods refused before anything runs
    out = results_dir(NAME, out)
    (out / "policies").mkdir(exist_ok=True)
    start = time.perf_counter()
    bar = progress(total=len(config.tasks) * len(config.methods) * len(config.seeds),
                   desc=f"{NAME}: runs")  # fmt: skip
    results: dict = {}
    csv_rows = []
    for name in config.tasks:
        results[name] = {}
        true_task = locomotion_task(name, smoothing=Exact())  # what every policy is scored on
        x_eval = true_task.initial_states(np.random.default_rng(config.eval_seed),
                                          config.eval_episodes)  # fmt: skip
        for method in config.methods:
            task = locomotion_task(name, smoothing=smoothing_of(method, config))
            runs, skipped = [], []
            for seed in config.seeds:
                run_ = train_method(task, method, config, seed, x_eval, true_task)
                runs.append(run_["rows"])
                skipped.append(run_.get("skipped", 0))
                _save(
                    out / "policies" / f"{name}_{method}_seed{seed}",
                    task,
                    run_["theta"],
                    {"task": name, "method": method, "seed": seed, **asdict(config)},
                    run_.get("policy"),  # ARS's own policy class; the others: task.policy
                )
                csv_rows += [{"task": name, "method": method, "seed": seed, **r}
                             for r in run_["rows"]]  # fmt: skip
                bar.set_postfix_str(f"{name} {method} seed {seed}: "
                                    f"{run_['rows'][-1]['return']:.3g}")  # fmt: skip
                bar.update()
            results[name][method] = _curve(runs) | {"skipped_iterations": skipped}
    bar.close()
    files = {"summary": out / "summary.json", "curves": out / "curves.csv"}
    for name in config.tasks:
        files[f"figure4_{name}"] = _plot(name, results[name], out / f"figure4_{name}.png")
    with (out / "curves.csv").open("w", newline="") as f:
        keys = list(dict.fromkeys(k for r in csv_rows for k in r))
        writer = csv.DictWriter(f, fieldnames=keys)
        writer.writeheader()
        writer.writerows(csv_rows)
    summary = {"config": asdict(config), "tasks": results,
               "seconds": time.perf_counter() - start, "folder": str(out)}  # fmt: skip
    summary["files"] = file_list(files) | {"policies": str((out / "policies").resolve())}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def _save(stem: Path, task, theta: np.ndarray, config: dict, policy=None) -> None:
    """Save a final policy (npz + json, :func:`drake_abs.policy.saving.save_policy`): the task's
    linear policy of the observation, or ``policy`` (ARS's normalised linear policy of the
    state, with its normaliser)."""
    from drake_abs.policy.saving import save_policy

    policy = task.policy(LinearPolicy(task.n_obs, task.nu)) if policy is None else policy
    save_policy(stem, policy, theta, task=task.name, config=config)


def _curve(runs: list[list[dict]]) -> dict:
    """Mean, min and max over seeds of the evaluated return per iteration, with the mean
    cumulative samples and seconds."""
    R = np.array([[r["return"] for r in rows] for rows in runs])
    S = np.array([[r["samples"] for r in rows] for rows in runs], float)
    T = np.array([[r["seconds"] for r in rows] for rows in runs])
    return {
        "return_mean": R.mean(axis=0).tolist(), "return_min": R.min(axis=0).tolist(),
        "return_max": R.max(axis=0).tolist(), "samples_mean": S.mean(axis=0).tolist(),
        "seconds_mean": T.mean(axis=0).tolist(), "final_returns": R[:, -1].tolist(),
        "initial_return": float(R[0, 0]),
    }  # fmt: skip


def _plot(name: str, curves: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    for method, c in curves.items():
        style = {"color": "tab:red", "lw": 2} if method == "fopg_abs" else {}
        for ax, x in zip(axes, (c["samples_mean"], c["seconds_mean"]), strict=True):
            (line,) = ax.plot(x, c["return_mean"], label=method, **style)
            ax.fill_between(x, c["return_min"], c["return_max"], alpha=0.15,
                            color=line.get_color())  # fmt: skip
    axes[0].set(xlabel="training samples (environment steps)", ylabel="evaluated return")
    axes[1].set(xlabel="wall time of training (s)", ylabel="evaluated return")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{name.replace('_', '-')}: return against samples and time (Zhang et al. 2023, "
                 "Fig. 4; mean and min-max over seeds)")  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def report(summary: dict) -> str:
    cfg = summary["config"]
    lines = [f"Locomotion learning (Zhang et al. 2023, Figure 4) on our plant: "
             f"{len(cfg['seeds'])} seeds, {cfg['iterations']} iterations of {cfg['rollouts']} "
             f"rollouts x {cfg['horizon']} steps; {summary['seconds']:.0f} s"]  # fmt: skip
    for name, curves in summary["tasks"].items():
        lines.append(f"{name}: evaluated return (start -> end, mean [min, max] over seeds)")
        ranked = sorted(curves.items(), key=lambda kv: -kv[1]["return_mean"][-1])
        for method, c in ranked:
            lines.append(f"  {method:16s} {c['initial_return']:9.3g} -> "
                         f"{c['return_mean'][-1]:9.3g} "
                         f"[{min(c['final_returns']):.3g}, {max(c['final_returns']):.3g}]  "
                         f"{c['samples_mean'][-1]:.0f} samples, "
                         f"{c['seconds_mean'][-1]:.1f} s")  # fmt: skip
    return "\n".join(lines)


if __name__ == "__main__":
    print(report(run(Config.test_size(), "results/locomotion-test")))
