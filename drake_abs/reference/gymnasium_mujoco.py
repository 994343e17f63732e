"""gymnasium's MuJoCo environments as gymnasium sets them up: their simulation settings (timestep,
frame skip, integrator), the frame skip of a given control period, and the states
``env.reset(seed=...)`` starts from, so that
:meth:`~drake_abs.reference.mujoco_plant.MujocoStepper.from_gymnasium` runs their episodes in
the engine from gymnasium's own initial states.

Needs gymnasium and MuJoCo (``pip install 'drake-abs[mujoco]'``), imported when called.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

__all__ = ["reset_states", "same_period_frame_skip"]


def same_period_frame_skip(env_id: str, time_step: float) -> dict:
    """gymnasium's MuJoCo settings of ``env_id`` and the ``frame_skip`` whose control period
    ``frame_skip * timestep`` equals ``time_step`` (s), the timestep read from the model.

    Returns ``{"timestep", "default_frame_skip", "default_period", "frame_skip",
    "integrator"}`` (s, s); ``ValueError`` when ``time_step`` is not a whole multiple of the
    timestep."""
    import gymnasium
    import mujoco

    env = gymnasium.make(env_id)
    try:
        model = env.unwrapped.model
        timestep = float(model.opt.timestep)
        default = int(env.unwrapped.frame_skip)
        integrator = mujoco.mjtIntegrator(model.opt.integrator).name.removeprefix("mjINT_")
        integrator = {"EULER": "Euler"}.get(integrator, integrator)
    finally:
        env.close()
    ratio = time_step / timestep
    skip = int(round(ratio))
    if skip < 1 or abs(ratio - skip) > 1e-9 * ratio:
        raise ValueError(
            f"time_step {time_step} s is not a whole multiple of {env_id}'s timestep {timestep} s"
        )
    return {"timestep": timestep, "default_frame_skip": default,
            "default_period": default * timestep, "frame_skip": skip,
            "integrator": integrator}  # fmt: skip


def reset_states(env_id: str, seeds: Iterable[int], **make_kwargs) -> np.ndarray:
    """(S, nq + nv + na) the MuJoCo states (qpos, qvel, act) gymnasium's ``env_id`` starts from
    after ``env.reset(seed=s)``, one row per seed (its reset noise, drawn by gymnasium);
    ``make_kwargs`` go to ``gymnasium.make``."""
    import gymnasium

    seeds = list(seeds)
    if not seeds or any(
        isinstance(s, bool) or not isinstance(s, int | np.integer) or s < 0 for s in seeds
    ):
        raise ValueError(f"seeds must be whole numbers >= 0, at least one; got {seeds!r}")
    env = gymnasium.make(env_id, disable_env_checker=True, **make_kwargs)
    try:
        out = []
        for seed in seeds:
            env.reset(seed=int(seed))
            data = env.unwrapped.data
            out.append(np.concatenate([data.qpos, data.qvel, data.act]))
    finally:
        env.close()
    return np.array(out)
