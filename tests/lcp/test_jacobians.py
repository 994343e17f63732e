"""Every Jacobian against central finite differences, and the Gaussian-matched identity against
numerical quadrature (docs/math.md sections 4 and 5b)."""

import numpy as np
import pytest
from numdiff import central_difference, random_p_matrix
from scipy import integrate
from scipy.special import ndtr

from drake_abs import (
    LCS,
    ContactAware,
    Exact,
    Fixed,
    GaussianMatched,
    LcsStepper,
    open_loop,
    point_mass_lcs,
    solve_lcp,
)
from drake_abs.lcp.sensitivity import dlam_dF

POLICIES = [
    Exact(),
    Fixed(1e-3),
    ContactAware(mu_max=1e-2, length=0.05, mu_min=1e-8),
    GaussianMatched(sigma=0.05),
    GaussianMatched(sigma=0.05, c1=0.1, c2=0.01),
]


@pytest.mark.parametrize("d", [1, 2, 3, 8])
@pytest.mark.parametrize("mu", [1e-6, 1e-3, 1e-1])
def test_solver_jacobians_match_finite_differences(d, mu, rng):
    F = random_p_matrix(rng, d)
    q = rng.normal(size=d)
    r = solve_lcp(F, q, mu, jacobians=True, strict=True)
    fd_q = central_difference(lambda qq: solve_lcp(F, qq, mu).lam, q, eps=1e-7)
    np.testing.assert_allclose(r.dlam_dq, fd_q, atol=1e-6 * (1 + np.abs(fd_q).max()))
    # scalar mu: dlam_dmu is (d,)
    fd_mu = central_difference(lambda m: solve_lcp(F, q, m[0]).lam, [mu], eps=1e-4 * mu)[:, 0]
    np.testing.assert_allclose(r.dlam_dmu, fd_mu, rtol=1e-5, atol=1e-8)
    # per-contact mu: dlam_dmu is (d, d)
    mus = mu * (1 + rng.uniform(size=d))
    rc = solve_lcp(F, q, mus, jacobians=True, strict=True)
    eps = 1e-3 * mu
    fd_mus = central_difference(lambda m: solve_lcp(F, q, m).lam, mus, eps=eps)
    # FD error: truncation ~ (eps/mu)^2 relative, roundoff ~ 1e-15 |lam| / eps absolute
    fd_err = 1e-6 * np.abs(fd_mus).max() + 1e-15 * np.abs(rc.lam).max() / eps
    np.testing.assert_allclose(rc.dlam_dmu, fd_mus, rtol=1e-5, atol=fd_err)
    # d lam / d F
    fd_F = central_difference(lambda f: solve_lcp(f.reshape(d, d), q, mu).lam, F.ravel(), 1e-7)
    np.testing.assert_allclose(
        dlam_dF(r.dlam_dq, r.lam).reshape(d, d * d), fd_F, atol=1e-6 * (1 + np.abs(fd_F).max())
    )


def test_batched_per_problem_mu_jacobian_shapes(rng):
    F = random_p_matrix(rng, 3)
    q = rng.normal(size=(5, 3))
    r = solve_lcp(F, q, np.logspace(-4, 0, 5), jacobians=True)
    assert r.dlam_dq.shape == (5, 3, 3) and r.dlam_dmu.shape == (5, 3)
    r = solve_lcp(np.stack([F] * 5), q, np.full((5, 3), 0.1), jacobians=True)
    assert r.dlam_dq.shape == (5, 3, 3) and r.dlam_dmu.shape == (5, 3, 3)


def random_lcs(rng, nx=5, nu=2, nc=3):
    return LCS(
        A=np.eye(nx) + 0.1 * rng.normal(size=(nx, nx)),
        B=rng.normal(size=(nx, nu)),
        C=rng.normal(size=(nx, nc)),
        c=rng.normal(size=nx),
        D=rng.normal(size=(nc, nx)),
        E=rng.normal(size=(nc, nu)),
        F=random_p_matrix(rng, nc),
        d=0.1 * rng.normal(size=nc),
    )


