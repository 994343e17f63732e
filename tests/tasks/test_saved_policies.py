"""Saved policies (drake_abs.policy.saving, drake_abs.tasks.saved_policies) and their replay
(drake_abs.diagrams.policy_replay, ``drake-abs replay``).

Round trips give identical actions (linear, MLP, and task policies of the Hopper's and the
HalfCheetah's observation); only known kinds are rebuilt; a deterministic episode on our plant is
the one DrakeAbsEnv steps from the same seed; the replay writes a self-contained Meshcat page of
that episode.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from pydrake.geometry import Meshcat, MeshcatParams

from drake_abs.diagrams.policy_replay import replay_policy_html
from drake_abs.experiments.cli import main
from drake_abs.policy.ars_v2 import NormalizedLinearPolicy
from drake_abs.policy.policies import LinearPolicy, MLPPolicy
from drake_abs.policy.saving import (
    FORMAT,
    POLICY_KINDS,
    load_policy,
    policy_paths,
    save_policy,
    saved_policy_files,
)
from drake_abs.tasks import saved_policies
from drake_abs.tasks.adapters import ObservationPolicy
from drake_abs.tasks.locomotion import locomotion_task


@pytest.fixture(scope="module")
def tasks():
    return {name: locomotion_task(name) for name in ("hopper", "half_cheetah")}


@pytest.fixture(scope="module")
def meshcat():
    return Meshcat(MeshcatParams(host="localhost"))


def _states(rng, nx, M=6):
    return rng.standard_normal((M, nx))


# ---------------------------------------------------------------------------------- round trips


@pytest.mark.parametrize(
    "policy",
    [
        LinearPolicy(4, 2),
        LinearPolicy(3, 2, bias=False, x_ref=(0.1, -0.2, 0.3)),
        MLPPolicy(5, 2, hidden=(4, 3), output_scale=0.5),
    ],
    ids=["linear", "linear-xref-nobias", "mlp"],
)
def test_round_trip_gives_identical_actions(policy, tmp_path, rng):
    theta = rng.standard_normal(policy.n_params)
    config = {"lr": np.float64(0.01), "hidden": (4, 3), "seeds": np.arange(3)}
    paths = save_policy(tmp_path / "sub" / "pi", policy, theta, config=config)
    assert paths == {"json": tmp_path / "sub" / "pi.json", "npz": tmp_path / "sub" / "pi.npz"}
    record = json.loads(paths["json"].read_text())
    assert record["format"] == FORMAT and record["kind"] == type(policy).__name__
    assert record["task"] is None and record["acts_on"] == "state"
    assert record["library"]["drake-abs"] and record["n_params"] == policy.n_params
    for path in (paths["json"], paths["npz"], tmp_path / "sub" / "pi"):  # any of the three
        saved = load_policy(path)
        assert saved.policy == policy and type(saved.policy) is type(policy)
        np.testing.assert_array_equal(saved.theta, theta)
        x = _states(rng, policy.nx)
        np.testing.assert_array_equal(saved.policy.act(saved.theta, x), policy.act(theta, x))
        assert saved.config == {"lr": 0.01, "hidden": [4, 3], "seeds": [0, 1, 2]}
        assert saved.task_name is None and saved.task is None


def test_array_fields_go_to_the_npz(tasks, tmp_path, rng):
    """ARS's policy of the full state carries its normaliser (mean, std) as arrays."""
    task = tasks["hopper"]
    policy = NormalizedLinearPolicy(
        task.nx, task.nu, mean=rng.standard_normal(task.nx), std=rng.uniform(0.5, 2, task.nx)
    )
    theta = rng.standard_normal(policy.n_params)
    paths = save_policy(tmp_path / "ars", policy, theta, task="hopper")
    record = json.loads(paths["json"].read_text())
    assert record["array_fields"] == ["mean", "std"] and "mean" not in record["fields"]
    assert record["acts_on"] == "state" and record["task"] == "hopper"
    with np.load(paths["npz"]) as arrays:
        np.testing.assert_array_equal(arrays["field:std"], policy.std)
    saved = saved_policies.load_policy(paths["json"], task=task)
    assert saved.policy is saved.inner and saved.task is task
    np.testing.assert_array_equal(saved.policy.mean, policy.mean)
    x = np.tile(task.x0, (4, 1)) + rng.standard_normal((4, task.nx))
    np.testing.assert_array_equal(saved.policy.act(saved.theta, x), policy.act(theta, x))
    with pytest.raises(ValueError, match="does not fit task 'half_cheetah'"):
        save_policy(tmp_path / "ars_hc", policy, theta, task="half_cheetah")
        saved_policies.load_policy(tmp_path / "ars_hc.json")


