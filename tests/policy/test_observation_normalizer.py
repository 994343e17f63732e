"""Observation normalisation (drake_abs.policy.observation_normalizer): the running statistics
equal numpy's over everything pushed, survive a round trip through their state, and the
normalised policy's products match central differences."""

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs.policy import ars_v2
from drake_abs.policy.observation_normalizer import NormalizedPolicy, RunningMeanStd
from drake_abs.policy.policies import LinearPolicy, MLPPolicy


def test_running_statistics_equal_numpys_over_all_rows():
    rng = np.random.default_rng(0)
    stats = RunningMeanStd(4)
    np.testing.assert_array_equal(stats.mean, 0.0)
    np.testing.assert_array_equal(stats.std, 1.0)
    rows = [rng.normal(3.0, [0.1, 1.0, 5.0, 1e-3], size=(n, 4)) for n in (1, 7, 0, 50, 3)]
    for r in rows:
        stats.push(r)
    everything = np.concatenate(rows)
    assert stats.count == len(everything)
    np.testing.assert_allclose(stats.mean, everything.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(stats.std, everything.std(axis=0), rtol=1e-10)
    np.testing.assert_array_equal(stats.floored_std(0.01), np.maximum(stats.std, 0.01))
    assert ars_v2.RunningMeanStd is RunningMeanStd  # ARS keeps its name for the same class


def test_state_round_trip_is_bit_identical():
    rng = np.random.default_rng(1)
    stats = RunningMeanStd(3)
    stats.push(rng.standard_normal((9, 3)))
    copy = RunningMeanStd.from_state(stats.state())
    more = rng.standard_normal((5, 3))
    stats.push(more)
    copy.push(more)
    np.testing.assert_array_equal(copy.mean, stats.mean)
    np.testing.assert_array_equal(copy.std, stats.std)
    assert copy.count == stats.count


@pytest.mark.parametrize("inner", [LinearPolicy(3, 2), MLPPolicy(3, 2, (4,))])
def test_normalized_policy_products_against_central_differences(inner):
    rng = np.random.default_rng(2)
    mean, std = rng.standard_normal(3), 0.2 + rng.random(3)
    pol = NormalizedPolicy(inner, mean, std)
    theta = rng.standard_normal(inner.n_params)
    o = rng.standard_normal((5, 3))
    np.testing.assert_allclose(pol.act(theta, o), inner.act(theta, (o - mean) / std), rtol=1e-14)
    du_dx, du_dth = pol.jacobians(theta, o)
    g_u = rng.standard_normal((5, 2))
    g_x, g_th = pol.vjp(theta, o, g_u)
    np.testing.assert_allclose(g_x, np.einsum("mi,mij->mj", g_u, du_dx), rtol=1e-12)
    np.testing.assert_allclose(g_th, np.einsum("mi,mij->mj", g_u, du_dth), rtol=1e-12)
    for m in range(5):
        fd_x = central_difference(lambda oo, m=m: pol.act(theta, oo[None])[0], o[m])
        np.testing.assert_allclose(du_dx[m], fd_x, rtol=1e-6, atol=1e-9)
    fd_th = central_difference(lambda th: pol.act(th, o).reshape(-1), theta).reshape(5, 2, -1)
    np.testing.assert_allclose(du_dth, fd_th, rtol=1e-6, atol=1e-9)


def test_bad_statistics_are_refused():
    with pytest.raises(ValueError, match="std"):
        NormalizedPolicy(LinearPolicy(2, 1), np.zeros(2), np.array([1.0, 0.0]))
    with pytest.raises(ValueError, match="mean"):
        NormalizedPolicy(LinearPolicy(2, 1), np.zeros(3), np.ones(2))
    with pytest.raises(ValueError, match="min_std"):
        RunningMeanStd(2).floored_std(0.0)
    with pytest.raises(ValueError, match="states"):
        RunningMeanStd(2).push(np.zeros((3, 4)))
