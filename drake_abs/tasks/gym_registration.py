"""The gymnasium ids of the locomotion tasks (``drake_abs/Hopper-v0``, ...), registered with string
entry points, so that registering imports neither Drake nor :mod:`drake_abs.tasks.gym_env`:
``gymnasium.make`` imports the environment class only when an environment is made.

gymnasium 1.x has no plugin mechanism (0.x loaded the ``gymnasium.envs`` entry-point group at
import; 1.0 removed it), so the ids are registered by importing this package:
``import drake_abs`` registers them when gymnasium is installed (:func:`register_if_installed`),
and ``gymnasium.make("drake_abs:drake_abs/Hopper-v0")`` does so from gymnasium alone (its
``"module:id"`` form imports the module first).
"""

from __future__ import annotations

import importlib.util

__all__ = ["ENTRY_POINT", "ENV_IDS", "MAX_EPISODE_STEPS", "register_envs", "register_if_installed"]

#: gymnasium id -> the locomotion task it makes
#: (:func:`drake_abs.tasks.locomotion.locomotion_task`).
ENV_IDS = {
    "drake_abs/Hopper-v0": "hopper",
    "drake_abs/HalfCheetah-v0": "half_cheetah",
    "drake_abs/Walker2d-v0": "walker2d",
    "drake_abs/Ant-v0": "ant",
}

#: The environment class of every id, as gymnasium's ``"module:attribute"`` text (imported by
#: ``gymnasium.make``, not here).
ENTRY_POINT = "drake_abs.tasks.gym_env:DrakeAbsEnv"

#: Steps after which ``gymnasium.make`` truncates an episode (its ``TimeLimit``), as gymnasium's
#: own v5 locomotion environments do.
MAX_EPISODE_STEPS = 1000


def register_envs() -> None:
    """Register :data:`ENV_IDS` with gymnasium (each a ``TimeLimit`` of
    :data:`MAX_EPISODE_STEPS` steps around :class:`~drake_abs.tasks.gym_env.DrakeAbsEnv`);
    registering again is harmless. Needs gymnasium (``ImportError`` without it)."""
    # the registry module itself, not the gymnasium package's attributes: it is complete as
    # soon as it is imported, even while the gymnasium package is still initialising
    from gymnasium.envs.registration import register, registry

    for env_id, task in ENV_IDS.items():
        if env_id in registry:
            continue
        register(
            env_id,
            entry_point=ENTRY_POINT,
            max_episode_steps=MAX_EPISODE_STEPS,
            kwargs={"task": task, "max_episode_steps": None},
        )


def register_if_installed() -> bool:
    """:func:`register_envs` if gymnasium is installed; return whether it was (what ``import
    drake_abs`` calls, so that ``gymnasium.make("drake_abs/Hopper-v0")`` needs no call)."""
    if importlib.util.find_spec("gymnasium") is None:
        return False
    register_envs()
    return True