def test_stems_keep_their_dots(tmp_path, rng):
    policy = LinearPolicy(2, 1)
    paths = save_policy(tmp_path / "run.v1.json", policy, np.ones(3))
    assert paths["json"].name == "run.v1.json" and paths["npz"].name == "run.v1.npz"
    assert policy_paths(tmp_path / "run.v1") == (paths["json"], paths["npz"])


@pytest.mark.parametrize(
    ("name", "inner_of"),
    [
        ("hopper", lambda t: LinearPolicy(t.n_obs, t.nu)),
        ("half_cheetah", lambda t: MLPPolicy(t.n_obs, t.nu, hidden=(8,), output_scale=0.3)),
    ],
)
def test_task_policy_round_trip(name, inner_of, tasks, tmp_path, rng):
    task = tasks[name]
    inner = inner_of(task)
    theta = 0.1 * rng.standard_normal(inner.n_params)
    policy = task.policy(inner)
    save_policy(tmp_path / name, policy, theta, task=task, config={"method": "fopg"})
    record = json.loads((tmp_path / f"{name}.json").read_text())
    assert record["task"] == name and record["acts_on"] == "observation"
    assert record["fields"]["nx"] == task.n_obs  # the inner policy is what is saved

    saved = saved_policies.load_policy(tmp_path / f"{name}.json", task=task)
    assert isinstance(saved.policy, ObservationPolicy) and saved.task is task
    assert saved.inner == inner and saved.task_name == name
    assert saved.config == {"method": "fopg"}
    x = np.tile(task.x0, (5, 1)) + 0.3 * rng.standard_normal((5, task.nx))
    np.testing.assert_array_equal(saved.policy.act(saved.theta, x), policy.act(theta, x))
    # the observation map is the task's: the inner policy on gymnasium's observation agrees
    np.testing.assert_array_equal(
        saved.inner.act(saved.theta, task.observation(x)), policy.act(theta, x)
    )
    # without a task given, the loader builds it from the saved name
    built = saved_policies.load_policy(tmp_path / name)
    assert built.task.name == name and built.task is not task
    np.testing.assert_array_equal(built.policy.act(built.theta, x), policy.act(theta, x))


def test_task_policies_need_the_task(tasks, tmp_path):
    task = tasks["hopper"]
    policy = task.policy(LinearPolicy(task.n_obs, task.nu))
    theta = np.zeros(policy.n_params)
    with pytest.raises(ValueError, match="task is required"):
        save_policy(tmp_path / "p", policy, theta)
    with pytest.raises(ValueError, match="task's observation"):
        save_policy(tmp_path / "p", policy, theta, task=tasks["half_cheetah"])
    save_policy(tmp_path / "p", policy, theta, task="hopper")
    with pytest.raises(ValueError, match="saved_policies.load_policy"):
        load_policy(tmp_path / "p")  # the generic loader cannot build the observation
    with pytest.raises(ValueError, match="acts in task 'hopper'"):
        saved_policies.load_policy(tmp_path / "p", task=tasks["half_cheetah"])


# ------------------------------------------------------------------------------- refusals


def test_unknown_kind_is_refused_by_name(tmp_path):
    paths = save_policy(tmp_path / "p", LinearPolicy(2, 1), np.zeros(3))
    record = json.loads(paths["json"].read_text())
    record["kind"] = "os.system"
    paths["json"].write_text(json.dumps(record))
    with pytest.raises(ValueError, match=r"unknown policy kind 'os\.system'") as err:
        load_policy(paths["json"])
    assert "LinearPolicy" in str(err.value)  # says what is known
    assert "os.system" not in POLICY_KINDS


