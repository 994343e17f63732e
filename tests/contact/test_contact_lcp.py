"""The rigid-body contact step (docs/math.md section 6) on a synthetic planar box whose dynamics
quantities are smooth closed forms: the assembled step Jacobian against central finite
differences of the whole step, with and without friction, frozen and total."""

from dataclasses import replace

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs import ContactAware, Exact, Fixed, solve_lcp
from drake_abs.contact.cone import FrictionCone
from drake_abs.contact.contact_lcp import contact_step
from drake_abs.contact.step_data import StepQuantities
from drake_abs.contact.stewart_trinkle import assemble_lcp
from drake_abs.multibody import build_scene_model

H = 0.01
CORNERS = np.array([[-0.2, -0.1], [0.2, -0.1]])  # box-frame corners touching the ground


def components(q, v, u, mass=1.3, inertia=0.02, g=9.81):
    """Planar box (x, z, theta): W, v_free, phi, Jn, Jt (+t, -t per corner), N; smooth in q."""
    x, z, th = q
    c, s = np.cos(th), np.sin(th)
    # a configuration-dependent mass matrix, so that dW/dq is exercised
    M = np.diag([mass, mass, inertia]) + 0.01 * np.outer([c, s, 0.3], [c, s, 0.3])
    W = np.linalg.inv(M)
    tau = u - np.array([0.0, mass * g, 0.0]) - 0.05 * v * np.abs(np.sin(th + 0.3))
    v_free = v + H * W @ tau
    phi, Jn, Jt = [], [], []
    for px, pz in CORNERS:
        phi.append(z + s * px + c * pz)
        Jn.append([0.0, 1.0, c * px - s * pz])
        t = [1.0, 0.0, -s * px - c * pz]
        Jt += [t, [-a for a in t]]
    N = np.eye(3) + 0.05 * np.diag([0.0, 0.0, np.sin(th)])  # a q-dependent N, to exercise dN
    return W, v_free, np.array(phi), np.array(Jn), np.array(Jt), N


def quantities(q, v, u, cone, derivatives=True):
    """StepQuantities of one state; derivatives by central differences of each component."""
    W, v_free, phi, Jn, Jt, N = components(q, v, u)
    rows = cone.sizes()[1]  # tangent rows: none without friction
    kwargs = {}
    if derivatives:
        p_nominal = np.concatenate([q, v, u])
        values = components(q, v, u)
        d = []
        for i, value in enumerate(values):

            def part(p, i=i):
                return components(p[:3], p[3:6], p[6:])[i].ravel()

            d.append(central_difference(part, p_nominal, eps=1e-6).reshape(*value.shape, 9))
        kwargs = dict(dW=d[0], dv_free=d[1], dphi=d[2], dJn=d[3], dJt=d[4][:rows], dN=d[5])
        kwargs = {k: a[None] for k, a in kwargs.items()}
    return StepQuantities(
        q[None],
        v[None],
        W[None],
        v_free[None],
        phi[None],
        Jn[None],
        Jt[None, :rows],
        N[None],
        **kwargs,
    )


CONES = {
    "frictionless": FrictionCone(np.array([np.nan, np.nan]), 2),
    "friction": FrictionCone(np.array([0.6, 0.6]), 2),
    "anitescu": FrictionCone(np.array([0.6, 0.6]), 2, formulation="anitescu"),
    "anitescu_mixed": FrictionCone(np.array([0.6, np.nan]), 2, formulation="anitescu"),
}
STATES = {
    "resting": (np.array([0.0, 0.1 + 1e-4, 0.0]), np.array([0.3, -0.2, 0.0])),
    # (at vx = 0.5 the exact frictional solution sticks exactly on the cone boundary: omega and
    # its slack are both 0, the step is not differentiable there and FD is no reference)
    "tilted_impact": (np.array([0.1, 0.13, 0.15]), np.array([1.0, -1.5, 0.4])),
    "sliding": (np.array([0.0, 0.0999, -0.02]), np.array([1.2, 0.0, 0.1])),
}


