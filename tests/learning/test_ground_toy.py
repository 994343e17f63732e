"""The 1-D toy of Bianchini et al. (2022) on drake-abs's solver: the explicit model against its
closed form, every loss gradient against central differences, and Table 1's constants measured
from the implementation against their closed forms (and the paper's printed value where it
differs)."""

import numpy as np
import pytest

from drake_abs.learning import GroundToy
from drake_abs.learning.generalization import (
    PAPER_TABLE_1,
    generalization_bound,
    lipschitz_table,
    loss_lipschitz,
    measured_lipschitz,
    toy_bounds,
)

TOY = GroundToy()


def data(rng, n, theta=0.0, noise=0.05):
    z = theta + np.concatenate([rng.uniform(0, 0.15, n // 2), rng.uniform(0, 8, n - n // 2)])
    v = rng.uniform(-15, 15, n)
    return z, v, TOY.f(theta, z, v) + noise * rng.standard_normal(n)


def test_the_solver_reproduces_the_closed_form_model_and_its_derivative():
    rng = np.random.default_rng(0)
    z, v, _ = data(rng, 400)
    for theta in (-0.03, 0.0, 0.02):
        pred, dpred, ok = TOY.predict(theta, z, v)
        assert ok.all()
        np.testing.assert_allclose(pred, TOY.f(theta, z, v), rtol=1e-10, atol=1e-10)
        h = 1e-7
        fd = (TOY.f(theta + h, z, v) - TOY.f(theta - h, z, v)) / (2 * h)
        # away from the kink (|q| > 2h) the derivative is 1/dt in contact, 0 outside
        F, q = TOY.lcp(theta, z, v)
        away = np.abs(q[:, 0]) > 1e-5
        np.testing.assert_allclose(dpred[away], fd[away], atol=1e-6)
        assert set(np.round(dpred[away] * TOY.dt, 8)) <= {0.0, 1.0}


def test_a_smoothed_model_is_smooth_and_tends_to_the_exact_one():
    """At mu > 0 the prediction is smooth in theta (its derivative continuous across the
    contact threshold) and tends to eq. 7 as mu -> 0 (larger mu: smoother)."""
    z, v = np.array([0.05]), np.array([-5.0])
    thetas = np.linspace(0.0, 0.05, 2001)  # crosses the threshold q = 0 near theta = 0.025
    d = np.array([TOY.predict(t, z, v, mu=1e-4)[1][0] for t in thetas])
    assert np.abs(np.diff(d)).max() < 0.02 / TOY.dt
    errs = [np.abs(TOY.predict(0.02, z, v, mu=mu)[0] - TOY.f(0.02, z, v)).max()
            for mu in (1e-2, 1e-4, 1e-6)]  # fmt: skip
    assert errs[0] > errs[1] > errs[2]


@pytest.mark.parametrize("kind", ["explicit", "explicit_mu", "violation"])
def test_loss_gradients_match_central_differences(kind):
    rng = np.random.default_rng(1)
    z, v, y = data(rng, 200)

    def loss(theta):
        if kind == "explicit":
            return TOY.explicit_loss(theta, z, v, y)[:2]
        if kind == "explicit_mu":
            return TOY.explicit_loss(theta, z, v, y, mu=1e-3)[:2]
        r = TOY.violation_implicit_loss(theta, z, v, y, 0.25)
        return r.loss, r.grad[:, 0]

    h = 1e-7
    for theta in (-0.013, 0.004, 0.021):
        value, grad = loss(theta)
        fd = (loss(theta + h)[0] - loss(theta - h)[0]) / (2 * h)
        if kind == "explicit":  # the exact model has kinks: compare away from them
            F, q = TOY.lcp(theta, z, v)
            keep = np.abs(q[:, 0]) > 1e-5
            grad, fd = grad[keep], fd[keep]
        np.testing.assert_allclose(grad, fd, rtol=1e-4, atol=1e-6 * (1 + np.abs(fd).max()))


def test_naive_implicit_equals_explicit_with_shared_parameters():
    rng = np.random.default_rng(2)
    z, v, y = data(rng, 100)
    np.testing.assert_allclose(TOY.naive_implicit_loss(0.01, z, v, y)[0],
                               (y - TOY.f(0.01, z, v)) ** 2, rtol=1e-9, atol=1e-12)  # fmt: skip


def test_realizable_data_cost_nothing_and_penetrating_data_cost_1_over_eps():
    """Noise-free data at the true height: the violation loss is 0 for every eps (a realizable
    model keeps its global minimum), up to roundoff. With the ground 1 cm too high, the data
    that end a step on the true ground penetrate the model's, ``h >= neg(phi)^2 / 2`` whatever
    lam, so the loss grows like 1 / eps as eps -> 0: the violation loss does not tend to the
    prediction loss (which stays finite) on data the model cannot explain."""
    rng = np.random.default_rng(3)
    z, v, y = data(rng, 100, noise=0.0)
    for eps in (1e-6, 1e-2, 0.25, 10.0):  # 0 up to the gap's roundoff (1e-16 m) times lam / eps
        assert np.abs(TOY.violation_implicit_loss(0.0, z, v, y, eps).loss).max() < 1e-12 / eps
    losses = np.array([TOY.violation_implicit_loss(0.01, z, v, y, eps).loss.mean()
                       for eps in (1e-2, 1e-4, 1e-6)])  # fmt: skip
    assert losses[1] / losses[0] == pytest.approx(100, rel=0.05)
    assert losses[2] / losses[1] == pytest.approx(100, rel=0.05)
    explicit = TOY.explicit_loss(0.01, z, v, y)[0].mean()  # finite, independent of eps
    assert losses[0] < explicit < losses[2]


def test_the_violation_impulse_moves_with_theta_at_m2_over_2eps():
    """In the region lam > 0, phi > 0 the violation minimiser is m r - m^2 phi / (2 eps):
    d lam* / d theta = m^2 / (2 eps) (2 at eps = 1/4; the paper's Table 1 prints 1)."""
    z, v, y = np.array([0.01]), np.array([-3.0]), np.array([-1.0])
    for eps in (0.25, 0.5, 1.0):
        lam = [TOY.violation_implicit_loss(t, z, v, y, eps).lam[0, 0] for t in (-1e-4, 1e-4)]
        assert lam[0] > 0
        assert (lam[1] - lam[0]) / 2e-4 == pytest.approx(TOY.m**2 / (2 * eps), rel=1e-8)


def test_table_1_measured_from_the_implementation():
    eps = 0.25
    closed = lipschitz_table(TOY, eps)
    measured = measured_lipschitz(TOY, eps, np.random.default_rng(4), n=4000)
    for key, value in closed.items():
        assert measured[key] == pytest.approx(value, rel=2e-3, abs=1e-12), key
    differs = {k for k in closed if not np.isclose(closed[k], PAPER_TABLE_1[k], rtol=2e-3)}
    assert differs == {"L_lambda,theta^vimp"}
    assert closed["L_lambda,theta^vimp"] == 2 * PAPER_TABLE_1["L_lambda,theta^vimp"]


def test_loss_constants_follow_the_papers_closed_forms():
    """Eqs. 14-16 from eqs. 11-13 and the table."""
    eps = 0.25
    b = toy_bounds(TOY, eps)
    lip = loss_lipschitz(lipschitz_table(TOY, eps), b, eps)
    m, lm = TOY.m, TOY.lambda_max
    assert lip["vimp"] == pytest.approx((m * b.B_nimp + lm * (1 + m**2 / (2 * eps))) / eps)
    assert lip["nimp"] == pytest.approx(2 * b.B_nimp / TOY.dt)
    assert lip["exp"] == pytest.approx(2 * b.B_exp / TOY.dt)


def test_the_bound_falls_with_data_and_rises_with_confidence():
    n = np.array([10.0, 100.0, 1e4])
    b = generalization_bound(3.0, 1.0, 2.0, n, delta=0.05)
    assert np.all(np.diff(b) < 0)
    assert generalization_bound(3.0, 1.0, 2.0, 100, delta=1e-6) > b[1]
    with pytest.raises(ValueError, match="delta"):
        generalization_bound(3.0, 1.0, 2.0, 100, delta=1.0)
    with pytest.raises(ValueError, match="n must be"):
        generalization_bound(3.0, 1.0, 2.0, 0.5)
