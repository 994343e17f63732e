"""The drake-abs command line.

Usage::

    drake-abs demo [--out DIR] [--duration S] [--no-meshcat]
    drake-abs experiment NAME [--out DIR] [--test-size] [--set KEY=VALUE ...] [--no-progress]
                         [--ray] [--address ADDR] [--workers N]
    drake-abs experiment --list
    drake-abs sweep NAME [--seeds S ...] [--set KEY=V1,V2 ...] [--test-size] [--out DIR] [--ray]
                    [--address ADDR] [--workers N] [--metric KEY] [--fresh | --check]
                    [--no-progress]
    drake-abs train TASK --method M [--steps N] [--seed S] [--out DIR] [--set KEY=VALUE ...]
                    [--no-progress]
    drake-abs record SCENE [--steps N] [--out FILE]
    drake-abs replay POLICY.json|POLICY.npz [--env ID] [--steps N] [--seed S] [--out FILE]
    drake-abs evaluate POLICY.npz [--env ID] [--seeds N] [--max-steps N] [--json FILE]
                       [--no-plant]
    drake-abs list
    drake-abs precompile
    drake-abs --version

Names are shown with dashes (gradient-variance, box-push); underscores are accepted too.
POLICY.npz is a policy file of the published format (drake_abs.policy.policy_files;
docs/policy_files.md); POLICY.json a policy saved by drake_abs.policy.saving.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from drake_abs.experiments.catalog import (
    DESCRIPTIONS,
    EXPERIMENTS,
    experiment_module,
)


def display_name(name: str) -> str:
    """The one spelling the CLI shows: dashes (``box_push`` -> ``box-push``)."""
    return name.replace("_", "-")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("drake-abs")
    except PackageNotFoundError:  # run from a checkout that is not installed
        return "unknown (not installed)"


# ---------------------------------------------------------------------------------- argument types


def positive_int(option: str, example: str = "100"):
    """An argparse type for ``option``: an integer > 0 (argparse names the option in its
    error message)."""

    def parse(text: str) -> int:
        try:
            value = int(text, 10)
        except ValueError:
            value = 0
        if value <= 0:
            raise argparse.ArgumentTypeError(
                f"expected a positive whole number such as {example}, got {text!r}"
            )
        return value

    parse.__name__ = "positive integer"
    return parse


def positive_float(option: str, example: str = "1.5", unit: str = "seconds"):
    """An argparse type for ``option``: a finite number > 0 (argparse names the option in its
    error message)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise argparse.ArgumentTypeError(
                f"expected a positive finite number of {unit} such as {example}, got {text!r}"
            )
        return value

    parse.__name__ = "positive number"
    return parse


def experiment_name(text: str) -> str:
    """An argparse type: an experiment name in either spelling, as its dashed name."""
    return display_name(text.strip().lower())


def _shipped_scenes() -> list[str]:
    from drake_abs.multibody.scene import shipped_scenes

    return shipped_scenes()


def scene_argument(text: str) -> str:
    """An argparse type: a scene YAML file, or a shipped scene's name in either spelling (as the
    scene's own name, e.g. ``box-push`` -> ``box_push``), or a ``package://`` URI."""
    if text.startswith("package://"):
        return text
    path = Path(text).expanduser()
    if path.suffix in (".yaml", ".yml") or path.is_file():
        if not path.is_file():
            raise argparse.ArgumentTypeError(f"no scene file {text!r}")
        return str(path.resolve())
    shipped = _shipped_scenes()
    by_display = {display_name(name): name for name in shipped}
    name = by_display.get(display_name(text.strip().lower()))
    if name is None:
        raise argparse.ArgumentTypeError(
            f"no scene {text!r}: give a scene YAML file or one of "
            + ", ".join(display_name(n) for n in shipped)
        )
    return name


# ------------------------------------------------------------------------------------- commands


def listing() -> str:
    """The experiments (one plain line each) and the shipped scenes."""
    width = max(len(n) for n in EXPERIMENTS)
    lines = ["experiments (drake-abs experiment NAME [--test-size]):"]
    lines += [f"  {name:{width}s}  {DESCRIPTIONS[name]}" for name in EXPERIMENTS]
    lines.append("")
    lines.append("shipped scenes (drake-abs record SCENE):")
    lines += [f"  {display_name(name)}" for name in _shipped_scenes()]
    return "\n".join(lines)


def _print_report(report: str, folder: Path) -> None:
    print(report)
    print(f"results written to {folder}")


def _run_demo(out: Path, *, duration: float | None, meshcat: bool) -> int:
    from drake_abs.experiments.bouncing_ball import Config, report, run
    from drake_abs.experiments.outputs import results_dir, write_provenance

    kwargs = {"meshcat": meshcat}
    if duration is not None:
        kwargs["duration"] = duration
    folder = results_dir("demo", out)
    summary = run(Config(**kwargs), folder)
    write_provenance(folder, "demo", Config(**kwargs))
    _print_report(report(summary), folder)
    return 0