def test_bad_files_and_arguments_are_named(tmp_path, rng):
    policy = LinearPolicy(2, 1)
    with pytest.raises(ValueError, match="theta must have shape"):
        save_policy(tmp_path / "p", policy, np.zeros(4))
    with pytest.raises(ValueError, match="theta contains NaN"):
        save_policy(tmp_path / "p", policy, np.array([0.0, np.nan, 0.0]))
    with pytest.raises(ValueError, match="policy must be one of the known kinds"):
        save_policy(tmp_path / "p", object(), np.zeros(3))
    with pytest.raises(ValueError, match=r"config\[.f.\] must be JSON data"):
        save_policy(tmp_path / "p", policy, np.zeros(3), config={"f": object()})
    with pytest.raises(FileNotFoundError, match="no saved policy"):
        load_policy(tmp_path / "missing.json")

    paths = save_policy(tmp_path / "p", policy, np.zeros(3))
    record = json.loads(paths["json"].read_text())
    paths["json"].write_text(json.dumps({**record, "fields": {**record["fields"], "depth": 3}}))
    with pytest.raises(ValueError, match=r"no field\(s\) \['depth'\]"):
        load_policy(paths["json"])
    paths["json"].write_text(json.dumps({**record, "n_params": 3, "fields": {"nx": 5, "nu": 1}}))
    with pytest.raises(ValueError, match="theta must be finite with shape"):
        load_policy(paths["json"])  # the npz's theta is not the size of the policy named
    paths["json"].write_text(json.dumps({"kind": "LinearPolicy"}))
    with pytest.raises(ValueError, match="not a saved policy"):
        load_policy(paths["json"])
    paths["json"].write_text("{not json")
    with pytest.raises(ValueError, match="not a JSON file"):
        load_policy(paths["json"])


def test_saved_policy_files_lists_only_policies(tmp_path):
    save_policy(tmp_path / "b", LinearPolicy(2, 1), np.zeros(3))
    save_policy(tmp_path / "a", MLPPolicy(2, 1, hidden=(2,)), np.zeros(9))
    (tmp_path / "log.json").write_text(json.dumps({"rows": []}))
    (tmp_path / "broken.json").write_text("{")
    assert [p.name for p in saved_policy_files(tmp_path)] == ["a.json", "b.json"]
    assert [p.name for p in saved_policy_files(tmp_path, "b*")] == ["b.json"]
    with pytest.raises(ValueError, match="folder must be an existing folder"):
        saved_policy_files(tmp_path / "nowhere")


# ------------------------------------------------------------------------ episodes and replay


def test_episode_is_drake_abs_envs_from_the_same_seed(tasks, rng):
    from drake_abs.tasks.gym_env import DrakeAbsEnv

    task = tasks["hopper"]
    inner = LinearPolicy(task.n_obs, task.nu)
    theta = 0.05 * rng.standard_normal(inner.n_params)
    policy = task.policy(inner)
    episode = saved_policies.run_episode(
        task, policy, theta, saved_policies.reset_state(task, 3), 200
    )
    env = DrakeAbsEnv(task, max_episode_steps=200)
    obs, _ = env.reset(seed=3)
    states, rewards, terminated = [env.state], [], False
    while True:
        obs, r, terminated, truncated, _ = env.step(inner.act(theta, obs[None])[0])
        states.append(env.state)
        rewards.append(r)
        if terminated or truncated:
            break
    assert terminated and episode.terminated  # the hopper falls within 200 actions (1.6 s)
    np.testing.assert_array_equal(episode.states, np.array(states))
    np.testing.assert_array_equal(episode.rewards, np.array(rewards))
    assert episode.steps == len(rewards)
    assert episode.seconds == pytest.approx(task.dt * len(rewards))
    longer = saved_policies.run_episode(
        task, policy, theta, states[0], 200, stop_at_termination=False
    )
    assert longer.steps == 200 and longer.terminated
    np.testing.assert_array_equal(longer.states[: len(states)], episode.states)


