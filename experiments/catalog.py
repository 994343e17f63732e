"""The experiments the command line and the sweeps know, by name: each one's module and a line
of description. Each module has ``Config`` (with a ``test_size()`` constructor), ``run(config=None,
out=None) -> dict`` and ``report(summary) -> str``; the demo is the bouncing ball with its own
options."""

from __future__ import annotations

import importlib
from types import ModuleType

#: Experiment name -> its module of drake_abs.experiments.
STANDARD_EXPERIMENTS: dict[str, str] = {
    "bouncing-ball": "bouncing_ball",
    "drake-comparison": "drake_comparison",
    "box-convergence": "box_convergence",
    "mpc-quadcopter": "mpc_quadcopter",
    "gradient-variance": "gradient_variance",
    "locomotion-variance": "locomotion_variance",
    "locomotion": "locomotion",
    "bias-return": "bias_return",
    "ball-throw": "ball_throw",
    "smoothing-vs-rs": "smoothing_vs_rs",
    "speed-accuracy": "speed_accuracy",
    "mujoco-comparison": "mujoco_comparison",
    "scene-recordings": "scene_recordings",
    "locomotion-transfer": "locomotion_transfer",
    "implicit-learning": "implicit_learning",
    "model-learning": "model_learning",
    "model-based-fopg": "model_based_fopg",
    "gym-locomotion": "gym_locomotion",
}
EXPERIMENTS = tuple(STANDARD_EXPERIMENTS)

#: Experiment name -> one plain line for ``drake-abs list`` and the help.
DESCRIPTIONS: dict[str, str] = {
    "bouncing-ball": "the bouncing ball: exact contact, BS and ABS (Zhang et al. 2023, Fig. 2)",
    "drake-comparison": "a pushed box and a dropped ball, ours beside Drake's SAP, Similar, Lagged",
    "box-convergence": "convergence of the frictional contact solver over a grid of box settings",
    "mpc-quadcopter": "gray-box tuning of a quadcopter MPC (Zuliani et al. 2025, Figs. 1 and 2)",
    "gradient-variance": "policy-gradient variance against horizon (Zhang et al. 2023, Fig. 3)",
    "locomotion-variance": "FOPG variance against unroll length, gymnasium's hopper, half-cheetah "
    "(Fig. 3)",
    "locomotion": "learning hopper and half-cheetah: FOPG-ABS against ARS, PIPPS, AoBG, MBPO, ... "
    "(Fig. 4)",
    "bias-return": "training with BS and ABS: return and gradient bias (Zhang et al. 2023, Fig. 5)",
    "ball-throw": "learning a throw with ZOPG, FOPG, FOPG-BS, FOPG-ABS (Zhang et al. 2023, 8.3)",
    "smoothing-vs-rs": "barrier against randomised smoothing (Zhang et al. 2023, Fig. 6)",
    "speed-accuracy": "cost against accuracy of every setting, ours and Drake's",
    "mujoco-comparison": "gymnasium's Hopper and HalfCheetah beside MuJoCo and Drake SAP",
    "scene-recordings": "robots and a pushed box recorded as Meshcat HTML pages",
    "locomotion-transfer": "policies trained on our plant run in gymnasium's MuJoCo Hopper and "
    "HalfCheetah",
    "implicit-learning": "learning a ground height: explicit, naive and violation implicit losses "
    "(Bianchini et al. 2022, Table 1, Figs. 1 and 3)",
    "model-learning": "our model's parameters learned from SAP and MuJoCo data, against a neural "
    "network: prediction error vs horizon and data size",
    "model-based-fopg": "Algorithm 2 in closed loop: model learned from MuJoCo's Hopper, FOPG-ABS "
    "in it, evaluated in MuJoCo",
    "gym-locomotion": "locomotion trained on our plant, scored in MuJoCo's own gymnasium v5 tasks "
    "(seeds, floors, policy files)",
}


def experiment_module(name: str) -> ModuleType:
    """The module of experiment ``name`` (a key of :data:`STANDARD_EXPERIMENTS`); ``ValueError``
    lists the known names."""
    if name not in STANDARD_EXPERIMENTS:
        raise ValueError(
            f"experiment must be one of {', '.join(STANDARD_EXPERIMENTS)}; got {name!r}"
        )
    return importlib.import_module(f"drake_abs.experiments.{STANDARD_EXPERIMENTS[name]}")
