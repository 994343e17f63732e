"""Transfer check: policies learned on our plant, run in MuJoCo's own gymnasium environments.

What a user does with a policy trained on our plant is to run it in gymnasium's ``Hopper-v5`` or
``HalfCheetah-v5``. For each task, every policy is evaluated deterministically (no exploration
noise) from the reset states of several seeds (gymnasium's reset noise; the same seed gives the
same start state in all three) for at most ``steps`` steps, in three settings, each in the
engine (:func:`drake_abs.tasks.episodes.score_episodes`: gymnasium v5's reward at the setting's
control period, its observation and healthy termination, from the task):

- **(a) ours**: our plant with exact (hard, complementarity) contact, one 0.01 s step per
  action, from the reset states :class:`~drake_abs.tasks.gym_env.DrakeAbsEnv` draws;
- **(b) MuJoCo, gymnasium's defaults**: the MuJoCo model of ``gymnasium.make("Hopper-v5")`` /
  ``gymnasium.make("HalfCheetah-v5")`` stepped as the environment steps it
  (:meth:`~drake_abs.reference.mujoco_plant.MujocoStepper.from_gymnasium`; soft contact; the
  Hopper acts every 4 x 2 ms = 8 ms with RK4, the HalfCheetah every 5 x 10 ms = 50 ms with
  Euler), from gymnasium's own ``reset(seed=...)`` states; the returns are those of gymnasium's
  ``env.step`` loop (to rounding: gymnasium adds the reward's terms in another order);
- **(c) MuJoCo at our control period**: the same with ``frame_skip`` such that ``frame_skip *
  model.opt.timestep`` = our time step (the file's timestep is read, not assumed: Hopper 0.002 s
  -> 5, HalfCheetah 0.01 s -> 1).

(c) - (b) isolates the control period; (a) - (c) the simulator (contact model, integrator, the
modelling our scenes state: the HalfCheetah's joint springs are dropped on our side); the
reward's terms (forward, control, survive) show where a difference comes from. A policy of the
observation (as saved for a task) sees gymnasium's observation of the state, a full-state policy
the state (qpos, qvel); actions are not clipped (see the explanation of the control cost).

Policies come from ``Config.policies`` (a folder of saved policies, ``STEM.json`` + ``STEM.npz``
as :func:`drake_abs.policy.saving.save_policy` writes them, e.g. ``results/locomotion/policies``),
and, for a task with none there (or when no folder is given), one policy is trained here briefly:
a linear policy of the observation, FOPG (:func:`~drake_abs.policy.estimators.first_order`) with
Adam through contact-aware adaptive barrier smoothing (or the scene's own exact contact), the best
iterate by a deterministic return on our plant kept, saved to ``policies/``. The zero action is
evaluated too, as a reference: the difference of the passive dynamics.

Outputs in ``out``: ``summary.json``, ``transfer.csv`` (one row per task, policy and setting),
``transfer.png`` (return, forward velocity and episode duration, mean +- std over seeds),
``<task>_replay.html`` (a Meshcat recording of the best policy on our plant), ``policies/``
(the policies trained here) and ``training/`` (their logs).
"""

from __future__ import annotations

import json
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from drake_abs.contact.unconverged import UnconvergedStepWarning
from drake_abs.experiments import outputs
from drake_abs.lcp.ipm import LCPConvergenceWarning
from drake_abs.policy.methods import method
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.saving import save_policy, saved_policy_files
from drake_abs.policy.training import Adam, train
from drake_abs.reference.gymnasium_mujoco import reset_states, same_period_frame_skip
from drake_abs.tasks.episodes import episode_statistics, score_episodes
from drake_abs.tasks.locomotion import TASKS, locomotion_task
from drake_abs.tasks.locomotion_training import evaluate
from drake_abs.tasks.saved_policies import load_policy, reset_state

