"""The model-learning experiment's data (experiments/model_learning.py): episodes of our scenes
recorded in Drake's SAP twin and in MuJoCo (drake_abs/reference/scene_sources.py) by the engine,
from the experiment's seeded initial states under random and scripted inputs: layout, seeding,
gymnasium's reset noise and termination, and our exact model's one-step predictions on each
source: exact (to rounding) where the source has no contact and no joint near a limit and
MuJoCo integrates as we do, the errors in contact recorded, not asserted."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")
gymnasium = pytest.importorskip("gymnasium")

from drake_abs.engine import open_loop  # noqa: E402
from drake_abs.experiments import model_learning as ml  # noqa: E402
from drake_abs.learning.transitions import (  # noqa: E402
    Transitions,
    one_step_errors,
    one_step_predictions,
)
from drake_abs.multibody import build_scene_model  # noqa: E402
from drake_abs.policy.controls import episode_seed, uniform_inputs  # noqa: E402
from drake_abs.reference.scene_sources import drake_source, mujoco_source  # noqa: E402
from drake_abs.tasks.locomotion import GymLocomotionReward  # noqa: E402

EXACT = 1e-9  # one-step agreement where both models integrate the same smooth dynamics
MODELS = {scene: build_scene_model(scene) for scene in ml.SCENES}
STEPPERS = {scene: model.stepper() for scene, model in MODELS.items()}
HOPPER_ENDS = GymLocomotionReward.hopper(0.01).terminated  # gymnasium's unhealthy Hopper


def _record(scene, source, inputs, episodes, seed, *, terminated=None) -> Transitions:
    """``episodes`` episodes from the experiment's initial states of ``episode_seed(seed, e)``,
    under ``inputs(episode seed) -> (steps, nu)`` clipped at the effort limits, with the
    source's contact flags."""
    model, effort = MODELS[scene], STEPPERS[scene].effort
    src = drake_source(model) if source == "sap" else mujoco_source(model)
    seeds = [episode_seed(seed, e) for e in range(episodes)]
    u = np.clip(np.stack([inputs(s) for s in seeds]), -effort, effort)
    run = open_loop(src.stepper, ml.initial_states(model, seeds), u, jacobians=False)
    return Transitions.from_trajectory(
        run, source=src.name, time_step=src.time_step, in_contact=src.in_contact,
        terminated=terminated,
    )  # fmt: skip


def _random(scene, steps, seed):
    effort = STEPPERS[scene].effort
    return lambda s: uniform_inputs(steps, -effort, effort, seed=[seed, s])


def _scripted(scene, steps, seed):
    return lambda s: ml.scripted_inputs(MODELS[scene], steps, STEPPERS[scene].effort, [seed, s])


def _record_property(record_property, name: str, errors: dict) -> None:
    """Keep the one-step errors (pytest's junit properties, and printed with -s)."""
    parts = {k: errors[k] for k in ("all", "smooth", "free", "contact") if k in errors}
    record_property(name, parts)
    print(f"\n{name}: " + "; ".join(
        f"{k} n={v['n']} q {v['q_mean']:.2e}/{v['q_max']:.2e} v {v['v_mean']:.2e}/{v['v_max']:.2e}"
        for k, v in parts.items() if v["n"]
    ))  # fmt: skip


@pytest.fixture(scope="module")
def sap_box():
    return _record("box_push", "sap", lambda s: uniform_inputs(60, -12.0, 12.0, seed=[0, s]), 3, 0)


@pytest.fixture(scope="module")
def sap_hopper():
    return _record("gym_hopper", "sap", _scripted("gym_hopper", 100, 0), 3, 0)


def _check_layout(data: Transitions, scene: str, episodes: int, steps: int):
    model, effort = MODELS[scene], STEPPERS[scene].effort
    assert data.nx == model.x0.size and data.nu == model.contact_model.nu
    assert data.time_step == model.scene.time_step
    assert np.array_equal(data.episode_ids, np.arange(data.n_episodes))
    assert data.n_episodes == episodes and len(data) <= episodes * steps
    for e in data.episode_ids:
        rows = np.flatnonzero(data.episode == e)
        assert np.array_equal(data.t[rows], np.arange(rows.size))
        # an episode chains: each transition starts where the previous one ended
        assert np.array_equal(data.x[rows[1:]], data.x_next[rows[:-1]])
    assert np.all(data.u >= -effort) and np.all(data.u <= effort)
    assert data.contact is not None and data.contact.dtype == bool


def test_sap_layout_and_determinism(sap_box, sap_hopper):
    _check_layout(sap_box, "box_push", 3, 60)
    _check_layout(sap_hopper, "gym_hopper", 3, 100)
    assert len(sap_box) == 180 and len(sap_hopper) == 300  # no early ends
    assert sap_box.source == "drake-sap:box_push"
    inputs = lambda s: uniform_inputs(60, -12.0, 12.0, seed=[0, s])  # noqa: E731
    assert _record("box_push", "sap", inputs, 3, 0).equals(sap_box)
    other = _record("box_push", "sap", inputs, 3, 1)
    assert not np.array_equal(other.x[0], sap_box.x[0])
    # the box starts tilted and lifted, no corner below the ground
    x0 = sap_box.x[sap_box.t == 0]
    assert np.all(np.abs(x0[:, 2]) > 0) and np.all(x0[:, 1] > 0.1)
    assert sap_box.contact.any() and (~sap_box.contact).any()


