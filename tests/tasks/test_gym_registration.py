"""gymnasium makes the locomotion environments with no registering call (issue 35, item 4): the
ids are registered by ``import drake_abs`` (string entry points: no Drake import), and
gymnasium's ``"module:id"`` form makes one from gymnasium alone. Each check runs in a fresh
process, as a user's script would."""

import subprocess
import sys

import pytest

pytest.importorskip("gymnasium")


def _run(code: str) -> str:
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def test_gymnasium_makes_the_hopper_from_a_fresh_process_with_no_registering_call():
    out = _run(
        "import gymnasium\n"
        "env = gymnasium.make('drake_abs:drake_abs/Hopper-v0')\n"
        "obs, info = env.reset(seed=0)\n"
        "obs, r, terminated, truncated, info = env.step(env.action_space.sample())\n"
        "print(type(env.unwrapped).__name__, obs.shape, env.spec.max_episode_steps)\n"
    )
    assert out.split() == ["DrakeAbsEnv", "(11,)", "1000"]


def test_importing_the_package_registers_the_ids_without_drake_or_the_env_module():
    out = _run(
        "import sys\n"
        "import drake_abs, gymnasium\n"
        "ids = sorted(i for i in gymnasium.registry if i.startswith('drake_abs/'))\n"
        "loaded = [m for m in sys.modules if m.startswith('pydrake')\n"
        "          or m == 'drake_abs.tasks.gym_env']\n"
        "assert not loaded, loaded\n"
        "env = gymnasium.make('drake_abs/Hopper-v0')\n"
        "print(*ids, type(env.unwrapped).__name__)\n"
    )
    assert out.split() == [
        "drake_abs/Ant-v0",
        "drake_abs/HalfCheetah-v0",
        "drake_abs/Hopper-v0",
        "drake_abs/Walker2d-v0",
        "DrakeAbsEnv",
    ]


def test_registering_again_is_harmless():
    import gymnasium

    from drake_abs.tasks import gym_registration

    before = {i: gymnasium.spec(i) for i in gym_registration.ENV_IDS}
    gym_registration.register_envs()
    assert {i: gymnasium.spec(i) for i in gym_registration.ENV_IDS} == before
    assert gym_registration.register_if_installed()
