"""The transfer check at the reduced size: policies trained on our plant, evaluated on it and in
gymnasium's own MuJoCo environments (defaults, and at our control period). The MuJoCo numbers
must be gymnasium's own (a rollout by hand with the same seeds gives the same returns), the
summary's numbers finite, the files written, a saved policy taken from a folder."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

from drake_abs.experiments.locomotion_transfer import (  # noqa: E402
    REFERENCE,
    SETTINGS,
    Config,
    report,
    run,
)
from drake_abs.policy.policies import LinearPolicy  # noqa: E402
from drake_abs.policy.saving import save_policy  # noqa: E402
from drake_abs.reference.gymnasium_mujoco import same_period_frame_skip  # noqa: E402
from drake_abs.tasks.locomotion import locomotion_task  # noqa: E402
from drake_abs.tasks.saved_policies import load_policy  # noqa: E402

ENV_IDS = {"hopper": "Hopper-v5", "half_cheetah": "HalfCheetah-v5"}


@pytest.fixture(scope="module")
def summary(tmp_path_factory):
    return run(Config.test_size(), tmp_path_factory.mktemp("transfer"))


def _by_hand(env_id, act, seeds, steps, frame_skip=None):
    """Returns and lengths of gymnasium's own episodes, stepped here."""
    options = {} if frame_skip is None else {"frame_skip": frame_skip}
    env = gymnasium.make(env_id, max_episode_steps=steps, **options)
    returns, lengths = [], []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        total, n = 0.0, 0
        while True:
            obs, r, terminated, truncated, _ = env.step(act(obs))
            total, n = total + r, n + 1
            if terminated or truncated:
                break
        returns.append(total)
        lengths.append(n)
    env.close()
    return returns, lengths


def _numbers(value):
    if isinstance(value, dict):
        for item in value.values():
            yield from _numbers(item)
    elif isinstance(value, list):
        for item in value:
            yield from _numbers(item)
    elif isinstance(value, int | float) and not isinstance(value, bool):
        yield value


def test_every_number_is_finite_and_every_setting_reported(summary):
    config = summary["config"]
    assert set(summary["tasks"]) == {"hopper", "half_cheetah"}
    for name, r in summary["tasks"].items():
        assert set(r["policies"]) == {f"{name}_fopg_abs", REFERENCE}
        for entry in r["policies"].values():
            assert set(entry["results"]) == set(SETTINGS)
            for stats in entry["results"].values():
                assert stats["episodes"] == len(config["seeds"])
                assert all(1 <= n <= config["steps"] for n in stats["lengths"])
                numbers = list(_numbers(stats))
                assert numbers and all(math.isfinite(v) for v in numbers)
            d = entry["differences"]
            for key in ("return", "reward_forward", "reward_survive", "seconds"):
                assert d["total"][key] == pytest.approx(d["time_step"][key] + d["simulator"][key])
    assert all(math.isfinite(v) for v in _numbers(summary["tasks"]))


def test_control_periods_are_read_from_the_models(summary):
    hop, cheetah = (summary["tasks"][n]["settings"] for n in ("hopper", "half_cheetah"))
    # our tasks act at gymnasium's control periods, so the same-period MuJoCo run is its default
    assert hop["ours"]["control_period"] == pytest.approx(0.008)
    assert cheetah["ours"]["control_period"] == pytest.approx(0.05)
    assert (hop["mujoco_default"]["frame_skip"], hop["mujoco_same_dt"]["frame_skip"]) == (4, 4)
    assert (cheetah["mujoco_default"]["frame_skip"], cheetah["mujoco_same_dt"]["frame_skip"]) == (
        5, 5,
    )  # fmt: skip
    assert hop["mujoco_same_dt"]["control_period"] == pytest.approx(0.008)
    assert hop["mujoco_default"]["control_period"] == pytest.approx(0.008)
    assert cheetah["mujoco_default"]["control_period"] == pytest.approx(0.05)
    with pytest.raises(ValueError, match="not a whole multiple"):
        same_period_frame_skip("Hopper-v5", 0.003)