NAME = "locomotion-transfer"
TASK_NAMES = ("hopper", "half_cheetah")
#: The three settings (key -> label), in order.
SETTINGS = {
    "ours": "(a) ours",
    "mujoco_default": "(b) MuJoCo, gymnasium defaults",
    "mujoco_same_dt": "(c) MuJoCo, our control period",
}
SMOOTHINGS = ("abs", "scene")
REFERENCE = "zero action"


@dataclass(frozen=True)
class Config:
    """Sizes and settings.

    Attributes:
        tasks: which of ``"hopper"``, ``"half_cheetah"``.
        policies: a folder of saved policies (``STEM.json``), or None: train one per task here.
        policy_pattern: which files of that folder (a glob, e.g. ``"*fopg_abs*.json"``).
        seeds: reset seeds of the evaluation episodes (one episode per seed and setting).
        steps: the most steps of an evaluation episode (in each setting's own control period).
        reference: evaluate the zero action too.
        iterations, rollouts, horizon, sigma, learning_rate: training here (per iteration
            ``rollouts`` rollouts of ``horizon`` steps with exploration noise ``sigma`` in
            action units; Adam's step size).
        smoothing: the training model's contact: ``"abs"`` (contact-aware adaptive barrier
            smoothing, ``contact_aware`` = (mu_max, length in m); larger mu is smoother) or
            ``"scene"`` (the scene's own, exact contact).
        train_seed: seeds the training noise and the start states of the iterate selection.
        select_episodes: start states (gymnasium's reset noise) of the deterministic return that
            picks the best iterate (over ``horizon`` steps on our exact plant); 0: keep the last.
        replay_steps: steps of the Meshcat replay of one policy per task.
    """

    tasks: tuple[str, ...] = TASK_NAMES
    policies: str | None = None
    policy_pattern: str = "*.json"
    seeds: tuple[int, ...] = tuple(range(10))
    steps: int = 1000
    reference: bool = True
    iterations: int = 40
    rollouts: int = 16
    horizon: int = 100
    sigma: float = 0.1
    learning_rate: float = 0.01
    smoothing: str = "abs"
    contact_aware: tuple[float, float] = (1e-2, 0.05)
    train_seed: int = 0
    select_episodes: int = 4
    replay_steps: int = 500

    @classmethod
    def test_size(cls) -> Config:
        return cls(seeds=(0, 1), steps=100, iterations=4, rollouts=4, horizon=20,
                   select_episodes=2, replay_steps=40)  # fmt: skip

    def check(self) -> None:
        """``ValueError`` naming the setting that is out of range."""
        if not self.tasks or any(name not in TASK_NAMES for name in self.tasks):
            raise ValueError(f"tasks must be among {TASK_NAMES}; got {self.tasks!r}")
        if self.policies is not None and not Path(self.policies).expanduser().is_dir():
            raise ValueError(f"policies must be an existing folder or None; got {self.policies!r}")
        if not self.seeds or any(
            isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in self.seeds
        ):
            raise ValueError(f"seeds must be whole numbers >= 0, at least one; got {self.seeds!r}")
        for name in ("steps", "iterations", "rollouts", "horizon", "replay_steps"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a whole number >= 1; got {value!r}")
        if not isinstance(self.select_episodes, int) or self.select_episodes < 0:
            raise ValueError(f"select_episodes must be >= 0; got {self.select_episodes!r}")
        if self.smoothing not in SMOOTHINGS:
            raise ValueError(f"smoothing must be one of {SMOOTHINGS}; got {self.smoothing!r}")
        if not (np.isfinite(self.sigma) and self.sigma >= 0):
            raise ValueError(f"sigma must be >= 0 (action units); got {self.sigma!r}")
        if not (np.isfinite(self.learning_rate) and self.learning_rate > 0):
            raise ValueError(f"learning_rate must be > 0; got {self.learning_rate!r}")


# ----------------------------------------------------------------------------------- training


def train_policy(name: str, config: Config, eval_task, folder: Path) -> Path:
    """Train a linear policy of ``name``'s observation briefly by FOPG with Adam (the model's
    contact as ``config.smoothing``), keep the best iterate by the deterministic return on
    ``eval_task`` (our exact plant) from ``select_episodes`` reset states, and save it to
    ``folder/policies/<name>_fopg_<smoothing>``. Returns the saved JSON's path."""
    fopg = method("fopg_abs" if config.smoothing == "abs" else "fopg_exact")
    smoothing = (fopg.make_smoothing(contact_aware=config.contact_aware)
                 if config.smoothing == "abs" else None)  # fmt: skip
    task = locomotion_task(name, smoothing=smoothing)
    inner = LinearPolicy(task.n_obs, task.nu)
    objective = task.objective(inner, config.horizon, config.sigma)
    x_select = eval_task.initial_states(np.random.default_rng([config.train_seed, 1]),
                                        config.select_episodes)  # fmt: skip
    seen: list[tuple[float, np.ndarray]] = []  # (deterministic return, theta) of every iterate

    def score(theta: np.ndarray) -> float:
        seen.append((evaluate(eval_task, theta, x_select, config.horizon), np.array(theta)))
        return seen[-1][0]

    label = f"fopg_{config.smoothing}"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LCPConvergenceWarning)  # counted in the log's rows
        warnings.simplefilter("ignore", UnconvergedStepWarning)
        run_ = train(
            lambda theta, rng: fopg.estimate(objective, theta, rng, config.rollouts),
            np.zeros(inner.n_params), Adam(lr=config.learning_rate), config.iterations,
            seed=config.train_seed, evaluate=score if config.select_episodes else None,
            log_dir=folder / "training", name=f"{name}_{label}",
            config={"task": name, **asdict(config)}, progress=False,
        )  # fmt: skip
    theta, chosen = run_.theta, len(run_.rows) - 1
    if seen:
        chosen = int(np.argmax([value for value, _ in seen]))
        theta = seen[chosen][1]
    info = {"task": name, "method": label, "iteration": chosen,
            "smoothing": repr(smoothing) if smoothing else "scene (exact)",
            "experiment": NAME, **asdict(config)}  # fmt: skip
    paths = save_policy(folder / "policies" / f"{name}_{label}", task.policy(inner), theta,
                        task=name, config=info)  # fmt: skip
    return paths["json"]