def _run_standard(name: str, out: Path | None, *, test_size: bool, ray: bool = False,
                  address: str | None = None, workers: int | None = None,
                  config=None) -> int:  # fmt: skip
    """Run one experiment (``config``, default its Config or test size); with ``ray`` its
    estimators' rollouts go to a :class:`~drake_abs.parallel.RayRunner` (the same numbers, see
    drake_abs.parallel)."""
    from drake_abs.experiments import outputs
    from drake_abs.experiments.outputs import default_out

    module = experiment_module(name)
    if config is None:
        config = module.Config.test_size() if test_size else module.Config()
    folder = default_out(name) if out is None else out.expanduser().resolve()
    if not ray:
        summary = module.run(config, folder)
    else:
        from drake_abs.parallel import RayRunner, connect, shutdown
        from drake_abs.policy.rollouts import use_runner

        connect(address, num_cpus=workers)
        try:
            with RayRunner() as runner, use_runner(runner):
                summary = module.run(config, folder)
                print(f"rollouts ran on {runner.workers} Ray worker(s) in {runner.tasks_sent} "
                      "tasks")  # fmt: skip
        finally:
            shutdown()
    outputs.write_provenance(folder, f"experiment {name}", config)
    _print_report(module.report(summary), folder)
    return 0


def add_ray_options(parser: argparse.ArgumentParser, ray_help: str) -> None:
    """``--ray`` (with ``ray_help``), ``--address`` and ``--workers``, the same on every command
    that can run on Ray."""
    parser.add_argument("--ray", action="store_true", help=ray_help)
    parser.add_argument(
        "--address", default=None, metavar="ADDR",
        help="join this Ray cluster (auto, HOST:6379 or ray://HOST:10001; implies --ray)",
    )  # fmt: skip
    parser.add_argument(
        "--workers", type=positive_int("--workers", "4"), default=None, metavar="N",
        help="CPUs of the local Ray cluster (implies --ray; default: all)",
    )  # fmt: skip


def wants_ray(sub: argparse.ArgumentParser, args: argparse.Namespace) -> bool:
    """Whether the Ray options ask for Ray; a usage error (exit 2) for ``--workers`` with
    ``--address``, or when Ray is asked for but not installed."""
    if args.address is not None and not args.address.strip():
        sub.error("argument --address: expected a Ray cluster's address (auto, HOST:6379 or "
                  f"ray://HOST:10001), got {args.address!r}")  # fmt: skip
    if args.address is not None and args.workers is not None:
        sub.error("argument --workers: sets the CPUs of a local Ray cluster; a cluster joined "
                  "with --address has its own")  # fmt: skip
    on_ray = args.ray or args.address is not None or args.workers is not None
    if on_ray:
        from drake_abs.parallel.cluster import require_ray

        try:
            require_ray()
        except ImportError as err:
            sub.error(f"argument --ray: {err}")
    return on_ray