@pytest.mark.parametrize("policy", POLICIES, ids=repr)
@pytest.mark.parametrize("gradient", ["frozen", "total"])
def test_lcs_step_jacobians_match_finite_differences(policy, gradient, rng):
    systems = [(point_mass_lcs(2, time_step=0.01), 4, 2), (random_lcs(rng), 5, 2)]
    for lcs, nx, nu in systems:
        for _ in range(4):
            x = rng.normal(size=nx) * 0.05
            u = rng.normal(size=nu)
            r = lcs.step(x, u, policy, gradient=gradient, strict=True)
            if gradient == "frozen":
                mu = r.lcp.mu_target[0]  # hold mu at this step's value

                def f(xx, uu, mu=mu, lcs=lcs):
                    z = lcs.contact_distance(xx[None], uu[None])[0]
                    lam = solve_lcp(lcs.F, z, mu).lam
                    return lcs.A @ xx + lcs.B @ uu + lcs.C @ lam + lcs.c
            else:

                def f(xx, uu, lcs=lcs):
                    return lcs.step(xx, uu, policy, jacobians=False).x_next

            Jx = central_difference(lambda xx, uu=u: f(xx, uu), x, eps=1e-7)
            Ju = central_difference(lambda uu, xx=x: f(xx, uu), u, eps=1e-7)
            scale = 1 + max(np.abs(Jx).max(), np.abs(Ju).max())
            np.testing.assert_allclose(r.dx_dx, Jx, atol=2e-6 * scale)
            np.testing.assert_allclose(r.dx_du, Ju, atol=2e-6 * scale)


@pytest.mark.parametrize("policy", POLICIES[1:], ids=repr)
def test_policy_dmu_dz_matches_finite_differences(policy, rng):
    F = random_p_matrix(rng, 3)
    for _ in range(5):
        z = rng.normal(size=(1, 3)) * 0.05
        fd = central_difference(lambda zz: policy.mu(zz[None], F)[0], z[0], eps=1e-8)
        np.testing.assert_allclose(policy.dmu_dz(z, F)[0], fd, rtol=1e-5, atol=1e-9)


@pytest.mark.parametrize("sigma", [0.01, 0.3])
@pytest.mark.parametrize("F", [0.05, 1.0, 20.0])
def test_gaussian_matched_equals_gaussian_smoothed_exact_solution(sigma, F):
    policy = GaussianMatched(sigma=sigma)
    z = np.linspace(-4 * sigma, 4 * sigma, 17)
    Fm = np.array([[F]])
    mu = policy.mu(z[:, None], Fm)
    r = solve_lcp(Fm, z[:, None], mu, jacobians=True, strict=True)

    def smoothed(zi):  # E_w[max(0, -(z + w)/F)], w ~ N(0, sigma^2), by quadrature
        def integrand(w):
            return max(0.0, -(zi + w) / F) * np.exp(-0.5 * (w / sigma) ** 2)

        val, _ = integrate.quad(integrand, -12 * sigma, 12 * sigma, points=[-zi], epsabs=1e-14)
        return val / (sigma * np.sqrt(2 * np.pi))

    expected = np.array([smoothed(zi) for zi in z])
    np.testing.assert_allclose(r.lam[:, 0], expected, rtol=1e-9, atol=1e-13)
    # total-mode derivative = derivative of the Gaussian-smoothed force: -Phi(-z/sigma) / F
    dmu = policy.dmu_dz(z[:, None], Fm)[:, 0, 0]
    total = r.dlam_dq[:, 0, 0] + r.dlam_dmu[:, 0, 0] * dmu
    np.testing.assert_allclose(total, -ndtr(-z / sigma) / F, rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize("policy", [Exact(), Fixed(1e-3), GaussianMatched(0.02)], ids=repr)
def test_rollout_chain_rule_matches_finite_differences(policy, rng):
    lcs = point_mass_lcs(2, time_step=0.01)
    x0 = np.array([0.0, 0.3, 1.0, 0.5])
    u = rng.normal(size=(40, 2))
    r = open_loop(LcsStepper(lcs, policy, "total"), x0, u)
    assert r.converged.all()

    def final(x, uu=u):
        return open_loop(LcsStepper(lcs, policy), x, uu, jacobians=False).x[0, -1]

    fd_x = central_difference(final, x0, eps=1e-7)
    np.testing.assert_allclose(r.dxH_dx0[0], fd_x, atol=1e-5 * (1 + np.abs(fd_x).max()))
    fd_u = central_difference(lambda uf: final(x0, uf.reshape(u.shape)), u.ravel(), eps=1e-7)
    analytic = r.dxH_du[0].transpose(1, 0, 2).reshape(4, -1)
    np.testing.assert_allclose(analytic, fd_u, atol=1e-5 * (1 + np.abs(fd_u).max()))
