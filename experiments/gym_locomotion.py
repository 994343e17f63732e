"""Locomotion scored where the community scores it: policies trained on our plant, each final
iterate scored in MuJoCo's own gymnasium v5 environment at its defaults.

For every task, method and training seed (a *run*, :mod:`drake_abs.tasks.training_runs`), the
method trains on our plant (the task's scene at gymnasium's control period; the method's contact
smoothing; gymnasium's reset noise on every episode, 1000-step episodes) until it has used
``env_steps`` environment steps. Along the way, ``evaluations`` times, the current policy is
scored in MuJoCo's own ``gymnasium.make(env_id)``
(:func:`drake_abs.reference.gym_scoring.score_policy`: one episode per reset seed
``0 .. score_seeds - 1``, at most 1000 steps, actions clipped to the action space): the curves
of return against environment steps and against wall-clock training time. The final iterate
(never the best by any score) is scored the same way, and on our plant (exact contact, the
same reset seeds:
:func:`drake_abs.tasks.published_policies.score_on_plant`), and written as a policy file anyone
can load,
``policies/<env id>/<method>/seed<k>.npz``. The zero-action and uniform-random-action floors of
each environment (:func:`~drake_abs.reference.gym_scoring.floors`, the same reset seeds) are
printed beside the scores.

**Resumable.** Each run keeps its folder ``runs/<task>/<method>/seed<k>/``: ``run.json`` (what
defines it: the task, method, seed, every setting of :class:`Config` that changes its numbers,
and the drake-abs version), a checkpoint of the whole training state, the curve so far. A run
is continued from its checkpoint, or taken as finished, only when ``run.json`` matches all of
that; otherwise it starts again. ``max_hours`` stops the experiment after that much wall time
(each run's progress kept); running it again continues. Several calls can share the work with
``runs=`` filters (task/method/seed) or the sweep command (``drake-abs sweep gym-locomotion
--seeds 0 1 2 3 4``, one point per seed).

Outputs in ``out``: ``runs/...`` (per run: ``curve.csv``, ``policy.npz``, ``score.json``),
``policies/<env id>/<method>/seed<k>.npz``, ``curves.csv`` (every evaluation of every run),
``summary.json``, ``table.md``, ``return_<task>.png`` (MuJoCo return against environment steps
and against training seconds, mean and min-max over seeds, the floors as lines).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from drake_abs.experiments import outputs
from drake_abs.policy.ars_trainer import ArsConfig
from drake_abs.policy.methods import method as registry_method
from drake_abs.policy.shac import ShacConfig
from drake_abs.tasks.training_runs import RunSettings

NAME = "gym-locomotion"
#: SHAC's settings in this experiment. The policy's step size 5e-3, decayed linearly to 0 over
#: the default budget (SHAC's schedule; with a constant step size a Hopper run peaked at 1416
#: in MuJoCo at 400k steps and fell below 200 by 700k). Change ``actor_lr_decay_steps`` with
#: ``env_steps``.
SHAC = ShacConfig(actor_lr=5e-3, actor_lr_decay_steps=1_000_000)
TASKS = ("hopper", "half_cheetah")
METHODS = ("shac_abs", "ars")


@dataclass(frozen=True)
class Config:
    """The runs (``tasks`` x ``methods`` x ``seeds``), their budget and how they are scored.

    Attributes:
        tasks: locomotion task names (:data:`drake_abs.tasks.locomotion.TASKS`).
        methods: registry names (:mod:`drake_abs.policy.methods`) of methods
            :mod:`drake_abs.tasks.training_runs` trains.
        seeds: training seeds.
        env_steps: the budget of each run (environment steps, control periods).
        settings: the runs' settings (policy kind, smoothing, smooth survive term, SHAC's:
            :data:`SHAC`, ARS's: the published ones).
        evaluations: MuJoCo scorings along each run (evenly spaced in environment steps, the
            start and the final iterate included).
        score_seeds: reset seeds 0 .. score_seeds - 1, one episode each, for every score.
        episode_steps: the most steps of a scored episode (gymnasium's 1000; smaller only for
            tests).
        plant_score: also score the final iterate on our plant (exact contact).
        max_hours: stop after this much wall time (runs keep their progress); None: no limit.
        checkpoint_every: iterations between checkpoints.
    """

    tasks: tuple[str, ...] = TASKS
    methods: tuple[str, ...] = METHODS
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    env_steps: int = 1_000_000
    settings: RunSettings = field(default_factory=lambda: RunSettings(shac=SHAC))
    evaluations: int = 11
    score_seeds: int = 10
    episode_steps: int = 1000
    plant_score: bool = True
    max_hours: float | None = None
    checkpoint_every: int = 20

    @classmethod
    def test_size(cls) -> Config:
        shac = ShacConfig(envs=4, window=4, episode_length=20, critic_hidden=(8,),
                          critic_epochs=2, critic_minibatches=2)  # fmt: skip
        ars = ArsConfig(directions=2, top=1, episode_length=20)
        return cls(tasks=("hopper",), methods=("shac_abs", "ars"), seeds=(0,), env_steps=160,
                   settings=RunSettings(shac=shac, ars=ars, sb3_envs=2), evaluations=3,
                   score_seeds=2,
                   episode_steps=20, checkpoint_every=2)  # fmt: skip

    def check(self) -> None:
        from drake_abs.tasks.locomotion import TASKS as KNOWN

        for name in self.tasks:
            if name not in KNOWN:
                raise ValueError(f"tasks must be among {sorted(KNOWN)}; got {name!r}")
        for m in self.methods:
            registry_method(m)  # unknown names refused here
        for name in ("env_steps", "evaluations", "score_seeds", "episode_steps",
                     "checkpoint_every"):  # fmt: skip
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1; got {getattr(self, name)!r}")
        if self.evaluations < 2:
            raise ValueError(f"evaluations must be >= 2 (the start and the end); got "
                             f"{self.evaluations}")  # fmt: skip
        if self.max_hours is not None and not self.max_hours > 0:
            raise ValueError(f"max_hours must be > 0 or None; got {self.max_hours!r}")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("drake-abs")
    except PackageNotFoundError:
        return "unknown"


def run_identity(config: Config, task: str, method: str, seed: int) -> dict:
    """What defines one run's numbers (its ``run.json`` must match to be reused): the task,
    method, seed, budget, scoring, drake-abs version, the settings its trainer reads
    (:meth:`~drake_abs.tasks.training_runs.RunSettings.for_method`) and the task's scene as
    it is now (:func:`scene_fingerprint`: a scene file edited within a version restarts its
    runs)."""
    settings = config.settings.for_method(method)
    return {
        "task": task, "method": method, "seed": int(seed), "env_steps": int(config.env_steps),
        "scene": scene_fingerprint(task),
        "settings": outputs_jsonable(settings),
        "evaluations": int(config.evaluations), "score_seeds": int(config.score_seeds),
        "episode_steps": int(config.episode_steps), "plant_score": bool(config.plant_score),
        "drake_abs_version": _version(),
    }  # fmt: skip


def scene_fingerprint(task: str) -> str:
    """A digest (16 hex digits) of the task's scene as loaded (every key of its YAML file,
    resolved), which changes when the scene's model changes."""
    import hashlib

    from drake_abs.multibody.scene import Scene
    from drake_abs.tasks.locomotion import TASKS as KNOWN

    scene = Scene.load(KNOWN[task].scene).to_dict()
    text = json.dumps(scene, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def outputs_jsonable(value):
    """``value`` with tuples as lists (what JSON gives back), for comparing identities."""
    return json.loads(json.dumps(value))


def evaluation_schedule(config: Config) -> list[int]:
    """The environment-step counts at which a run is scored (the first is 0)."""
    return [int(round(k * config.env_steps / (config.evaluations - 1)))
            for k in range(config.evaluations)]  # fmt: skip


def _score(file, env_id: str, config: Config) -> dict:
    from drake_abs.reference.gym_scoring import score_policy

    return score_policy(file.act, env_id, seeds=range(config.score_seeds),
                        max_steps=config.episode_steps)  # fmt: skip


def train_one(config: Config, task: str, method: str, seed: int, folder: Path,
              deadline: float | None) -> dict | None:  # fmt: skip
    """Train (or continue) one run into ``folder``; its record when finished, None when the
    deadline stopped it first."""
    from drake_abs.tasks.training_runs import resume_run, start_run

    folder.mkdir(parents=True, exist_ok=True)
    identity = run_identity(config, task, method, seed)
    record_path, checkpoint = folder / "run.json", folder / "checkpoint.pkl"
    record = json.loads(record_path.read_text()) if record_path.exists() else None
    if record is not None and record.get("identity") != identity:
        record = None  # another run's folder: start again
        checkpoint.unlink(missing_ok=True)
    if record is not None and record.get("status") == "done":
        return record
    curve = record["curve"] if record is not None else []
    if record is not None and checkpoint.exists():
        run_ = resume_run(checkpoint, task, method, seed, config.settings)
    else:
        run_, curve = start_run(task, method, seed, config.settings), []
    env_id = run_.task.env_id
    schedule = evaluation_schedule(config)
    scored = {row["env_steps_target"] for row in curve}

    def save_progress(status: str) -> None:
        run_.save(checkpoint)
        outputs.write_json(record_path, {"identity": identity, "status": status, "curve": curve})

    iterations = 0
    while True:
        due = [s for s in schedule if s <= run_.env_steps and s not in scored]
        if due:  # score once per passed target (the current iterate)
            file = run_.policy_file()
            score = _score(file, env_id, config)
            curve.append({"env_steps_target": due[-1], "env_steps": run_.env_steps,
                          "seconds": run_.seconds, "mujoco_mean": score["mean"],
                          "mujoco_std": score["std"], "mujoco_min": score["min"],
                          "mujoco_max": score["max"],
                          "train_return": run_.recent_return})  # fmt: skip
            scored.update(due)
        if run_.env_steps >= config.env_steps:
            break
        if deadline is not None and time.perf_counter() >= deadline:
            save_progress("partial")
            return None
        run_.iterate()
        iterations += 1
        if iterations % config.checkpoint_every == 0:
            save_progress("partial")
    file = run_.policy_file()
    file.save(folder / "policy.npz")
    final = _score(file, env_id, config)
    plant = None
    if config.plant_score:
        from drake_abs.tasks.locomotion import locomotion_task
        from drake_abs.tasks.published_policies import score_on_plant

        exact = locomotion_task(task, control_period=run_.task.dt, substeps=run_.task.substeps)
        plant = score_on_plant(exact, file, seeds=range(config.score_seeds),
                               max_steps=config.episode_steps)  # fmt: skip
    # training windows (SHAC) dropped for an unconverged contact solve, over the whole run
    dropped = sum(int(row.get("dropped", 0)) for row in run_.rows)
    record = {"identity": identity, "status": "done", "curve": curve, "mujoco": final,
              "plant": plant, "env_steps": run_.env_steps, "seconds": run_.seconds,
              "dropped_windows": dropped,
              "log": run_.rows[-1] if run_.rows else {}}  # fmt: skip
    outputs.write_json(record_path, record)
    checkpoint.unlink(missing_ok=True)  # finished: the policy file is what stays
    return record


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Train, score and summarise every run of ``config`` (continuing unfinished ones); write
    the outputs to ``out`` (default results/gym-locomotion)."""
    from drake_abs.reference.gym_scoring import floors
    from drake_abs.tasks.locomotion import TASKS as KNOWN

    config = Config() if config is None else config
    config.check()
    out = outputs.results_dir(NAME, out)
    start = time.perf_counter()
    deadline = None if config.max_hours is None else start + 3600.0 * config.max_hours
    units = [(t, m, s) for t in config.tasks for m in config.methods for s in config.seeds]
    bar = outputs.progress(total=len(units), desc=f"{NAME}: runs")
    records: dict = {}
    for task, m, seed in units:
        folder = out / "runs" / task / m / f"seed{seed}"
        record = train_one(config, task, m, seed, folder, deadline)
        records[(task, m, seed)] = record
        if record is not None:
            env_id = KNOWN[task].env_id
            target = out / "policies" / env_id / m / f"seed{seed}.npz"
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes((folder / "policy.npz").read_bytes())
            bar.set_postfix_str(f"{task} {m} seed {seed}: {record['mujoco']['mean']:.4g}")
        bar.update()
    bar.close()
    floor = {t: floors(KNOWN[t].env_id, range(config.score_seeds), config.episode_steps)
             for t in config.tasks}  # fmt: skip
    summary = _summarise(config, records, floor)
    summary["seconds"] = time.perf_counter() - start
    summary["folder"] = str(out)
    files = {"summary": out / "summary.json", "curves": out / "curves.csv",
             "table": out / "table.md"}  # fmt: skip
    rows = [{"task": t, "method": m, "seed": s, **row}
            for (t, m, s), rec in records.items() if rec is not None
            for row in rec["curve"]]  # fmt: skip
    outputs.write_csv(out / "curves.csv", rows)
    (out / "table.md").write_text("\n".join(_table(summary)) + "\n")
    for t in config.tasks:
        files[f"return_{t}"] = _plot(t, summary, records, out / f"return_{t}.png")
    summary["files"] = outputs.file_list(files) | {"policies": str((out / "policies").resolve())}
    outputs.write_json(out / "summary.json", summary)
    return summary


def _summarise(config: Config, records: dict, floor: dict) -> dict:
    from drake_abs.tasks.locomotion import TASKS as KNOWN

    tasks: dict = {}
    for t in config.tasks:
        entry = {"env_id": KNOWN[t].env_id, "floors": {k: v["mean"] for k, v in floor[t].items()},
                 "methods": {}}  # fmt: skip
        for m in config.methods:
            done = {s: records[(t, m, s)] for s in config.seeds if records[(t, m, s)] is not None}
            per_seed = {s: r["mujoco"]["mean"] for s, r in done.items()}
            plant = {s: r["plant"]["mean"] for s, r in done.items() if r["plant"] is not None}
            values = np.array(list(per_seed.values()))
            entry["methods"][m] = {
                "label": registry_method(m).label, "seeds_done": sorted(done),
                "seeds_missing": [s for s in config.seeds if s not in done],
                "mujoco_per_seed": per_seed, "plant_per_seed": plant,
                "mujoco_mean": float(values.mean()) if values.size else None,
                "mujoco_min": float(values.min()) if values.size else None,
                "mujoco_max": float(values.max()) if values.size else None,
                "plant_mean": float(np.mean(list(plant.values()))) if plant else None,
                "env_steps": {s: r["env_steps"] for s, r in done.items()},
                "train_seconds": {s: r["seconds"] for s, r in done.items()},
                "unconverged_plant_episodes": {
                    s: r["plant"]["unconverged_episodes"] for s, r in done.items()
                    if r["plant"] is not None
                },
            }  # fmt: skip
        tasks[t] = entry
    return {"config": outputs_jsonable(asdict(config)), "tasks": tasks,
            "drake_abs_version": _version()}  # fmt: skip


def _table(summary: dict) -> list[str]:
    lines = []
    for entry in summary["tasks"].values():
        f = entry["floors"]
        lines.append(f"### {entry['env_id']} (MuJoCo's own environment; floors: zero action "
                     f"{f['zero']:.1f}, random action {f['random']:.1f})")  # fmt: skip
        rows = []
        for r in entry["methods"].values():
            if r["mujoco_mean"] is None:
                rows.append([r["label"], "not finished", "", "", ""])
                continue
            seeds = ", ".join(f"{v:.0f}" for v in r["mujoco_per_seed"].values())
            plant = "" if r["plant_mean"] is None else f"{r['plant_mean']:.0f}"
            rows.append([r["label"], f"{r['mujoco_mean']:.0f}", seeds, plant,
                         f"{np.mean(list(r['env_steps'].values())):.3g}"])  # fmt: skip
        lines += outputs.markdown_table(
            ["method", "MuJoCo mean", "per seed", "our plant mean", "env steps"], rows
        )
        lines.append("")
    return lines


def _plot(task: str, summary: dict, records: dict, path: Path) -> Path:
    plt = outputs.pyplot()
    entry = summary["tasks"][task]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    for m in entry["methods"]:
        curves = [rec["curve"] for (t, mm, _), rec in records.items()
                  if t == task and mm == m and rec is not None]  # fmt: skip
        if not curves:
            continue
        n = min(len(c) for c in curves)
        R = np.array([[row["mujoco_mean"] for row in c[:n]] for c in curves])
        S = np.array([[row["env_steps"] for row in c[:n]] for c in curves], float)
        T = np.array([[row["seconds"] for row in c[:n]] for c in curves])
        for ax, x in zip(axes, (S.mean(0), T.mean(0)), strict=True):
            (line,) = ax.plot(x, R.mean(0), label=registry_method(m).label)
            ax.fill_between(x, R.min(0), R.max(0), alpha=0.15, color=line.get_color())
    for ax in axes:
        for key, style in (("zero", "--"), ("random", ":")):
            ax.axhline(entry["floors"][key], color="gray", ls=style, lw=1,
                       label=f"{key} action")  # fmt: skip
        ax.set_ylabel("return in MuJoCo (gymnasium v5)")
    axes[0].set_xlabel("environment steps of training (our plant)")
    axes[1].set_xlabel("wall-clock training time (s)")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{entry['env_id']}: return of the iterate in MuJoCo's own environment "
                 "(mean and min-max over training seeds)")  # fmt: skip
    return outputs.save_figure(fig, path)


def report(summary: dict) -> str:
    cfg = summary["config"]
    head = (f"Locomotion trained on our plant, scored in MuJoCo's gymnasium v5 environments: "
            f"{len(cfg['seeds'])} training seeds, {cfg['env_steps']} environment steps each, "
            f"{cfg['score_seeds']} reset seeds per score; {summary['seconds']:.0f} s")  # fmt: skip
    return "\n".join([head, *_table(summary)])


if __name__ == "__main__":
    print(report(run(Config.test_size(), "results/gym-locomotion-test")))
