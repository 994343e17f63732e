"""``drake-abs train TASK --method M``: one training run of a locomotion task, its progress, its
policy file and summary (issue 35, item 4), with a tiny budget."""

import json

import numpy as np
import pytest

from drake_abs.experiments.cli import main
from drake_abs.experiments.train import base_settings, trainable_methods
from drake_abs.policy.policy_files import load_policy_file

TINY = [
    "--set",
    "shac.envs=2",
    "--set",
    "shac.episode_length=20",
    "--set",
    "shac.critic_hidden=[8]",
]


def test_train_writes_a_policy_file_and_a_summary_after_the_budget(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["train", "hopper", "--method", "fopg-episode-abs", "--steps", "200", "--seed", "3",
            "--out", str(out), "--no-progress", *TINY]  # fmt: skip
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "training FOPG-ABS (episodes) (fopg_episode_abs) on hopper, seed 3" in printed
    assert "200 / 200 env steps" in printed  # the progress lines reach the budget
    assert f"results written to {out}" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["task"] == "hopper" and summary["method"] == "fopg_episode_abs"
    assert summary["seed"] == 3 and summary["steps"] == 200
    assert summary["env_steps"] >= 200 and summary["iterations"] >= 1
    assert summary["settings"]["shac"]["envs"] == 2  # --set applied
    assert summary["settings"]["shac"]["actor_lr_decay_steps"] == 200  # decays over the budget
    file = load_policy_file(out / "policy.npz")
    assert file.metadata["method"] == "fopg_episode_abs" and file.metadata["seed"] == 3
    assert int(file.metadata["training_steps"]) == summary["env_steps"]
    action = file.output(np.zeros(file.n_obs))
    assert action.shape == (file.nu,) and np.all(np.isfinite(action))
    # what produced it: the command, the resolved settings, the versions
    record = json.loads((out / "provenance.json").read_text())
    assert record["command"].startswith("train hopper --method fopg_episode_abs --seed 3")
    assert record["config"] == record["config"] | summary["settings"]  # all of them, and more
    assert {"ars", "sb3_envs"} <= set(record["config"])  # the settings the method leaves unused
    assert record["drake_abs_version"] and record["dependencies"]["drake"]


def test_ars_starts_from_the_published_settings_of_the_task_and_set_changes_one():
    settings = base_settings("half_cheetah", "ars", 1000)
    assert settings.ars is not None and settings.ars.directions > 0
    assert base_settings("hopper", "shac_abs", 1000).ars is None
    assert "shac_abs" in trainable_methods() and "fopg_abs" not in trainable_methods()


@pytest.mark.parametrize(
    "argv, says",
    [
        (["train", "hoppr", "--method", "shac_abs"], "no task 'hoppr'"),
        (["train", "hopper", "--method", "fopg_abs"], "no trainable method 'fopg_abs'"),
        (["train", "hopper"], "--method"),
        (["train", "hopper", "--method", "ars", "--steps", "0"], "--steps"),
        (["train", "hopper", "--method", "shac_abs", "--set", "shac.nope=1"], "unknown setting"),
        (["train", "hopper", "--method", "shac_abs", "--set", "shac.envs=0"], "envs"),
        (["train", "hopper", "--method", "shac_abs", "--set", "policy=cnn"], "policy"),
    ],
)
def test_bad_arguments_are_usage_errors_naming_the_option(argv, says, capsys, tmp_path):
    with pytest.raises(SystemExit) as err:
        main([*argv, "--out", str(tmp_path / "never")])
    assert err.value.code == 2
    assert says in capsys.readouterr().err
    assert not (tmp_path / "never").exists()  # refused before anything ran


def test_the_help_names_every_trainable_method_and_task(capsys):
    from drake_abs.tasks.locomotion import TASKS

    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for name in trainable_methods():
        assert name in text, name
    for task in TASKS:
        assert task.replace("_", "-") in text, task
