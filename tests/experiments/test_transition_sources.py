"""Transition data from Drake's SAP and MuJoCo in our scenes' coordinates
(experiments/transition_sources.py) and its container (drake_abs/learning/transitions.py):
shapes and validation, episodes, windows and splits, seeding, and our exact model's one-step
predictions on each source: exact (to rounding) where the source has no contact and no joint
near a limit and MuJoCo integrates as we do, the errors in contact recorded, not asserted."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")
pytest.importorskip("gymnasium")

from drake_abs.experiments import transition_sources as ts  # noqa: E402
from drake_abs.learning.transitions import (  # noqa: E402
    Transitions,
    error_summary,
    one_step_predictions,
)

EXACT = 1e-9  # one-step agreement where both models integrate the same smooth dynamics


def _synthetic(lengths=(3, 5, 4), nx=4, nu=2, seed=0, contact=True) -> Transitions:
    rng = np.random.default_rng(seed)
    n = sum(lengths)
    episode = np.concatenate([np.full(k, e) for e, k in enumerate(lengths)])
    t = np.concatenate([np.arange(k) for k in lengths])
    return Transitions(
        x=rng.normal(size=(n, nx)), u=rng.normal(size=(n, nu)), x_next=rng.normal(size=(n, nx)),
        episode=episode, t=t, source="synthetic", time_step=0.01,
        contact=rng.random(n) < 0.5 if contact else None,
    )  # fmt: skip


def _record(record_property, name: str, errors: dict) -> None:
    """Keep the one-step errors (pytest's junit properties, and printed with -s)."""
    parts = {k: errors[k] for k in ("all", "smooth", "free", "contact") if k in errors}
    record_property(name, parts)
    print(f"\n{name}: " + "; ".join(
        f"{k} n={v['n']} q {v['q_mean']:.2e}/{v['q_max']:.2e} v {v['v_mean']:.2e}/{v['v_max']:.2e}"
        for k, v in parts.items() if v["n"]
    ))  # fmt: skip


# ---------------------------------------------------------------------------- the container


def test_validation_names_the_argument():
    good = _synthetic()
    n = len(good)
    base = dict(x=good.x, u=good.u, x_next=good.x_next, episode=good.episode, t=good.t,
                source="s", time_step=0.01)  # fmt: skip
    bad = {
        "x": np.zeros(n),
        "u": np.zeros((n + 1, 2)),
        "x_next": np.zeros((n, 5)),
        "episode": np.zeros(n - 1, int),
        "t": -np.ones(n, int),
        "time_step": 0.0,
        "contact": np.zeros(n + 2, bool),
    }
    for name, value in bad.items():
        with pytest.raises(ValueError, match=name):
            Transitions(**(base | {name: value}))
    with pytest.raises(ValueError, match="x_next contains NaN"):
        Transitions(**(base | {"x_next": np.full((n, 4), np.nan)}))
    with pytest.raises(ValueError, match="t must increase within an episode"):
        Transitions(**(base | {"t": np.zeros(n, int)}))
    # stored read-only copies; the caller's arrays untouched
    x = np.array(good.x)
    data = Transitions(**(base | {"x": x}))
    assert x.flags.writeable and not data.x.flags.writeable
    assert (data.nx, data.nu, data.n_episodes, len(data)) == (4, 2, 3, n)


def test_windows_stay_in_one_episode():
    data = _synthetic(lengths=(3, 5, 4))  # rows 0-2, 3-7, 8-11
    assert np.array_equal(data.windows(1), np.arange(12))
    assert np.array_equal(data.windows(3), [0, 3, 4, 5, 8, 9])
    assert np.array_equal(data.windows(5), [3])
    assert data.windows(6).size == 0 and data.windows(50).size == 0
    # a gap in t (a dropped step) breaks a window too
    cut = data.select(np.delete(np.arange(12), 5))  # episode 1 loses t = 2: t 0, 1, 3, 4
    assert np.array_equal(cut.windows(3), [0, 7, 8])
    assert np.array_equal(cut.windows(2), [0, 1, 3, 5, 7, 8, 9])
    with pytest.raises(ValueError, match="horizon"):
        data.windows(0)


def test_split_subset_concatenate_save_load(tmp_path):
    data = _synthetic(lengths=(3, 5, 4, 6, 2, 7))
    train, test = data.split(0.5, 7)
    assert set(train.episode_ids).isdisjoint(test.episode_ids)
    assert len(train) + len(test) == len(data) and train.n_episodes == 3
    again, _ = data.split(0.5, np.random.default_rng(7))
    assert again.equals(train)
    for bad in (0.0, 1.0, "a"):
        with pytest.raises(ValueError, match="fraction"):
            data.split(bad, 0)
    with pytest.raises(ValueError, match="at least 2 episodes"):
        _synthetic(lengths=(4,)).split(0.5, 0)
    # subset: whole episodes (the first ones, or random ones), the last cut to its first steps
    first = data.subset(10)
    assert len(first) == 10 and np.array_equal(first.episode, [0] * 3 + [1] * 5 + [2] * 2)
    assert np.array_equal(first.t[-2:], [0, 1])
    rand = data.subset(10, 3)
    assert len(rand) == 10 and rand.equals(data.subset(10, 3))
    counts = [np.sum(rand.episode == e) for e in rand.episode_ids]
    full = [np.sum(data.episode == e) for e in rand.episode_ids]
    assert counts[:-1] == full[:-1] and rand.windows(1).size == 10
    with pytest.raises(ValueError, match="n must be"):
        data.subset(len(data) + 1)
    # concatenate: episodes kept apart, source joined, contact kept only when all have it
    other = _synthetic(lengths=(2, 2), seed=1, contact=False)
    both = data.concatenate(other)
    assert len(both) == len(data) + 4 and both.n_episodes == 8 and both.contact is None
    assert Transitions.concatenate(data, data).source == "synthetic"
    with pytest.raises(ValueError, match="nx, nu"):
        data.concatenate(_synthetic(nx=3))
    for item in (data, other):
        loaded = Transitions.load(item.save(tmp_path / "d"))
        assert loaded.equals(item) and not loaded.x.flags.writeable


def test_error_summary_parts():
    data = _synthetic()
    pred = np.array(data.x_next)
    pred[0, 1] += 0.5  # a position error in row 0
    pred[1, 3] -= 2.0  # a velocity error in row 1
    s = error_summary(data, pred, nq=2)
    assert s["all"]["q_max"] == pytest.approx(0.5) and s["all"]["v_max"] == pytest.approx(2.0)
    assert s["free"]["n"] + s["contact"]["n"] == len(data)
    with pytest.raises(ValueError, match="x_pred"):
        error_summary(data, pred[:-1], nq=2)


# ------------------------------------------------------------------------------ policies


def test_policies_seeded_and_in_range():
    low, high = ts.control_range("gym_hopper")
    assert np.array_equal(high, [200.0, 200.0, 200.0]) and np.array_equal(low, -high)
    a, b = ts.random_policy(3, low, high, 5), ts.random_policy(3, low, high, 5)
    a.reset(11)
    b.reset(11)
    us = np.array([a(None, t) for t in range(50)])
    assert np.array_equal(us, [b(None, t) for t in range(50)])
    assert np.all(us >= low) and np.all(us <= high) and np.unique(us[:, 0]).size == 50
    gait = ts.scripted_policy("gym_half_cheetah", 2)
    gait.reset(1)
    first = [gait(None, t) for t in range(5)]
    gait.reset(1)
    assert np.array_equal(first, [gait(None, t) for t in range(5)])
    push = ts.scripted_policy("box_push", 0)
    assert push(None, 0).shape == (1,) and push(None, 35)[0] == 0.0  # between pulses
    K = np.full((3, 12), 0.1)
    linear = ts.feedback_policy(lambda x: K @ x, scale=high, low=low, high=high)
    assert np.allclose(linear(np.full(12, 1.0), 0), np.clip(200 * 1.2, -200, 200))


# -------------------------------------------------------------------------- Drake's SAP


@pytest.fixture(scope="module")
def sap_box():
    return ts.sap_transitions("box_push", ts.random_policy(1, -12.0, 12.0, 0), 3, 60, 0)


@pytest.fixture(scope="module")
def sap_hopper():
    return ts.sap_transitions("gym_hopper", ts.scripted_policy("gym_hopper", 0), 3, 100, 0)


def _check_layout(data: Transitions, scene: str, episodes: int, steps: int):
    model = ts.scene_model(scene)
    low, high = ts.control_range(scene)
    assert data.nx == model.x0.size and data.nu == model.contact_model.nu
    assert data.time_step == model.scene.time_step
    assert np.array_equal(data.episode_ids, np.arange(data.n_episodes))
    assert data.n_episodes == episodes and len(data) <= episodes * steps
    for e in data.episode_ids:
        rows = np.flatnonzero(data.episode == e)
        assert np.array_equal(data.t[rows], np.arange(rows.size))
        # an episode chains: each transition starts where the previous one ended
        assert np.array_equal(data.x[rows[1:]], data.x_next[rows[:-1]])
    assert np.all(data.u >= low) and np.all(data.u <= high)
    assert data.contact is not None and data.contact.dtype == bool


def test_sap_layout_and_determinism(sap_box, sap_hopper):
    _check_layout(sap_box, "box_push", 3, 60)
    _check_layout(sap_hopper, "gym_hopper", 3, 100)
    assert len(sap_box) == 180 and len(sap_hopper) == 300  # no early ends
    assert sap_box.source == "drake-sap:box_push"
    again = ts.sap_transitions("box_push", ts.random_policy(1, -12.0, 12.0, 0), 3, 60, 0)
    assert again.equals(sap_box)
    other = ts.sap_transitions("box_push", ts.random_policy(1, -12.0, 12.0, 0), 3, 60, 1)
    assert not np.array_equal(other.x[0], sap_box.x[0])
    # the box starts tilted and lifted, no corner below the ground
    x0 = sap_box.x[sap_box.t == 0]
    assert np.all(np.abs(x0[:, 2]) > 0) and np.all(x0[:, 1] > 0.1)
    assert sap_box.contact.any() and (~sap_box.contact).any()


def test_sap_twin_coordinates_are_ours():
    from drake_abs.reference.drake_twin import make_drake_twin

    for scene in ts.SCENES:
        twin = make_drake_twin(ts.scene_model(scene).scene, "sap")
        ts.check_drake_coordinates(twin.plant, scene)


def test_our_one_step_predictions_on_sap(sap_box, sap_hopper, record_property):
    """Away from contact and joint limits Drake's discrete step is ours (semi-implicit Euler,
    implicit joint damping, the same mass matrix with armature): agreement to rounding. In
    contact the models differ (compliant, regularised SAP against hard complementarity with
    speculative contacts): recorded, only checked finite and converged."""
    for name, data, scene in (("box", sap_box, "box_push"), ("hopper", sap_hopper, "gym_hopper")):
        e = ts.prediction_errors(data, scene)
        _record(record_property, f"sap_{name}", e)
        assert e["unconverged"] == 0
        assert e["smooth"]["n"] >= 20
        assert e["smooth"]["q_max"] < EXACT and e["smooth"]["v_max"] < EXACT
        assert np.all(np.isfinite(e["v_err"]))
        # contact is where the models part: larger errors on average
        assert e["contact"]["v_mean"] > 1e3 * e["smooth"]["v_mean"] + 1e-6


# -------------------------------------------------------------------------------- MuJoCo


@pytest.fixture(scope="module")
def mujoco_hopper():
    low, high = ts.control_range("gym_hopper")
    return ts.mujoco_transitions("gym_hopper", ts.random_policy(3, low, high, 0), 4, 100, 3)


def test_mujoco_hopper_layout_determinism_termination(mujoco_hopper, sap_hopper):
    data = mujoco_hopper
    _check_layout(data, "gym_hopper", 4, 100)
    assert data.source == "mujoco-Hopper-v5:gym_hopper"
    low, high = ts.control_range("gym_hopper")
    again = ts.mujoco_transitions("gym_hopper", ts.random_policy(3, low, high, 0), 4, 100, 3)
    assert again.equals(data)
    # gymnasium's healthy termination ends the random hopper's episodes: the last state of a
    # short episode is unhealthy (height <= 0.7 m or |pitch| >= 0.2 rad)
    short = [e for e in data.episode_ids if np.sum(data.episode == e) < 100]
    assert short
    for e in short:
        last = data.x_next[np.flatnonzero(data.episode == e)[-1]]
        assert last[1] <= 0.7 or abs(last[2]) >= 0.2
    # gymnasium's reset noise, drawn as our initial_state draws it: the SAP and MuJoCo episodes
    # of one seed start from the same states
    sap = ts.sap_transitions("gym_hopper", ts.scripted_policy("gym_hopper", 0), 2, 1, 3)
    assert np.array_equal(sap.x, data.x[data.t == 0][:2])


@pytest.mark.parametrize("scene", ["gym_hopper", "gym_half_cheetah"])
def test_mujoco_coordinates_match_ours_in_free_flight(scene, record_property):
    """High above the ground (no contact) with MuJoCo stepping as we do (semi-implicit Euler,
    one 10 ms step; the half-cheetah's joint springs, which our scene drops, off), our one-step
    prediction is MuJoCo's to rounding wherever no joint is near a limit: qpos, qvel map to our
    x entry by entry. gymnasium's own Hopper (RK4, 5 x 2 ms) differs by its integration only."""
    base = ts.scene_model(scene).x0.copy()
    base[1] += 5.0
    if scene == "gym_hopper":  # thigh and leg mid-range (their upper limits are 0)
        base[3:5] = -0.6
    low, high = ts.control_range(scene)
    policy = ts.random_policy(low.size, 0.1 * low, 0.1 * high, 4)
    env_options = {"terminate_when_unhealthy": False} if scene == "gym_hopper" else None
    same = {"integrator": "Euler", "timestep": 0.01, "springs": False}
    data = ts.mujoco_transitions(scene, policy, 2, 40, 4, initial_state_base=base,
                                 mujoco_options=same, env_options=env_options)  # fmt: skip
    assert not data.contact.any()
    e = ts.prediction_errors(data, scene)
    _record(record_property, f"mujoco_{scene}_euler_free", e)
    assert e["smooth"]["n"] >= 60
    assert e["smooth"]["q_max"] < EXACT and e["smooth"]["v_max"] < EXACT
    if scene == "gym_hopper":  # gymnasium's integrator: RK4 at 2 ms, O(h^2) apart from ours
        rk4 = ts.mujoco_transitions(scene, policy, 2, 40, 4, initial_state_base=base,
                                    env_options=env_options)  # fmt: skip
        e = ts.prediction_errors(rk4, scene)
        _record(record_property, "mujoco_hopper_rk4_free", e)
        assert 1e-5 < e["smooth"]["q_max"] < 2e-2


def test_our_one_step_predictions_on_mujoco(mujoco_hopper, record_property):
    """gymnasium's environments as published: recorded (not asserted: soft contact, the
    Hopper's RK4 at 2 ms, the half-cheetah's joint springs)."""
    e = ts.prediction_errors(mujoco_hopper, "gym_hopper")
    _record(record_property, "mujoco_hopper", e)
    assert e["unconverged"] == 0 and np.all(np.isfinite(e["v_err"]))
    cheetah = ts.mujoco_transitions("gym_half_cheetah", ts.scripted_policy("gym_half_cheetah", 0),
                                    2, 100, 0)  # fmt: skip
    _check_layout(cheetah, "gym_half_cheetah", 2, 100)
    assert len(cheetah) == 200  # HalfCheetah never terminates
    e = ts.prediction_errors(cheetah, "gym_half_cheetah")
    _record(record_property, "mujoco_half_cheetah", e)
    assert np.all(np.isfinite(e["v_err"]))


# --------------------------------------------------------------------------- the MuJoCo box


def test_box_mjcf_is_the_sdf_box():
    import mujoco

    model, substeps = ts.box_mujoco_model()
    assert substeps == 1 and model.opt.timestep == 0.01
    assert model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
    plant = ts.scene_model("box_push").plant
    box = plant.GetBodyByName("box")
    inertia = box.default_spatial_inertia()
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "box")
    assert model.body_mass[body] == pytest.approx(inertia.get_mass(), rel=1e-12)
    assert model.body_mass.sum() == pytest.approx(inertia.get_mass(), rel=1e-12)
    assert np.allclose(model.body_ipos[body], inertia.get_com(), atol=1e-12)
    rot = inertia.CalcRotationalInertia().CopyToFullMatrix3()
    assert np.allclose(np.diag(model.body_inertia[body]), rot, rtol=1e-9, atol=1e-12)
    assert np.allclose(model.body_iquat[body], [1, 0, 0, 0])
    # the scene's contact points, friction, joint order and actuator
    scene = ts.scene_model("box_push").scene
    points = np.array(scene.contacts[0].points, float)
    spheres = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"contact_{k}")
               for k in range(4)]  # fmt: skip
    assert np.allclose(model.geom_pos[spheres], points)
    assert np.allclose(model.geom_friction[spheres, 0], scene.contacts[0].friction)
    floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    assert model.geom_pos[floor, 2] == -model.geom_size[spheres[0], 0]  # touch at z = 0
    assert np.array_equal(ts.check_mujoco_coordinates(model, "box_push"), [1.0])


def test_mujoco_box(record_property, sap_box):
    policy = ts.scripted_policy("box_push", 0)
    data = ts.mujoco_transitions("box_push", policy, 3, 60, 0)
    _check_layout(data, "box_push", 3, 60)
    assert len(data) == 180 and data.source == "mujoco:box_push"
    assert data.equals(ts.mujoco_transitions("box_push", ts.scripted_policy("box_push", 0),
                                             3, 60, 0))  # fmt: skip
    # the same initial states as the SAP box of the same seed
    assert np.array_equal(data.x[data.t == 0], sap_box.x[sap_box.t == 0])
    e = ts.prediction_errors(data, "box_push")
    _record(record_property, "mujoco_box", e)
    assert e["free"]["n"] >= 10 and e["free"]["v_max"] < EXACT and e["free"]["q_max"] < EXACT
    # batched and one-by-one predictions agree for the box (no joint damping)
    batched, _ = one_step_predictions(ts.exact_stepper("box_push"), data, batch=64)
    single, _ = one_step_predictions(ts.exact_stepper("box_push"), data)
    assert np.allclose(batched, single, rtol=0, atol=1e-12)