def test_reset_state_is_gymnasiums():
    gymnasium = pytest.importorskip("gymnasium")
    pytest.importorskip("mujoco")
    task = locomotion_task("half_cheetah")
    env = gymnasium.make("HalfCheetah-v5")
    env.reset(seed=11)
    data = env.unwrapped.data
    np.testing.assert_array_equal(
        saved_policies.reset_state(task, 11), np.concatenate([data.qpos, data.qvel])
    )
    env.close()


def test_replay_writes_the_meshcat_page_of_the_episode(tasks, tmp_path, meshcat, rng):
    task = tasks["half_cheetah"]
    inner = LinearPolicy(task.n_obs, task.nu)
    theta = 0.05 * rng.standard_normal(inner.n_params)
    save_policy(tmp_path / "cheetah", task.policy(inner), theta, task="half_cheetah")
    saved = saved_policies.load_policy(tmp_path / "cheetah.json", task=task)
    replay = replay_policy_html(saved, tmp_path / "out" / "cheetah.html", steps=15, seed=2,
                                meshcat=meshcat)  # fmt: skip
    html = replay.path.read_text()
    assert replay.path == tmp_path / "out" / "cheetah.html"
    assert len(html) > 100_000 and "meshcat" in html.lower() and "<script" in html
    assert "http://localhost" not in html  # self-contained, plays offline
    expected = saved_policies.run_episode(
        task, saved.policy, theta, saved_policies.reset_state(task, 2), 15
    )
    np.testing.assert_array_equal(replay.episode.states, expected.states)
    assert replay.episode.steps == 15 and replay.task_name == "half_cheetah"
    # from the path, as the command line does (the task is built)
    again = replay_policy_html(tmp_path / "cheetah.json", tmp_path / "again.html", steps=15,
                               seed=2, meshcat=meshcat)  # fmt: skip
    np.testing.assert_array_equal(again.episode.states, expected.states)


def test_a_replay_draws_one_frame_per_action(tasks):
    from drake_abs.diagrams.policy_replay import replay_scene

    for task in tasks.values():  # 8 ms (one plant step) and 50 ms (five) per action
        scene = replay_scene(task)
        assert scene.time_step == pytest.approx(task.dt)
        assert scene.name == task.plant.scene.name


def test_replay_refuses_what_it_cannot_replay(tmp_path, meshcat):
    save_policy(tmp_path / "bare", LinearPolicy(2, 1), np.zeros(3))
    with pytest.raises(ValueError, match="acts in no task"):
        replay_policy_html(tmp_path / "bare.json", tmp_path / "x.html", meshcat=meshcat)
    with pytest.raises(ValueError, match="saved_or_path must be"):
        replay_policy_html(42, tmp_path / "x.html", meshcat=meshcat)
    assert not (tmp_path / "x.html").exists()


def test_replay_command(tasks, tmp_path, capsys):
    task = tasks["hopper"]
    inner = LinearPolicy(task.n_obs, task.nu)
    save_policy(tmp_path / "hop", task.policy(inner), np.zeros(inner.n_params), task="hopper")
    html = tmp_path / "hop.html"
    assert main(["replay", str(tmp_path / "hop.json"), "--steps", "5", "--out", str(html)]) == 0
    out = capsys.readouterr().out
    assert str(html.resolve()) in out and "5 steps" in out and html.is_file()

    record = json.loads((tmp_path / "hop.json").read_text())
    (tmp_path / "odd.json").write_text(json.dumps({**record, "kind": "Pickled"}))
    save_policy(tmp_path / "bare", LinearPolicy(2, 1), np.zeros(3))
    bad = [
        ([str(tmp_path / "nope.json")], "argument POLICY: no saved policy"),
        ([str(tmp_path / "odd.json")], "argument POLICY: unknown policy kind 'Pickled'"),
        ([str(tmp_path / "bare.json")], "argument POLICY:"),
        ([str(tmp_path / "hop.json"), "--steps", "0"], "argument --steps:"),
        ([str(tmp_path / "hop.json"), "--seed", "-2"], "argument --seed:"),
        ([str(tmp_path / "hop.json"), "--out", str(tmp_path)], "argument --out:"),
    ]
    for argv, message in bad:
        with pytest.raises(SystemExit) as exit_:
            main(["replay", *argv])
        assert exit_.value.code == 2, argv
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, (argv, err)