@pytest.mark.parametrize("cone", CONES.values(), ids=CONES.keys())
@pytest.mark.parametrize("state", STATES.values(), ids=STATES.keys())
@pytest.mark.parametrize(
    "policy, gradient",
    [
        (Exact(), "frozen"),
        (Fixed(1e-4), "frozen"),
        (ContactAware(mu_max=1e-3, length=0.02, mu_min=1e-8), "total"),
    ],
    ids=["exact", "bs", "abs-total"],
)
def test_step_jacobians_match_finite_differences(cone, state, policy, gradient):
    q, v = state
    u = np.array([0.4, 2.0, 0.01])
    r = contact_step(quantities(q, v, u, cone), cone, H, policy, gradient=gradient, strict=True)
    assert r.lam[0, :2].max() > 1e-3  # every state makes contact within the step
    mu_frozen = r.lcp.mu_target

    def step(p):
        quant = quantities(p[:3], p[3:6], p[6:], cone, derivatives=False)
        if gradient == "frozen" and not policy.is_constant:  # hold mu at its nominal value
            F, z, _ = assemble_lcp(quant, cone, H)
            lam = solve_lcp(F, z, mu_frozen, on_bad_matrix="attempt", strict=True).lam
            G = np.concatenate([quant.Jn, quant.Jt], axis=1)
            f = np.einsum("brn,br->bn", G, lam[:, : G.shape[1]])
            v_next = quant.v_free + np.einsum("bnm,bm->bn", quant.W, f)
            q_next = quant.q + H * np.einsum("bqn,bn->bq", quant.N, v_next)
        else:
            out = contact_step(quant, cone, H, policy, strict=True)
            q_next, v_next = out.q_next, out.v_next
        return np.concatenate([q_next[0], v_next[0]])

    fd = central_difference(step, np.concatenate([q, v, u]), eps=1e-7)
    analytic = np.concatenate([r.dx_dx[0], r.dx_du[0]], axis=1)
    np.testing.assert_allclose(analytic, fd, atol=2e-5 * (1 + np.abs(fd).max()))


def test_narrow_geometric_derivatives_give_the_same_step(rng):
    """Narrow dphi, dJn, dJt, dN (their first K columns; the rest zero) step exactly as their
    full-width padding, and mismatched widths are refused by name."""
    sm = build_scene_model("box_push")
    model = sm.contact_model
    B = 4
    x = np.tile(sm.x0, (B, 1))
    x[:, model.nq] = rng.uniform(-1.0, 1.0, B)
    q, v = x[:, : model.nq], x[:, model.nq :]
    u = rng.uniform(-5, 5, (B, model.nu))
    quant = model.quantities(q, v, u)
    P = quant.dv_free.shape[-1]
    K = model.nq
    for name in ("dphi", "dJn", "dJt", "dN"):  # this provider's rows do not depend on v, u
        assert np.abs(quant.full(name)[..., K:]).max(initial=0.0) == 0.0
    wide = replace(quant, **{n: quant.full(n) for n in ("dphi", "dJn", "dJt", "dN")})
    narrow = replace(quant, **{n: quant.full(n)[..., :K] for n in ("dphi", "dJn", "dJt")},
                     dN=quant.full("dN")[..., :0])  # fmt: skip
    assert wide.dJn.shape[-1] == P and narrow.dJn.shape[-1] == K
    cone = model.cone
    for smoothing in (Exact(), ContactAware(1e-3, 0.02)):
        a = contact_step(wide, cone, model.h, smoothing)
        b = contact_step(narrow, cone, model.h, smoothing)
        for key in ("q_next", "v_next", "lam", "dx_dx", "dx_du", "dlam_dx", "dlam_du"):
            np.testing.assert_allclose(getattr(b, key), getattr(a, key), rtol=0, atol=1e-13)
    with pytest.raises(ValueError, match="dphi, dJn, dJt must share"):
        replace(wide, dJn=quant.full("dJn")[..., :K])
