"""The ``drake-abs`` command line.

drake-abs demo [--out DIR] [--duration S] [--no-meshcat]
drake-abs experiment NAME [--out DIR] [--test-size]
drake-abs record SCENE [--steps N] [--out FILE]
drake-abs precompile
"""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

# Experiment name -> module of drake_abs.experiments. Each module has ``Config`` (with a
# ``test_size()`` constructor), ``run(config=None, out=None) -> dict`` and
# ``report(summary) -> str``. The demo is the bouncing ball with its own options.
STANDARD_EXPERIMENTS: dict[str, str] = {
    "bouncing-ball": "bouncing_ball",
    "drake-comparison": "drake_comparison",
    "box-convergence": "box_convergence",
    "mpc-quadcopter": "mpc_quadcopter",
    "gradient-variance": "gradient_variance",
    "bias-return": "bias_return",
    "ball-throw": "ball_throw",
    "smoothing-vs-rs": "smoothing_vs_rs",
    "speed-accuracy": "speed_accuracy",
    "mujoco-comparison": "mujoco_comparison",
    "scene-recordings": "scene_recordings",
}
EXPERIMENTS = tuple(STANDARD_EXPERIMENTS)


def _run_demo(out: Path, *, duration: float | None, meshcat: bool) -> int:
    from drake_abs.experiments.bouncing_ball import Config, report, run

    kwargs = {"meshcat": meshcat}
    if duration is not None:
        kwargs["duration"] = duration
    print(report(run(Config(**kwargs), out)))
    print(f"results written to {out.resolve()}")
    return 0


def _run_standard(module_name: str, out: Path, *, test_size: bool) -> int:
    module = importlib.import_module(f"drake_abs.experiments.{module_name}")
    config = module.Config.test_size() if test_size else module.Config()
    print(module.report(module.run(config, out)))
    print(f"results written to {out.resolve()}")
    return 0


def _record(scene_arg: str, steps: int, out: str | None) -> int:
    from drake_abs.diagrams.scene_visualization import record_scene
    from drake_abs.multibody.builder import PACKAGE_DIR
    from drake_abs.multibody.scene import Scene

    path = Path(scene_arg)
    if not path.is_file():
        path = PACKAGE_DIR / "scenes" / f"{scene_arg}.yaml"
    if not path.is_file():
        shipped = sorted(p.stem for p in (PACKAGE_DIR / "scenes").glob("*.yaml"))
        print(f"no scene {scene_arg!r}: give a YAML file or one of {shipped}", file=sys.stderr)
        return 2
    scene = Scene.from_yaml(path)
    html = Path(out or f"results/{scene.name}.html")
    html.parent.mkdir(parents=True, exist_ok=True)
    record_scene(scene, steps, html)
    print(f"recorded {steps} steps of {scene.name} (Meshcat, localhost) to {html.resolve()}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="drake-abs", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="the bouncing-ball demo (Zhang et al. 2023, Figure 2)")
    demo.add_argument("--out", default="results/demo", help="results folder (default: %(default)s)")
    demo.add_argument("--duration", type=float, default=None, help="simulated seconds")
    demo.add_argument("--no-meshcat", action="store_true", help="skip the Meshcat HTML recording")
    exp = sub.add_parser("experiment", help="reproduce one of the papers' experiments")
    exp.add_argument("name", choices=EXPERIMENTS)
    exp.add_argument("--out", default=None, help="results folder (default: results/NAME)")
    exp.add_argument("--test-size", action="store_true", help="the reduced size CI runs")
    rec = sub.add_parser("record", help="record a scene's rollout as a self-contained HTML page")
    rec.add_argument("scene", help="a scene YAML, or the name of a shipped scene (e.g. box_push)")
    rec.add_argument("--steps", type=int, default=100)
    rec.add_argument("--out", default=None, help="HTML file (default: results/SCENE.html)")
    sub.add_parser("precompile", help="compile and cache the numba kernels (make does this)")
    args = parser.parse_args(argv)
    if args.command == "precompile":
        from drake_abs.experiments.precompile import precompile

        print("compiling and caching the numba kernels (once per install)")
        total = sum(precompile().values())
        print(f"done in {total:.1f} s")
        return 0
    if args.command == "record":
        return _record(args.scene, args.steps, args.out)
    if args.command == "demo":
        return _run_demo(Path(args.out), duration=args.duration, meshcat=not args.no_meshcat)
    out = Path(args.out or f"results/{args.name}")
    return _run_standard(STANDARD_EXPERIMENTS[args.name], out, test_size=args.test_size)


if __name__ == "__main__":
    sys.exit(main())
