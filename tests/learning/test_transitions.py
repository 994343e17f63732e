"""The transitions container (drake_abs/learning/transitions.py): shapes and validation,
episodes, windows and splits, files, the error summary, and transitions made from an engine run
(episodes cut where they end, contact at either end of a step)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from drake_abs.contact.lcs import LcsStepper
from drake_abs.engine import open_loop
from drake_abs.learning.transitions import Transitions, error_summary
from drake_abs.tasks.point_mass import point_mass_lcs


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


# ------------------------------------------------------------------------ from an engine run


def test_from_trajectory_of_an_engine_run():
    lcs = point_mass_lcs()
    rng = np.random.default_rng(0)
    nx, nu = lcs.B.shape
    x0, u = rng.normal(size=(3, nx)), rng.normal(size=(3, 6, nu))
    run = open_loop(LcsStepper(lcs), x0, u, jacobians=False, on_unconverged="flag")
    data = Transitions.from_trajectory(run, source="lcs", time_step=0.1)
    assert (len(data), data.n_episodes, data.source, data.time_step) == (18, 3, "lcs", 0.1)
    assert data.contact is None
    np.testing.assert_array_equal(data.x.reshape(3, 6, -1), run.x[:, :-1])
    np.testing.assert_array_equal(data.x_next.reshape(3, 6, -1), run.x[:, 1:])
    np.testing.assert_array_equal(data.u.reshape(3, 6, -1), u)
    np.testing.assert_array_equal(data.episode, np.repeat(np.arange(3), 6))
    np.testing.assert_array_equal(data.t, np.tile(np.arange(6), 3))


def test_from_trajectory_ends_episodes_and_flags_contact():
    # state of rollout m at step t: (10 m + t, 0); u: the same with a minus sign
    x = np.stack([np.stack([[10.0 * m + t, 0.0] for t in range(5)]) for m in range(3)])
    run = SimpleNamespace(x=x, u=-x[:, :-1, :1])

    def terminated(states):  # rollout 0 ends on reaching t = 2, rollout 2 on t = 1
        return np.isin(states[:, 0], [2.0, 21.0])

    def in_contact(states):  # contact at rollout 0's t = 1 and rollout 1's t = 4
        return np.isin(states[:, 0], [1.0, 14.0])

    data = Transitions.from_trajectory(run, source="s", time_step=0.01, terminated=terminated,
                                       in_contact=in_contact)  # fmt: skip
    np.testing.assert_array_equal(data.episode, [0, 0, 1, 1, 1, 1, 2])
    np.testing.assert_array_equal(data.t, [0, 1, 0, 1, 2, 3, 0])
    np.testing.assert_array_equal(data.x[:, 0], [0, 1, 10, 11, 12, 13, 20])
    np.testing.assert_array_equal(data.x_next[:, 0], [1, 2, 11, 12, 13, 14, 21])
    np.testing.assert_array_equal(data.u[:, 0], -data.x[:, 0])
    # a step is in contact when either of its states is
    np.testing.assert_array_equal(data.contact, [1, 1, 0, 0, 0, 1, 0])
    with pytest.raises(ValueError, match="terminated"):
        Transitions.from_trajectory(run, source="s", time_step=0.01,
                                    terminated=lambda s: np.zeros(2, bool))  # fmt: skip
    with pytest.raises(ValueError, match="trajectory"):
        Transitions.from_trajectory(SimpleNamespace(x=x, u=x), source="s", time_step=0.01)