def _run_sweep(sub: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    """The sweep subcommand: build the grid (argument errors exit 2), run it, print the report;
    1 if a point failed (everything is written first). With ``--check``, run nothing: print
    what a run would do with every point; 0 if every point is fresh, else 1."""
    from drake_abs.experiments.sweep import (
        ExperimentPoint,
        GridError,
        build_grid,
        check_report,
        report,
    )
    from drake_abs.parallel.sweep import FRESH, check_sweep, run_sweep

    on_ray = wants_ray(sub, args)
    try:
        points = build_grid(args.name, seeds=args.seeds, settings=args.settings,
                            test_size=args.test_size)  # fmt: skip
    except GridError as err:
        sub.error(f"argument {err.argument}: {err}")
    out = Path(args.out or f"results/sweep-{args.name}").expanduser().resolve()
    if args.check:
        from drake_abs.parallel.provenance import provenance

        fn = ExperimentPoint(args.name, args.test_size)
        states = check_sweep(fn, points, out)
        print(check_report(states, description=fn.describe(), out=out, provenance=provenance()))
        return 0 if all(s.state == FRESH for s in states) else 1
    result = run_sweep(
        ExperimentPoint(args.name, args.test_size), points, out,
        backend="ray" if on_ray else "local", address=args.address, num_cpus=args.workers,
        resume=not args.fresh, progress=not args.no_progress, metric=args.metric,
    )  # fmt: skip
    print(report(result))
    print(f"results written to {out}")
    if result.metric_error:
        sub.error(f"argument --metric: {result.metric_error} (everything else is written; run "
                  "again with another --metric: finished points are not recomputed)")  # fmt: skip
    if result.failures:
        print(f"{len(result.failures)} of {len(result.points)} points failed; each traceback is "
              "in its point.json", file=sys.stderr)  # fmt: skip
        return 1
    return 0


def seed_number(text: str) -> int:
    """An argparse type: a seed, a whole number >= 0."""
    try:
        value = int(text, 10)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0 such as 0, got {text!r}")
    return value


seed_number.__name__ = "seed"


def _record(scene, steps: int, out: str | None) -> int:
    from drake_abs.diagrams.scene_visualization import record_scene

    html = Path(out or f"results/{scene.name}.html").expanduser().resolve()
    html.parent.mkdir(parents=True, exist_ok=True)
    record_scene(scene, steps, html)
    print(f"recorded {steps} steps of {scene.name} (Meshcat, localhost) to {html}")
    return 0


def policy_argument(text: str) -> str:
    """An argparse type: a policy file (``.npz`` of the published format, as its absolute
    path), or a saved policy, its STEM.json (or STEM.npz, or STEM), as the JSON's absolute
    path."""
    from drake_abs.policy.policy_files import is_policy_file, load_policy_file
    from drake_abs.policy.saving import policy_paths

    if is_policy_file(text):
        return str(Path(text).expanduser().resolve())
    json_path, _ = policy_paths(text)
    path = Path(text).expanduser()
    if path.suffix == ".npz" and path.is_file() and not json_path.is_file():
        try:  # an npz that is no policy file (damaged, empty, other arrays): say what is wrong
            load_policy_file(path)
        except (ValueError, OSError) as err:
            raise argparse.ArgumentTypeError(str(err)) from None
    if not json_path.is_file():
        raise argparse.ArgumentTypeError(
            f"no saved policy or policy file {text!r}: give a policy file (.npz with W, b or "
            "W0, b0, ...) or the STEM.json that save_policy wrote"
        )
    return str(json_path.resolve())


policy_argument.__name__ = "saved policy"


def _replay(saved, steps: int | None, seed: int, out: str | None) -> int:
    from drake_abs.diagrams.policy_replay import replay_policy_html

    stem = Path(saved.path).name.removesuffix(".json").removesuffix(".npz")
    html = Path(out or f"results/{stem}.html").expanduser().resolve()
    replay = replay_policy_html(saved, html, steps=steps, seed=seed)
    ep = replay.episode
    ended = "terminated" if ep.terminated else "not terminated"
    print(f"replayed {stem} ({replay.task_name}, seed {seed}) on our plant: {ep.steps} steps "
          f"({ep.seconds:g} s, {ended}), return {ep.total_return:.2f}, forward "
          f"{ep.forward_distance:+.3f} m (Meshcat, localhost) to {replay.path}")  # fmt: skip
    return 0


def _plant_score(file, env_id: str, seeds: list[int], max_steps: int) -> dict:
    """The policy file's score on our plant, or ``{"skipped": why}`` where the environment has
    no scene on our plant or our task observes something else than gymnasium (checked on the
    reset observations of the same seeds)."""
    import numpy as np

    from drake_abs.reference.gym_scoring import reset_observations
    from drake_abs.tasks.locomotion import locomotion_task
    from drake_abs.tasks.published_policies import score_on_plant, task_name_for_env
    from drake_abs.tasks.saved_policies import reset_state

    try:
        name = task_name_for_env(env_id)
    except ValueError as err:
        return {"skipped": str(err)}
    task = locomotion_task(name)
    ours = task.observation(np.array([reset_state(task, s) for s in seeds]))
    theirs = reset_observations(env_id, seeds)
    if ours.shape != theirs.shape or not np.allclose(ours, theirs, rtol=0, atol=1e-12):
        return {"skipped": f"task {name!r} does not observe what {env_id} observes (its reset "
                           "observations differ from gymnasium's)"}  # fmt: skip
    return score_on_plant(task, file, seeds=seeds, max_steps=max_steps)


def _score_row(label: str, score: dict) -> str:
    lengths = score["lengths"]
    return (
        f"  {label:15s}{score['mean']:11.2f}{score['std']:10.2f}{score['min']:11.2f}"
        f"{score['max']:11.2f}   {score['length_mean']:7.1f}  {min(lengths)}..{max(lengths)}"
    )


def evaluation_report(result: dict) -> str:
    """The plain-text report of ``drake-abs evaluate`` from its JSON record."""
    seeds = result["seeds"]
    span = f"{seeds[0]}..{seeds[-1]}" if seeds == list(range(seeds[0], seeds[-1] + 1)) else (
        ", ".join(str(s) for s in seeds))  # fmt: skip
    meta = result["metadata"]
    about = ", ".join(f"{k} {meta[k]}" for k in ("method", "seed", "training_steps") if k in meta)
    mj = result["mujoco"]
    header = (f"  {'':15s}{'mean':>11s}{'std':>10s}{'min':>11s}{'max':>11s}   steps (mean, "
              "min..max)")  # fmt: skip
    lines = [
        f"policy {result['policy']}",
        f"  {result['description']}" + (f" ({about})" if about else ""),
        "",
        f"{result['env_id']} in MuJoCo (gymnasium {mj['policy']['gymnasium']}, mujoco "
        f"{mj['policy']['mujoco']}, the environment's defaults), {len(seeds)} episodes from "
        f"reset seeds {span}, at most {result['max_steps']} steps, actions clipped to the "
        "action space:",
        header,
        _score_row("policy", mj["policy"]),
        _score_row("zero action", mj["zero"]),
        _score_row("random action", mj["random"]),
        "  (random action: uniform in the action space from numpy.random.default_rng(seed))",
        "",
    ]
    plant = result["plant"]
    if plant is None:
        lines.append("our plant: not scored (--no-plant)")
    elif "skipped" in plant:
        lines.append(f"our plant: not scored: {plant['skipped']}")
    else:
        lines += [
            f"our plant (task {plant['task']}, {plant['dt']:g} s per action), the same reset "
            "seeds and steps:",
            header,
            _score_row("policy", plant),
            f"  episodes with an unconverged contact solve: {plant['unconverged_episodes']} of "
            f"{len(plant['returns'])} ({plant['unconverged_steps']} steps)",
        ]
    return "\n".join(lines)


def _evaluate(sub: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    """The evaluate subcommand: the policy file's score in MuJoCo's own environment with the
    floors beside it, and on our plant; the JSON record to ``--json``."""
    import json

    from drake_abs.policy.policy_files import load_policy_file
    from drake_abs.reference.gym_scoring import floors, score_policy

    try:
        file = load_policy_file(args.policy)
    except (ValueError, OSError) as err:
        sub.error(f"argument POLICY: {err}")
    named = file.metadata.get("env_id")
    env_id = args.env or named
    if env_id is None:
        sub.error("argument --env: the policy file names no env_id; give the gymnasium "
                  "environment, e.g. --env Hopper-v5")  # fmt: skip
    if args.env and named and args.env != named:
        print(f"note: the policy file was written for {named}; scoring it in {args.env}",
              file=sys.stderr)  # fmt: skip
    env_id = str(env_id)
    try:
        import gymnasium

        env = gymnasium.make(env_id)
    except ImportError as err:
        sub.error(f"argument --env: gymnasium and mujoco are needed ({err})")
    except Exception as err:  # gymnasium's unknown-id and missing-dependency errors
        sub.error(f"argument --env: {env_id!r}: {err}")
    obs_shape, action_shape = env.observation_space.shape, env.action_space.shape
    env.close()
    if obs_shape != (file.n_obs,) or action_shape != (file.nu,):
        sub.error(
            f"argument POLICY: the policy maps {file.n_obs} observations to {file.nu} actions; "
            f"{env_id} observes {obs_shape} and acts with {action_shape}"
        )
    seeds, steps = list(range(args.seeds)), args.max_steps
    result = {
        "policy": args.policy, "description": file.describe(), "metadata": dict(file.metadata),
        "env_id": env_id, "seeds": seeds, "max_steps": steps,
        "mujoco": {"policy": score_policy(file.output, env_id, seeds=seeds, max_steps=steps),
                   **floors(env_id, seeds, steps)},
        "plant": None if args.no_plant else _plant_score(file, env_id, seeds, steps),
    }  # fmt: skip
    print(evaluation_report(result))
    if args.json is not None:
        path = Path(args.json).expanduser().resolve()
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result, indent=1) + "\n")
        print(f"written to {path}")
    return 0