# ---------------------------------------------------------------------------------------- run


def _policies_for(config: Config) -> dict[str, list[Path]]:
    """Task name -> the saved policies of ``config.policies`` that act in it."""
    found = {name: [] for name in config.tasks}
    if config.policies is None:
        return found
    for path in saved_policy_files(config.policies, config.policy_pattern):
        task_name = json.loads(path.read_text()).get("task")
        if task_name in found:
            found[task_name].append(path)
    return found


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Evaluate every task's policies in the three settings; write summary.json, the CSV table,
    the plot and one Meshcat replay per task to ``out`` (default results/locomotion-transfer)."""
    from pydrake.geometry import Meshcat, MeshcatParams

    from drake_abs.diagrams.policy_replay import replay_policy_html
    from drake_abs.reference.mujoco_plant import MujocoStepper

    config = config or Config()
    config.check()
    out = outputs.results_dir(NAME, out)
    start = time.perf_counter()
    saved_paths = _policies_for(config)
    meshcat = Meshcat(MeshcatParams(host="localhost"))
    results: dict = {}
    files: dict[str, Path] = {}
    bar = outputs.progress(total=len(config.tasks), desc=f"{NAME}: tasks")
    for name in config.tasks:
        bar.set_postfix_str(name)
        env_id = TASKS[name].env_id
        task = locomotion_task(name)  # the scene's own, exact contact: our plant
        mujoco = same_period_frame_skip(env_id, task.dt)
        skips = {"mujoco_default": mujoco["default_frame_skip"],
                 "mujoco_same_dt": mujoco["frame_skip"]}  # fmt: skip
        ours = "semi-implicit Euler time stepping, hard contact"
        settings = {"ours": {"control_period": task.dt, "frame_skip": None, "timestep": task.dt,
                             "integrator": ours}}  # fmt: skip
        settings |= {key: {"control_period": skip * mujoco["timestep"], "frame_skip": skip,
                           "timestep": mujoco["timestep"], "integrator": mujoco["integrator"]}
                     for key, skip in skips.items()}  # fmt: skip
        # setting -> (stepper, its initial states); None: the task's own stepper (our plant)
        x_mujoco = reset_states(env_id, config.seeds)
        steppers = {"ours": (None, np.array([reset_state(task, s) for s in config.seeds]))}
        steppers |= {key: (MujocoStepper.from_gymnasium(env_id, frame_skip=skip), x_mujoco)
                     for key, skip in skips.items()}  # fmt: skip
        paths = saved_paths[name] or [train_policy(name, config, task, out)]
        source = "saved" if saved_paths[name] else "trained here"
        loaded = {Path(p).name.removesuffix(".json"): (load_policy(p, task=task), str(p))
                  for p in paths}  # fmt: skip
        # label -> (policy, theta, source, file)
        candidates = {label: (sp.policy, sp.theta, source, file)
                      for label, (sp, file) in loaded.items()}  # fmt: skip
        if config.reference:
            zero = LinearPolicy(task.nx, task.nu)  # zero parameters: the zero action
            candidates[REFERENCE] = (zero, np.zeros(zero.n_params), "reference", None)
        policies = {}
        for label, (policy, theta, source, file) in candidates.items():
            stats = {key: episode_statistics(score_episodes(task, policy, theta, x0s, config.steps,
                                                            stepper=stepper))
                     for key, (stepper, x0s) in steppers.items()}  # fmt: skip
            policies[label] = {"source": source, "file": file, "results": stats,
                               "differences": differences(stats)}  # fmt: skip
        best = max(loaded, key=lambda lb: policies[lb]["results"]["ours"]["return_mean"])
        replay = replay_policy_html(loaded[best][0], out / f"{name}_replay.html",
                                    steps=config.replay_steps, seed=config.seeds[0],
                                    meshcat=meshcat)  # fmt: skip
        files[f"{name}_replay"] = replay.path
        results[name] = {
            "env_id": env_id, "settings": settings, "policies": policies,
            "replay": {"policy": best, "html": str(replay.path), "seed": config.seeds[0],
                       "steps": replay.episode.steps, "return": replay.episode.total_return,
                       "terminated": replay.episode.terminated},
        }  # fmt: skip
        bar.update()
    bar.close()
    files["table"] = _write_csv(out / "transfer.csv", results)
    files["plot"] = _plot(out / "transfer.png", results, config)
    files["summary"] = out / "summary.json"
    summary = {"config": asdict(config), "tasks": results,
               "seconds": time.perf_counter() - start, "folder": str(out)}  # fmt: skip
    summary["files"] = outputs.file_list(files)
    if (out / "policies").is_dir():
        summary["files"]["policies"] = str((out / "policies").resolve())
    summary["explanation"] = {name: explanation(name, results[name]) for name in results}
    outputs.write_json(out / "summary.json", summary, indent=1)
    return summary


def differences(results: dict) -> dict:
    """Where the returns part, in the mean over seeds, each as return, forward, control and
    survive terms: ``time_step`` = (c) - (b) (the control period, MuJoCo on both sides),
    ``simulator`` = (a) - (c) (our plant against MuJoCo, the same period), ``total`` = (a) -
    (b)."""
    pairs = {
        "time_step": ("mujoco_same_dt", "mujoco_default"),
        "simulator": ("ours", "mujoco_same_dt"),
        "total": ("ours", "mujoco_default"),
    }
    keys = ("return", "reward_forward", "reward_ctrl", "reward_survive", "length", "seconds",
            "forward_velocity", "action_rms")  # fmt: skip
    return {
        name: {k: results[a][f"{k}_mean"] - results[b][f"{k}_mean"] for k in keys}
        for name, (a, b) in pairs.items()
    }


# -------------------------------------------------------------------------------- outputs


def _write_csv(path: Path, results: dict) -> Path:
    keys = ("return", "length", "seconds", "forward_velocity", "reward_forward", "reward_ctrl",
            "reward_survive", "action_rms", "saturated_fraction")  # fmt: skip
    return outputs.write_csv(path, [
        {"task": name, "policy": label, "source": entry["source"], "setting": key,
         "control_period_s": r["settings"][key]["control_period"],
         "frame_skip": r["settings"][key]["frame_skip"], "episodes": stats["episodes"],
         **{f"{k}_{s}": stats[f"{k}_{s}"] for k in keys for s in ("mean", "std")},
         "terminated_fraction": stats["terminated_fraction"],
         "unconverged_steps": stats["unconverged_steps"]}
        for name, r in results.items() for label, entry in r["policies"].items()
        for key, stats in entry["results"].items()])  # fmt: skip


def _plot(path: Path, results: dict, config: Config) -> Path:
    metrics = (("return", "return over the episode"),
               ("forward_velocity", "forward distance per second (m/s)"),
               ("seconds", "episode duration (s)"))  # fmt: skip
    size = (6.5 * len(results), 9)
    fig, axes = outputs.pyplot().subplots(len(metrics), len(results), figsize=size, squeeze=False)
    width = 0.8 / len(SETTINGS)
    for col, r in enumerate(results.values()):
        labels = list(r["policies"])
        x = np.arange(len(labels))
        for row, (key, ylabel) in enumerate(metrics):
            ax = axes[row, col]
            for i, setting in enumerate(SETTINGS):
                stats = [r["policies"][lb]["results"][setting] for lb in labels]
                period = r["settings"][setting]["control_period"]
                ax.bar(x + (i - 1) * width, [s[f"{key}_mean"] for s in stats], width,
                       yerr=[s[f"{key}_std"] for s in stats], capsize=3,
                       label=f"{SETTINGS[setting]} ({period * 1e3:g} ms)")  # fmt: skip
            ax.set_xticks(x, labels, fontsize=7, rotation=15)
            ax.set_ylabel(ylabel)
            ax.axhline(0.0, color="k", lw=0.5)
            if row == 0:
                ax.set_title(f"{r['env_id']}: {len(config.seeds)} seeds, at most "
                             f"{config.steps} steps")  # fmt: skip
                ax.legend(fontsize=7)
    fig.suptitle("Policies trained on our plant, run on it and in gymnasium's MuJoCo "
                 "environments (mean +- std over reset seeds)")  # fmt: skip
    return outputs.save_figure(fig, path)


def explanation(name: str, r: dict) -> str:
    """Why the settings' returns differ, for task ``name`` (the settings are this run's)."""
    s = r["settings"]
    a, b, c = s["ours"], s["mujoco_default"], s["mujoco_same_dt"]
    ms = {key: f"{v['control_period'] * 1e3:g} ms" for key, v in s.items()}
    lines = [
        f"Control period: ours {ms['ours']}; gymnasium's {r['env_id']} {b['frame_skip']} x "
        f"{b['timestep'] * 1e3:g} ms = {ms['mujoco_default']} ({b['integrator']}); (c) "
        f"{c['frame_skip']} x {c['timestep'] * 1e3:g} ms = {ms['mujoco_same_dt']}. Every reward "
        "term is counted per step: over an episode the forward term is the number of steps "
        "times the mean forward velocity (m/s) and the control cost a sum over steps, so the "
        f"same number of steps lasts {b['control_period'] / a['control_period']:g} times as long "
        f"in (b) as on ours, and the policy, trained to act every {ms['ours']}, holds each "
        f"action for {ms['mujoco_default']} in (b). (c) - (b) is this effect alone.",
        "Simulator: ours steps hard contact (a complementarity problem: no penetration, "
        "Coulomb friction) with semi-implicit Euler and hard joint limits; MuJoCo's contact is "
        "soft (the mujoco-comparison experiment measures 10-30 mm of sinking where ours stays "
        f"on the ground), its joint limits soft too, integrated with {b['integrator']}. (a) - (c) "
        "is this effect at the same control period.",
        "Closed loop: the policy acts on the states it meets, so once a simulator takes the body "
        "elsewhere its actions differ too; a linear policy's action is not clipped, the motors "
        "saturate at +-1 (MuJoCo clamps ctrl, ours clips the torque) but the control cost counts "
        "the action as given (gymnasium's rule, on both sides): a policy driven off the states it "
        "was trained on pays a large control cost (the action rms and the share beyond +-1 are "
        "reported per setting).",
    ]
    if name == "half_cheetah":
        lines.append(
            "Model: our HalfCheetah scene drops the joint springs of the MuJoCo file (stiffness "
            "240 ... 60 N m/rad, which our step does not model): MuJoCo's legs are pulled back "
            "to their rest angles, ours rest on their damping and limits."
        )
    if name == "hopper":
        lines.append(
            "Healthy termination: the Hopper's episode ends at its first unhealthy state "
            "(height <= 0.7 m or |pitch| >= 0.2 rad) and every step alive earns 1, so the return "
            "is mostly the episode's length in steps: a hopper that stays up for the same time "
            f"earns {1 / b['control_period']:g} per second in (b) and "
            f"{1 / a['control_period']:g} on ours and in (c), and a small difference in when it "
            "tips (another contact model, another period) changes the return by the steps lost."
        )
    return " ".join(lines)


def report(summary: dict) -> str:
    cfg = summary["config"]
    lines = [
        f"Transfer to gymnasium's MuJoCo environments: deterministic returns over at most "
        f"{cfg['steps']} steps, mean +- std over {len(cfg['seeds'])} reset seeds; "
        f"{summary['seconds']:.0f} s"
    ]
    for name, r in summary["tasks"].items():
        lines.append(f"\n{name} ({r['env_id']}):")
        for label, entry in r["policies"].items():
            lines.append(f"  policy {label} ({entry['source']}):")
            for key, st in entry["results"].items():
                setting = f"{SETTINGS[key]} ({r['settings'][key]['control_period'] * 1e3:g} ms)"
                unconverged = st["unconverged_steps"]
                lines.append(
                    f"    {setting:42s} return "
                    f"{st['return_mean']:9.2f} +- {st['return_std']:7.2f}   length "
                    f"{st['length_mean']:6.1f} +- {st['length_std']:5.1f} steps "
                    f"({st['seconds_mean']:5.2f} s)   forward "
                    f"{st['forward_velocity_mean']:+.3f} +- {st['forward_velocity_std']:.3f} m/s"
                    + f"   action rms {st['action_rms_mean']:.2f}"
                    + f" ({100 * st['saturated_fraction_mean']:.0f} % beyond +-1)"
                    + (f"   unconverged steps {unconverged}" if unconverged else "")
                )
            for part, title in (("time_step", "control period (c) - (b)"),
                                ("simulator", "simulator (a) - (c)")):  # fmt: skip
                p = entry["differences"][part]
                lines.append(
                    f"    {title:26s} return {p['return']:+9.2f} = forward "
                    f"{p['reward_forward']:+.2f} + control {p['reward_ctrl']:+.2f} + survive "
                    f"{p['reward_survive']:+.2f}; length {p['length']:+.1f} steps, "
                    f"{p['seconds']:+.2f} s"
                )
        rep = r["replay"]
        lines += [f"  replay of {rep['policy']} on our plant (seed {rep['seed']}, {rep['steps']} "
                  f"steps, return {rep['return']:.2f}): {rep['html']}",
                  "  why: " + summary["explanation"][name]]  # fmt: skip
    return "\n".join(lines)


if __name__ == "__main__":
    print(report(run(Config.test_size(), "results/locomotion-transfer-test")))