def test_our_one_step_predictions_on_sap(sap_box, sap_hopper, record_property):
    """Away from contact and joint limits Drake's discrete step is ours (semi-implicit Euler,
    implicit joint damping, the same mass matrix with armature): agreement to rounding. In
    contact the models differ (compliant, regularised SAP against hard complementarity with
    speculative contacts): recorded, only checked finite and converged."""
    for name, data, scene in (("box", sap_box, "box_push"), ("hopper", sap_hopper, "gym_hopper")):
        e = one_step_errors(STEPPERS[scene], data)
        _record_property(record_property, f"sap_{name}", e)
        assert e["unconverged"] == 0
        assert e["smooth"]["n"] >= 20
        assert e["smooth"]["q_max"] < EXACT and e["smooth"]["v_max"] < EXACT
        assert np.all(np.isfinite(e["v_err"]))
        # contact is where the models part: larger errors on average
        assert e["contact"]["v_mean"] > 1e3 * e["smooth"]["v_mean"] + 1e-6


@pytest.fixture(scope="module")
def mujoco_hopper():
    return _record("gym_hopper", "mujoco", _random("gym_hopper", 100, 0), 4, 3,
                   terminated=HOPPER_ENDS)  # fmt: skip


def test_mujoco_hopper_layout_determinism_termination(mujoco_hopper):
    data = mujoco_hopper
    _check_layout(data, "gym_hopper", 4, 100)
    assert data.source == "mujoco-Hopper-v5:gym_hopper"
    again = _record("gym_hopper", "mujoco", _random("gym_hopper", 100, 0), 4, 3,
                    terminated=HOPPER_ENDS)  # fmt: skip
    assert again.equals(data)
    # gymnasium's healthy termination ends the random hopper's episodes: the last state of a
    # short episode is unhealthy (height <= 0.7 m or |pitch| >= 0.2 rad), the others healthy
    short = [e for e in data.episode_ids if np.sum(data.episode == e) < 100]
    assert short
    for e in short:
        rows = np.flatnonzero(data.episode == e)
        last = data.x_next[rows[-1]]
        assert last[1] <= 0.7 or abs(last[2]) >= 0.2
        assert not HOPPER_ENDS(data.x_next[rows[:-1]]).any()
    # the initial states are gymnasium's resets of the episodes' seeds
    env = gymnasium.make("Hopper-v5")
    for e in range(2):
        env.reset(seed=episode_seed(3, e))
        state = np.concatenate([env.unwrapped.data.qpos, env.unwrapped.data.qvel])
        np.testing.assert_array_equal(data.x[(data.episode == e) & (data.t == 0)][0], state)
    env.close()


def test_our_one_step_predictions_on_mujoco(mujoco_hopper, record_property):
    """gymnasium's environments as published: recorded (not asserted: soft contact, the
    Hopper's RK4 at 2 ms, the half-cheetah's joint springs)."""
    e = one_step_errors(STEPPERS["gym_hopper"], mujoco_hopper)
    _record_property(record_property, "mujoco_hopper", e)
    assert e["unconverged"] == 0 and np.all(np.isfinite(e["v_err"]))
    cheetah = _record("gym_half_cheetah", "mujoco", _scripted("gym_half_cheetah", 100, 0), 2, 0)
    _check_layout(cheetah, "gym_half_cheetah", 2, 100)
    assert len(cheetah) == 200
    e = one_step_errors(STEPPERS["gym_half_cheetah"], cheetah)
    _record_property(record_property, "mujoco_half_cheetah", e)
    assert np.all(np.isfinite(e["v_err"]))


def test_mujoco_box(record_property, sap_box):
    data = _record("box_push", "mujoco", _scripted("box_push", 60, 0), 3, 0)
    _check_layout(data, "box_push", 3, 60)
    assert len(data) == 180 and data.source == "mujoco:box_push"
    assert data.equals(_record("box_push", "mujoco", _scripted("box_push", 60, 0), 3, 0))
    # the same initial states as the SAP box of the same seed
    assert np.array_equal(data.x[data.t == 0], sap_box.x[sap_box.t == 0])
    e = one_step_errors(STEPPERS["box_push"], data)
    _record_property(record_property, "mujoco_box", e)
    assert e["free"]["n"] >= 10 and e["free"]["v_max"] < EXACT and e["free"]["q_max"] < EXACT
    # batched and one-by-one predictions agree for the box (no joint damping)
    batched, _ = one_step_predictions(STEPPERS["box_push"], data, batch=64)
    single, _ = one_step_predictions(STEPPERS["box_push"], data)
    assert np.allclose(batched, single, rtol=0, atol=1e-12)


def test_collect_random_and_scripted_episodes():
    config = ml.Config.test_size()
    model, effort = MODELS["gym_half_cheetah"], STEPPERS["gym_half_cheetah"].effort
    random_data, scripted = ml.collect(model, effort, "mujoco", config)
    episodes = max(config.train_episodes) + config.test_episodes
    for data in (random_data, scripted):
        _check_layout_no_contact(data, episodes, config.steps, effort)
    assert random_data.source == scripted.source == "mujoco-HalfCheetah-v5:gym_half_cheetah"
    # random inputs fill the effort range; the gait swings each motor at half its effort
    assert np.all(np.abs(random_data.u).max(axis=0) > 0.5 * effort)
    assert np.all(np.abs(scripted.u) <= 0.5 * effort + 1e-12)
    assert not np.array_equal(random_data.x[0], scripted.x[0])  # seeded apart


def _check_layout_no_contact(data, episodes, steps, effort):
    assert data.n_episodes == episodes and len(data) == episodes * steps
    assert data.contact is None and np.all(np.abs(data.u) <= effort)