@pytest.mark.parametrize("name", ["hopper", "half_cheetah"])
def test_mujoco_returns_are_gymnasiums_own(summary, name):
    """The zero action's returns in (b) and (c) are those of gymnasium's own rollouts of zeros
    with the same seeds (and differ from ours: another simulator)."""
    config, r = summary["config"], summary["tasks"][name]
    zero = r["policies"][REFERENCE]["results"]
    nu = {"hopper": 3, "half_cheetah": 6}[name]
    same_dt = r["settings"]["mujoco_same_dt"]["frame_skip"]
    for key, frame_skip in (("mujoco_default", None), ("mujoco_same_dt", same_dt)):
        returns, lengths = _by_hand(ENV_IDS[name], lambda obs: np.zeros(nu), config["seeds"],
                                    config["steps"], frame_skip)  # fmt: skip
        assert zero[key]["returns"] == pytest.approx(returns, rel=1e-12, abs=1e-12)
        assert zero[key]["lengths"] == lengths
    assert zero["ours"]["returns"] != pytest.approx(zero["mujoco_same_dt"]["returns"], rel=1e-3)


def test_files_are_written(summary):
    files = {k: Path(v) for k, v in summary["files"].items()}
    for key in ("summary", "table", "plot", "hopper_replay", "half_cheetah_replay"):
        assert files[key].is_file() and files[key].stat().st_size > 0, key
    assert json.loads(files["summary"].read_text())["files"] == summary["files"]
    rows = list(csv.DictReader(files["table"].open()))
    assert len(rows) == 2 * 2 * 3  # tasks x (trained, zero) x settings
    assert {row["setting"] for row in rows} == set(SETTINGS)
    html = files["hopper_replay"].read_text()
    assert "meshcat" in html.lower() and "http://localhost" not in html
    # the trained policies are saved with their config and load back into their task
    for name in ("hopper", "half_cheetah"):
        saved = load_policy(files["policies"] / f"{name}_fopg_abs.json")
        assert saved.task.name == name and saved.config["experiment"] == "locomotion-transfer"
    text = report(summary)
    assert "(b) MuJoCo, gymnasium defaults (8 ms)" in text and "why:" in text


def test_saved_policies_from_a_folder_act_on_gymnasiums_observation(tmp_path, rng):
    """A saved policy is evaluated, not retrained; in (b) it is the user's loop: gymnasium's
    observation into the saved inner policy."""
    task = locomotion_task("hopper")
    inner = LinearPolicy(task.n_obs, task.nu)
    theta = 0.02 * rng.standard_normal(inner.n_params)
    save_policy(tmp_path / "policies" / "mine", task.policy(inner), theta, task="hopper")
    save_policy(tmp_path / "policies" / "other_task", LinearPolicy(17, 6), np.zeros(108),
                task="half_cheetah")  # fmt: skip
    config = Config(tasks=("hopper",), policies=str(tmp_path / "policies"),
                    policy_pattern="mine*", seeds=(4,), steps=60, reference=False,
                    replay_steps=5)  # fmt: skip
    out = run(config, tmp_path / "out")
    (label,) = out["tasks"]["hopper"]["policies"]
    entry = out["tasks"]["hopper"]["policies"][label]
    assert label == "mine" and entry["source"] == "saved"
    assert not (tmp_path / "out" / "policies").exists()  # nothing trained
    returns, lengths = _by_hand("Hopper-v5", lambda obs: inner.act(theta, obs[None])[0], (4,), 60)
    assert entry["results"]["mujoco_default"]["returns"] == pytest.approx(returns, rel=1e-12)
    assert entry["results"]["mujoco_default"]["lengths"] == lengths


def test_bad_settings_are_named(tmp_path):
    with pytest.raises(ValueError, match="tasks must be among"):
        run(Config(tasks=("walker",)), tmp_path)
    with pytest.raises(ValueError, match="policies must be an existing folder"):
        run(Config(policies=str(tmp_path / "none")), tmp_path)
    with pytest.raises(ValueError, match="steps must be a whole number"):
        run(Config(steps=0), tmp_path)
    with pytest.raises(ValueError, match="smoothing must be one of"):
        run(Config(smoothing="soft"), tmp_path)
