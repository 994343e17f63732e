"""The violation-implicit loss (drake_abs.learning.violation): its inner minimum against brute
force and scipy, its gradient against central differences, its limits and its input checks."""

import numpy as np
import pytest
from scipy.optimize import minimize

from drake_abs.learning.violation import complementarity_violation, violation_loss


def objective(y, g0, D, phi, eps, lam):
    r = y - g0 - D @ lam
    return r @ r + complementarity_violation(phi[None], lam[None])[0] / eps


def random_problem(rng, B, ny, nl):
    y = rng.normal(size=(B, ny))
    g0 = rng.normal(size=(B, ny))
    D = rng.normal(size=(B, ny, nl))
    phi = rng.normal(size=(B, nl))
    return y, g0, D, phi


@pytest.mark.parametrize("eps", [1e-3, 0.25, 10.0])
def test_one_impulse_matches_a_brute_force_minimum(eps):
    rng = np.random.default_rng(0)
    y, g0, D, phi = random_problem(rng, 50, 2, 1)
    r = violation_loss(y, g0, D, phi, eps)
    assert r.converged.all()
    grid = np.linspace(-20, 20, 400001)  # vectorised over the grid, one data point at a time
    for b in range(50):
        res = (y[b][:, None] - g0[b][:, None] - D[b][:, :1] * grid[None]) ** 2
        h = 0.5 * min(phi[b, 0], 0) ** 2 + 0.5 * np.minimum(grid, 0) ** 2
        h = h + max(phi[b, 0], 0) * np.maximum(grid, 0)
        best = (res.sum(axis=0) + h / eps).min()
        assert r.loss[b] <= best + 1e-12
        assert r.loss[b] >= best - 1e-6 * (1 + best)


@pytest.mark.parametrize("nl", [2, 4])
def test_several_impulses_match_scipy(nl):
    """The objective is convex: scipy's minimum from many starts is not below ours."""
    rng = np.random.default_rng(nl)
    y, g0, D, phi = random_problem(rng, 20, 3, nl)
    eps = 0.25
    r = violation_loss(y, g0, D, phi, eps)
    assert r.converged.all()
    for b in range(20):
        fun = lambda lam, b=b: objective(y[b], g0[b], D[b], phi[b], eps, lam)  # noqa: E731
        best = min(minimize(fun, rng.normal(size=nl), method="Nelder-Mead",
                            options={"xatol": 1e-10, "fatol": 1e-14, "maxiter": 20000}).fun
                   for _ in range(5))  # fmt: skip
        assert r.loss[b] <= best + 1e-8
        np.testing.assert_allclose(fun(r.lam[b]), r.loss[b], rtol=1e-12, atol=1e-14)


def test_gradient_matches_central_differences():
    """theta moves g0, D and phi (smoothly); the envelope-theorem gradient against central
    differences of the loss."""
    rng = np.random.default_rng(3)
    B, ny, nl, T = 30, 3, 2, 4
    y, g0, D, phi = random_problem(rng, B, ny, nl)
    A0 = rng.normal(size=(B, ny, T))
    AD = rng.normal(size=(B, ny, nl, T)) * 0.3
    AP = rng.normal(size=(B, nl, T))

    def problem(theta):
        s = np.sin(theta)
        return (g0 + A0 @ s, D + AD @ s, phi + AP @ s,
                A0 * np.cos(theta), AD * np.cos(theta), AP * np.cos(theta))  # fmt: skip

    theta = rng.normal(size=T) * 0.1
    G0, DD, PH, dG0, dDD, dPH = problem(theta)
    r = violation_loss(y, G0, DD, PH, 0.25, dg0=dG0, dD=dDD, dphi=dPH)
    h = 1e-6
    for t in range(T):
        e = np.zeros(T)
        e[t] = h
        up = violation_loss(y, *problem(theta + e)[:3], 0.25).loss
        dn = violation_loss(y, *problem(theta - e)[:3], 0.25).loss
        np.testing.assert_allclose(r.grad[:, t], (up - dn) / (2 * h), rtol=1e-5, atol=1e-7)


def test_a_complementary_realizable_pair_has_zero_loss():
    """y = g0 + D lam with lam >= 0 complementary to phi >= 0: the loss is 0 at that lam."""
    D = np.array([[[1.0, 0.5], [0.0, 2.0]]])
    lam = np.array([0.7, 0.0])
    y = np.array([[0.1, -0.3]]) + D[0] @ lam
    phi = np.array([[0.0, 1.3]])
    r = violation_loss(y, np.array([[0.1, -0.3]]), D, phi, 0.25)
    assert r.loss[0] == pytest.approx(0.0, abs=1e-20)
    np.testing.assert_allclose(r.lam[0], lam, atol=1e-12)


def test_larger_eps_never_raises_the_loss():
    """Larger eps: looser complementarity, a smaller minimum (the violation term weighs less)."""
    rng = np.random.default_rng(5)
    y, g0, D, phi = random_problem(rng, 40, 2, 2)
    losses = [violation_loss(y, g0, D, phi, eps).loss for eps in (1e-3, 1e-2, 0.1, 1.0, 10.0)]
    assert all(np.all(a >= b - 1e-12) for a, b in zip(losses, losses[1:], strict=False))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"eps": 0.0}, "eps"),
        ({"eps": np.nan}, "eps"),
        ({"D": np.zeros((2, 3))}, "D must have shape"),
        ({"phi": np.zeros((2, 3))}, "phi must have shape"),
        ({"g0": np.zeros((3, 2))}, "y and g0"),
        ({"y": np.full((2, 2), np.inf)}, "y must be finite"),
    ],
)
def test_bad_input_is_refused_by_name(kwargs, match):
    args = {"y": np.zeros((2, 2)), "g0": np.zeros((2, 2)), "D": np.ones((2, 2, 1)),
            "phi": np.zeros((2, 1)), "eps": 0.25} | kwargs  # fmt: skip
    with pytest.raises(ValueError, match=match):
        violation_loss(**args)
