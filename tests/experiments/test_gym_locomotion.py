"""gym-locomotion at test size: a run trains, is scored in MuJoCo's own environment and on our
plant, ships its policy file, and resumes only what matches.

Checked: the final policy file's MuJoCo score is the record's (rescored independently through
the file); floors come from the same reset seeds; a finished run is reused, not retrained; a run
whose settings differ starts again; a run stopped by ``max_hours`` and continued gives the
numbers of an uninterrupted run (wall times aside)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

from drake_abs.experiments import gym_locomotion as g  # noqa: E402
from drake_abs.policy.policy_files import load_policy_file  # noqa: E402
from drake_abs.reference.gym_scoring import floors, score_policy  # noqa: E402


@pytest.fixture(scope="module")
def done(tmp_path_factory):
    out = tmp_path_factory.mktemp("gl")
    return out, g.run(g.Config.test_size(), out)


def _numbers(curve):
    return [{k: v for k, v in row.items() if k != "seconds"} for row in curve]


def test_outputs_and_the_shipped_policy_scores_what_the_record_says(done):
    out, summary = done
    cfg = g.Config.test_size()
    entry = summary["tasks"]["hopper"]
    assert set(entry["methods"]) == {"shac_abs", "ars"}
    r = entry["methods"]["shac_abs"]
    assert r["seeds_done"] == [0] and r["seeds_missing"] == []
    assert r["env_steps"][0] >= cfg.env_steps
    path = out / "policies" / "Hopper-v5" / "shac_abs" / "seed0.npz"
    file = load_policy_file(path)
    assert file.metadata["env_id"] == "Hopper-v5" and file.metadata["method"] == "shac_abs"
    again = score_policy(file.act, "Hopper-v5", seeds=range(cfg.score_seeds),
                         max_steps=cfg.episode_steps)  # fmt: skip
    assert again["mean"] == pytest.approx(r["mujoco_mean"], rel=0, abs=1e-12)
    f = floors("Hopper-v5", range(cfg.score_seeds), cfg.episode_steps)
    assert entry["floors"] == {"zero": f["zero"]["mean"], "random": f["random"]["mean"]}
    assert r["plant_mean"] is not None and np.isfinite(r["plant_mean"])
    record = json.loads((out / "runs/hopper/shac_abs/seed0/run.json").read_text())
    assert [row["env_steps_target"] for row in record["curve"]] == g.evaluation_schedule(cfg)
    assert isinstance(record["dropped_windows"], int) and record["dropped_windows"] >= 0
    for name in ("summary", "curves", "table", "return_hopper"):
        assert (out / summary["files"][name]).exists()
    assert "Hopper-v5" in g.report(summary)


def test_a_finished_run_is_reused_and_a_changed_one_restarts(done, monkeypatch):
    out, summary = done
    calls = []
    import drake_abs.tasks.training_runs as tr

    real = tr.start_run
    monkeypatch.setattr(tr, "start_run", lambda *a, **k: calls.append(a) or real(*a, **k))
    again = g.run(g.Config.test_size(), out)
    assert calls == []  # reused: same identity, status done
    assert again["tasks"] == summary["tasks"]
    changed = replace(g.Config.test_size(), env_steps=80)
    g.run(changed, out)
    assert len(calls) == 2  # another budget: new runs (both methods)


@pytest.mark.parametrize("method", ["shac_abs", "ars", "sb3_ppo"])
def test_a_stopped_run_continues_to_the_uninterrupted_numbers(tmp_path, method):
    if method.startswith("sb3_"):  # the library baselines: the `baselines` extra
        pytest.importorskip("stable_baselines3")
    cfg = g.Config.test_size()
    whole = g.train_one(cfg, "hopper", method, 0, tmp_path / "whole", None)
    folder = tmp_path / "parts"
    # a deadline already passed: the run stops after its first scoring, checkpointed
    assert g.train_one(cfg, "hopper", method, 0, folder, deadline=0.0) is None
    partial = json.loads((folder / "run.json").read_text())
    assert partial["status"] == "partial" and (folder / "checkpoint.pkl").exists()
    rest = g.train_one(cfg, "hopper", method, 0, folder, None)
    assert _numbers(rest["curve"]) == _numbers(whole["curve"])
    assert rest["mujoco"]["returns"] == whole["mujoco"]["returns"]
    assert not (folder / "checkpoint.pkl").exists()  # finished: only the policy stays


def test_bad_settings_are_named():
    with pytest.raises(ValueError, match="tasks must be among"):
        replace(g.Config.test_size(), tasks=("humanoid",)).check()
    with pytest.raises(ValueError, match="evaluations must be >= 2"):
        replace(g.Config.test_size(), evaluations=1).check()


def test_a_run_is_defined_by_the_settings_its_trainer_reads():
    cfg = g.Config.test_size()
    other = replace(cfg, settings=replace(cfg.settings, shac=replace(cfg.settings.shac, sigma=0.3)))
    assert g.run_identity(cfg, "hopper", "ars", 0) == g.run_identity(other, "hopper", "ars", 0)
    assert g.run_identity(cfg, "hopper", "shac_abs", 0) != g.run_identity(
        other, "hopper", "shac_abs", 0
    )
    assert g.run_identity(cfg, "hopper", "ars", 0) != g.run_identity(cfg, "hopper", "ars", 1)
    assert g.run_identity(cfg, "hopper", "ars", 0)["scene"] == g.scene_fingerprint("hopper")
    assert g.scene_fingerprint("hopper") != g.scene_fingerprint("walker2d")
    soft = replace(cfg, settings=replace(cfg.settings, contact="mujoco"))
    for method in ("shac_abs", "ars", "sb3_ppo"):  # every trainer reads the contact law
        assert g.run_identity(cfg, "hopper", method, 0) != g.run_identity(soft, "hopper", method, 0)
    with pytest.raises(ValueError, match="contact must be one of"):
        replace(cfg.settings, contact="soft")
    more = replace(cfg, settings=replace(cfg.settings, sb3_envs=4))
    assert g.run_identity(cfg, "hopper", "shac_abs", 0) == g.run_identity(
        more, "hopper", "shac_abs", 0
    )
    assert g.run_identity(cfg, "hopper", "sb3_ppo", 0) != g.run_identity(
        more, "hopper", "sb3_ppo", 0
    )