def task_argument(text: str) -> str:
    """An argparse type: a locomotion task name in either spelling (``half-cheetah`` ->
    ``half_cheetah``)."""
    from drake_abs.tasks.locomotion import TASKS

    name = text.strip().lower().replace("-", "_")
    if name not in TASKS:
        raise argparse.ArgumentTypeError(
            f"no task {text!r}: give one of " + ", ".join(display_name(t) for t in TASKS)
        )
    return name


task_argument.__name__ = "task"


def train_method(text: str) -> str:
    """An argparse type: a method a training run trains (the registry's name; dashes accepted
    for underscores)."""
    from drake_abs.experiments.train import trainable_methods

    known = trainable_methods()
    for name in (text.strip(), text.strip().replace("-", "_")):
        if name in known:
            return name
    raise argparse.ArgumentTypeError(f"no trainable method {text!r}: give one of "
                                     + ", ".join(known))  # fmt: skip


train_method.__name__ = "method"


def _train(sub: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    """The train subcommand: the run's settings (``--set`` applied to the defaults), the run,
    its report."""
    import importlib.util

    from drake_abs.experiments import outputs
    from drake_abs.experiments.train import base_settings, default_out, report, train
    from drake_abs.policy.methods import method as registry_method

    if registry_method(args.method).estimator == "sb3" and (
        importlib.util.find_spec("stable_baselines3") is None
    ):
        sub.error(f"argument --method: {args.method} is a library baseline: it needs the "
                  "baselines extra (pip install 'drake-abs[baselines]')")  # fmt: skip
    try:
        settings = base_settings(args.task, args.method, args.steps)
    except ValueError as err:  # e.g. ARS on a task with no published settings
        sub.error(f"argument --method: {err}")
    if args.settings:
        settings = with_settings(sub, settings, args.settings)
    out = default_out(args.task, args.method, args.seed) if args.out is None else Path(args.out)
    summary = train(args.task, args.method, steps=args.steps, seed=args.seed, out=out,
                    settings=settings)  # fmt: skip
    outputs.write_provenance(Path(summary["files"]["summary"]).parent,
                             f"train {args.task} --method {args.method} --seed {args.seed} "
                             f"--steps {args.steps}", settings)  # fmt: skip
    _print_report(report(summary), Path(summary["files"]["summary"]).parent)
    return 0


def _check_folder(parser: argparse.ArgumentParser, out: str | None) -> None:
    """A usage error unless ``--out`` can be a results folder: not a file, and not under one."""
    path = None if out is None else Path(out).expanduser()
    if path is not None and path.exists() and not path.is_dir():
        parser.error(f"argument --out: {out!r} is a file, not a folder")
    _check_parents(parser, "--out", out)


def _check_parents(parser: argparse.ArgumentParser, option: str, value: str | None) -> None:
    """A usage error when a folder above ``value`` (an output path) is an existing file, so
    that the folder cannot be created; an empty ``value`` is refused too."""
    if value is None:
        return
    if not value.strip():
        parser.error(f"argument {option}: expected a path, got {value!r}")
    for parent in Path(value).expanduser().absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                parser.error(
                    f"argument {option}: {value!r} is under {str(parent)!r}, which is a file, "
                    "not a folder"
                )
            return


def _check_file(parser: argparse.ArgumentParser, option: str, value: str | None) -> None:
    """A usage error unless ``value`` (an output file) can be written: not a folder, not under
    a file."""
    if value is not None and Path(value).expanduser().is_dir():
        parser.error(f"argument {option}: {value!r} is a folder; give a file name")
    _check_parents(parser, option, value)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="drake-abs",
        description="Adaptive barrier smoothing on Drake: the demo, the papers' experiments, "
        "sweeps of them over seeds and settings (here or on Ray), scene recordings.",
        epilog="Names are shown with dashes; the same names with underscores are accepted too. "
        "'drake-abs list' shows every experiment and scene.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    demo = sub.add_parser(
        "demo",
        help="the bouncing-ball demo, with a guide to its plots (Zhang et al. 2023, Figure 2)",
        description="Run the bouncing-ball demo, write its plots, a Meshcat recording and "
        "summary.json, and print what to look at.",
    )
    demo.add_argument(
        "--out", default="results/demo", metavar="DIR", help="results folder (default: %(default)s)"
    )
    demo.add_argument(
        "--duration",
        type=positive_float("--duration", "1.0"),
        default=None,
        metavar="S",
        help="simulated seconds, at least one time step of 0.01 s (default: 1.0)",
    )
    demo.add_argument("--no-meshcat", action="store_true", help="skip the Meshcat HTML recording")

    experiment_help = "\n".join(f"  {n:18s} {DESCRIPTIONS[n]}" for n in EXPERIMENTS)
    exp = sub.add_parser(
        "experiment",
        help="reproduce one of the papers' experiments (see 'drake-abs list')",
        description="Run one experiment and write its plots and summary.json to its results "
        "folder.",
        epilog="experiments:\n" + experiment_help,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    exp.add_argument(
        "name",
        nargs="?",
        type=experiment_name,
        choices=EXPERIMENTS,
        metavar="NAME",
        help="the experiment, e.g. gradient-variance (listed below)",
    )
    exp.add_argument("--list", action="store_true", help="list the experiments and exit")
    exp.add_argument(
        "--out", default=None, metavar="DIR", help="results folder (default: results/NAME)"
    )
    exp.add_argument("--test-size", action="store_true", help="the reduced size CI runs")
    exp.add_argument(
        "--set", action="append", default=[], dest="settings", metavar="KEY=VALUE",
        help="a setting of the experiment's Config (repeat for more; a dotted KEY such as "
        "settings.shac.actor_lr sets a field of a group of settings)",
    )  # fmt: skip
    exp.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_ray_options(
        exp, "run the estimators' rollouts on Ray actors (a local cluster on 127.0.0.1)"
    )

    tr = sub.add_parser(
        "train",
        help="train one policy on a locomotion task with a method of the registry",
        description="Train one run of a locomotion task (our plant, gymnasium's reward) with a "
        "method of the registry until it has stepped the budget of environment steps, printing "
        "its progress; write the policy file (policy.npz, which evaluate and replay read) and "
        "summary.json to the results folder.",
        epilog="examples:\n"
        "  drake-abs train hopper --method shac-abs --steps 200000\n"
        "  drake-abs train hopper --method fopg_episode_abs --set shac.envs=16 --seed 1\n"
        "  drake-abs train half-cheetah --method ars --set ars.directions=4\n"
        "settings (--set): the fields of drake_abs.tasks.training_runs.RunSettings, dotted for "
        "a group's\n(shac.actor_lr, ars.step_size); values are YAML. Defaults: the "
        "gym-locomotion experiment's.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    tr.add_argument(
        "task", type=task_argument, metavar="TASK",
        help="the locomotion task: hopper, half-cheetah, walker2d or ant",
    )  # fmt: skip
    tr.add_argument(
        "--method", type=train_method, required=True, metavar="M",
        help="the method, by its registry name: shac_abs, shac_exact, fopg_episode_abs, "
        "fopg_episode_exact, ars, sb3_ppo, sb3_sac or sb3_ars",
    )  # fmt: skip
    tr.add_argument(
        "--steps", type=positive_int("--steps", "200000"), default=None, metavar="N",
        help="the budget: environment steps (control periods) to train for (default: 1000000)",
    )  # fmt: skip
    tr.add_argument(
        "--seed", type=seed_number, default=0, metavar="S", help="the run's seed (default: 0)"
    )
    tr.add_argument(
        "--out", default=None, metavar="DIR",
        help="results folder (default: results/train-TASK-METHOD-seedS)",
    )  # fmt: skip
    tr.add_argument(
        "--set", action="append", default=[], dest="settings", metavar="KEY=VALUE",
        help="a setting of the run (repeat for more; a dotted KEY such as shac.actor_lr sets a "
        "field of a group of settings)",
    )  # fmt: skip
    tr.add_argument("--no-progress", action="store_true", help="no progress bar")

    rec = sub.add_parser(
        "record",
        help="record a scene's rollout as a self-contained HTML page",
        description="Roll a scene out from its initial state with zero actuation and write "
        "the Meshcat recording as one HTML page (open it in a browser, no server needed).",
    )
    rec.add_argument(
        "scene",
        type=scene_argument,
        metavar="SCENE",
        help="a scene YAML file, or a shipped scene such as box-push (see 'drake-abs list')",
    )
    rec.add_argument(
        "--steps",
        type=positive_int("--steps", "100"),
        default=100,
        metavar="N",
        help="time steps to simulate, a positive whole number (default: %(default)s)",
    )
    rec.add_argument(
        "--out", default=None, metavar="FILE", help="HTML file (default: results/SCENE.html)"
    )
    rep = sub.add_parser(
        "replay",
        help="replay a saved policy on our plant as a self-contained HTML page",
        description="Run a saved policy (written by save_policy, e.g. by the locomotion "
        "experiments) deterministically on our plant from the state its task's reset gives "
        "with the seed, and write the Meshcat recording as one HTML page (open it in a "
        "browser, no server needed). The episode ends where the task ends it (the Hopper "
        "falling) or after the steps.",
    )
    rep.add_argument(
        "policy",
        type=policy_argument,
        metavar="POLICY",
        help="a policy file (.npz: W, b or W0, b0, ..., obs_mean, obs_std) or a saved policy's "
        "JSON file (STEM.json, beside its STEM.npz)",
    )
    rep.add_argument(
        "--env", default=None, metavar="ID",
        help="a policy file's gymnasium environment, e.g. Hopper-v5 (default: the file's "
        "env_id)",
    )  # fmt: skip
    rep.add_argument(
        "--steps",
        type=positive_int("--steps", "1000"),
        default=None,
        metavar="N",
        help="time steps to run at most, a positive whole number (default: 1000, "
        "gymnasium's episode length)",
    )
    rep.add_argument(
        "--seed",
        type=seed_number,
        default=0,
        metavar="S",
        help="the reset seed: the start state, as gymnasium's reset(seed=S) (default: 0)",
    )
    rep.add_argument(
        "--out", default=None, metavar="FILE", help="HTML file (default: results/STEM.html)"
    )
    ev = sub.add_parser(
        "evaluate",
        help="score a policy file in MuJoCo's own gymnasium environment and on our plant",
        description="Score a policy file (.npz: W, b or W0, b0, ..., obs_mean, obs_std) in "
        "MuJoCo's own gymnasium environment at its defaults (gymnasium.make(ID)), one episode "
        "per reset seed 0 .. N-1, actions clipped to the action space, with the zero-action "
        "and random-action floors over the same seeds beside it; then on our plant (the task "
        "that models the environment, from the same reset states), where there is one.",
    )
    ev.add_argument(
        "policy", metavar="POLICY.npz",
        help="the policy file (docs/policy_files.md says what it holds)",
    )  # fmt: skip
    ev.add_argument(
        "--env", default=None, metavar="ID",
        help="the gymnasium environment, e.g. Hopper-v5 (default: the file's env_id)",
    )  # fmt: skip
    ev.add_argument(
        "--seeds", type=positive_int("--seeds", "10"), default=10, metavar="N",
        help="episodes, from reset seeds 0 .. N-1 (default: %(default)s)",
    )  # fmt: skip
    ev.add_argument(
        "--max-steps", type=positive_int("--max-steps", "1000"), default=1000, metavar="N",
        help="the most steps of an episode (default: %(default)s, the environments' own limit; "
        "fewer only for quick checks)",
    )  # fmt: skip
    ev.add_argument("--json", default=None, metavar="FILE", help="also write the record here")
    ev.add_argument("--no-plant", action="store_true", help="score in MuJoCo only")
    sweep = sub.add_parser(
        "sweep",
        help="run an experiment over seeds and settings, here or on a Ray cluster",
        description="Run one experiment for every combination of seeds and settings, each "
        "point in its own folder (points/NAME under the results folder), and gather the "
        "summaries into sweep.json, sweep.csv and sweep.png. Every point records what produced "
        "it: its whole Config, the drake-abs version and git commit, the versions of the "
        "libraries that compute the numbers. A point already done in the results folder is not "
        "computed again when its Config, the drake-abs version and those library versions all "
        "match (the commit alone does not count: --fresh recomputes everything); otherwise it "
        "is recomputed and the report says why. A point that fails is reported with its "
        "traceback and the others complete (the exit code is then 1). --check runs nothing: "
        "it lists every point as fresh (a run would reuse it), stale (with what differs), "
        "missing or unfinished, and exits 0 when every point is fresh, 1 otherwise.",
        epilog="examples:\n"
        "  drake-abs sweep gradient-variance --test-size --seeds 0 1 2 --set samples=8,16\n"
        "  drake-abs sweep gradient-variance --seeds 0 1 --set 'horizons=[10,50],[100]' --ray\n"
        "  drake-abs sweep ball-throw --set learning_rate=0.01,0.03 --address HEAD:6379\n"
        "values are YAML: 10, 1e-4, true, [10, 50] (a list is one value of a tuple setting);\n"
        "a setting's values are split on the commas outside brackets.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sweep.add_argument(
        "name", type=experiment_name, choices=EXPERIMENTS, metavar="NAME",
        help="the experiment, e.g. gradient-variance (see 'drake-abs list')",
    )  # fmt: skip
    sweep.add_argument(
        "--seeds", nargs="+", type=seed_number, default=None, metavar="S",
        help="seeds, e.g. 0 1 2 (for experiments with a seed setting; default: its own)",
    )  # fmt: skip
    sweep.add_argument(
        "--set", action="append", default=[], dest="settings", metavar="KEY=V1,V2",
        help="a setting of the experiment's Config and its values; repeat for more settings "
        "(every combination is run)",
    )  # fmt: skip
    sweep.add_argument("--test-size", action="store_true", help="start from the reduced size")
    sweep.add_argument(
        "--out", default=None, metavar="DIR", help="results folder (default: results/sweep-NAME)"
    )
    add_ray_options(sweep, "run the points as Ray tasks on a local cluster")
    sweep.add_argument(
        "--metric", default=None, metavar="KEY",
        help="the numeric column of sweep.csv to plot (default: the first that varies)",
    )  # fmt: skip
    redo = sweep.add_mutually_exclusive_group()
    redo.add_argument("--fresh", action="store_true", help="recompute every point (no resume)")
    redo.add_argument(
        "--check", action="store_true",
        help="run nothing: list every point as fresh, stale (and why), missing or unfinished; "
        "exit code 0 when all are fresh, 1 otherwise",
    )  # fmt: skip
    sweep.add_argument("--no-progress", action="store_true", help="no progress bars")
    parser.subcommands = {
        "demo": demo, "experiment": exp, "record": rec, "replay": rep, "sweep": sweep,
        "evaluate": ev, "train": tr,
    }  # fmt: skip

    sub.add_parser(
        "list",
        help="list the experiments and the shipped scenes",
        description="List the experiments (one line each) and the shipped scenes.",
    )
    sub.add_parser(
        "precompile",
        help="compile and cache the numba kernels (make does this)",
        description="Compile and cache the numba kernels once per install.",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "no_progress", False):
        from drake_abs.experiments.outputs import set_progress

        set_progress(False)
    if args.command == "list" or (args.command == "experiment" and args.list):
        print(listing())
        return 0
    if args.command == "precompile":
        from drake_abs.experiments.precompile import precompile

        print("compiling and caching the numba kernels (once per install)")
        total = sum(precompile().values())
        print(f"done in {total:.1f} s")
        return 0
    sub = parser.subcommands[args.command]
    if args.command == "record":
        _check_file(sub, "--out", args.out)
        from drake_abs.multibody.scene import Scene

        try:
            scene = Scene.load(args.scene)
        except (ValueError, OSError) as err:  # a malformed or unreadable scene file
            sub.error(f"argument SCENE: {err}")
        return _record(scene, args.steps, args.out)
    if args.command == "evaluate":
        _check_file(sub, "--json", args.json)
        return _evaluate(sub, args)
    if args.command == "replay":
        _check_file(sub, "--out", args.out)
        from drake_abs.tasks.published_policies import load_for_task
        from drake_abs.tasks.saved_policies import load_policy

        is_file = args.policy.endswith(".npz")
        if args.env is not None and not is_file:
            sub.error("argument --env: applies to a policy file (.npz); a saved policy "
                      "(STEM.json) names its task")  # fmt: skip
        try:
            saved = load_for_task(args.policy, env_id=args.env) if is_file else (
                load_policy(args.policy))  # fmt: skip
        except (ValueError, OSError) as err:  # not a policy, an unknown kind, a missing npz
            sub.error(f"argument POLICY: {err}")
        if saved.task is None:
            sub.error(
                f"argument POLICY: {args.policy!r} acts in no task, so there is no scene to "
                "replay it in: save it with its task (save_policy(..., task='hopper'))"
            )
        return _replay(saved, args.steps, args.seed, args.out)
    if args.command == "sweep":
        _check_folder(sub, args.out)
        return _run_sweep(sub, args)
    if args.command == "train":
        _check_folder(sub, args.out)
        if args.steps is None:
            from drake_abs.experiments.train import DEFAULT_STEPS

            args.steps = DEFAULT_STEPS
        return _train(sub, args)
    if args.command == "demo":
        _check_folder(sub, args.out)
        if args.duration is not None:
            from drake_abs.experiments.bouncing_ball import Config

            h = Config.time_step
            if args.duration < h:
                sub.error(
                    f"argument --duration: expected at least one time step ({h:g} s), "
                    f"got {args.duration:g}"
                )
        return _run_demo(Path(args.out), duration=args.duration, meshcat=not args.no_meshcat)
    if args.name is None:
        sub.error("the following arguments are required: NAME (see 'drake-abs list')")
    _check_folder(sub, args.out)
    on_ray = wants_ray(sub, args)
    out = None if args.out is None else Path(args.out)
    config = _configured(sub, args.name, args.settings, args.test_size)
    return _run_standard(args.name, out, test_size=args.test_size, ray=on_ray,
                         address=args.address, workers=args.workers, config=config)  # fmt: skip


def _configured(sub: argparse.ArgumentParser, name: str, settings: list[str], test_size: bool):
    """The experiment's Config (test size or full) with the ``--set KEY=VALUE`` settings
    applied, or None without any; a usage error (exit 2) naming a bad one."""
    if not settings:
        return None
    module = experiment_module(name)
    base = module.Config.test_size() if test_size else module.Config()
    return with_settings(sub, base, settings)


def with_settings(sub: argparse.ArgumentParser, base, settings: list[str]):
    """``base`` (a settings dataclass: an experiment's Config, a training run's settings) with
    the ``--set KEY=VALUE`` texts applied, each value read as YAML and checked against its field
    (a dotted KEY sets a field of a nested dataclass); a usage error (exit 2) of ``sub`` naming
    a bad one: an unknown key, a wrong type, a key given twice or with several values."""
    from drake_abs.experiments.sweep import GridError, parse_setting
    from drake_abs.parallel.overrides import apply_overrides

    values = {}
    try:
        for setting in settings:
            key, parsed = parse_setting(setting, base)
            if len(parsed) != 1 or key in values:
                raise GridError("--set", f"{setting!r}: give one value per setting, once "
                                "(a sweep runs several: drake-abs sweep)")  # fmt: skip
            values[key] = parsed[0]
        return apply_overrides(base, values)
    except (GridError, ValueError) as err:
        sub.error(f"argument --set: {err}")


if __name__ == "__main__":
    sys.exit(main())
