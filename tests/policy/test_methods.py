"""The one method registry: names, labels, smoothing designs and estimators; bad names refused."""

import numpy as np
import pytest

from drake_abs import ContactAware, Exact, Fixed
from drake_abs.contact.lcs import LcsStepper
from drake_abs.policy.estimators import PolicyObjective, first_order, zeroth_order
from drake_abs.policy.methods import METHODS, SMOOTHINGS, Method, make_smoothing, method
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.tasks.point_mass import point_mass_lcs


def test_every_method_names_a_design_and_a_unique_label():
    labels = [m.label for m in METHODS.values()]
    assert len(set(labels)) == len(labels)
    assert all(m.smoothing in SMOOTHINGS for m in METHODS.values())
    trainers = {m.name for m in METHODS.values() if not m.estimates_gradient}
    assert trainers == {"ars", "mbpo", "shac_abs", "shac_exact", "fopg_episode_abs",
                        "fopg_episode_exact", "sb3_ppo", "sb3_sac", "sb3_ars"}  # fmt: skip


def test_smoothing_policies_of_each_design():
    assert isinstance(method("fopg_exact").make_smoothing(), Exact)
    abs_ = method("fopg_abs").make_smoothing(contact_aware=(1e-2, 0.05))
    assert isinstance(abs_, ContactAware) and abs_ == ContactAware(1e-2, 0.05)
    bs = method("fopg_bs_1e-2")
    assert bs.label == "FOPG mu = 1e-2" and bs.mu == 1e-2
    assert bs.make_smoothing(mu=5.0) == Fixed(1e-2)  # the name's mu, not the experiment's
    assert method("fopg_bs").make_smoothing(mu=5.0) == Fixed(5.0)


@pytest.mark.parametrize("bad", ["fopg_bs_x", "fopg_bs_-1", "FOPG-ABS", "sac", ""])
def test_unknown_names_are_refused_with_the_known_ones(bad):
    with pytest.raises(ValueError, match="known: .*fopg_abs"):
        method(bad)


def test_designs_need_their_numbers():
    with pytest.raises(ValueError, match="needs mu"):
        make_smoothing("bs")
    with pytest.raises(ValueError, match="contact_aware"):
        make_smoothing("abs")
    with pytest.raises(ValueError, match="smoothing must be one of"):
        Method("x", "X", "gaussian", "first_order")
    with pytest.raises(ValueError, match="estimator must be one of"):
        Method("x", "X", "exact", "adam")


def test_estimate_is_the_named_estimator():
    """The registry adds no arithmetic: the same seed gives the estimator's own numbers."""
    lcs = point_mass_lcs(1)
    obj = PolicyObjective(
        LcsStepper(lcs, Exact()), LinearPolicy(nx=2, nu=1),
        QuadraticReward(Q=np.eye(2), R=np.eye(1), x_goal=np.zeros(2)), np.array([1.0, 0.0]),
        20, 0.1,
    )  # fmt: skip
    theta = np.zeros(3)
    for name, direct in (("fopg_exact", first_order), ("zopg", zeroth_order)):
        a = method(name).estimate(obj, theta, np.random.default_rng(0), 8)
        b = direct(obj, theta, np.random.default_rng(0), 8)
        np.testing.assert_array_equal(a.grad, b.grad)
    with pytest.raises(ValueError, match="trainer"):
        method("ars").estimate(obj, theta, np.random.default_rng(0), 8)
