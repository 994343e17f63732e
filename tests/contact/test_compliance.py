"""MuJoCo's soft contact as a regularised LCP (drake_abs.contact.compliance), on closed-form
dynamics: MuJoCo's impedance numbers, the rest penetration MuJoCo's documentation gives, the
hard step unchanged on hard rows, step Jacobians against central differences, and solvability
at the extremes of solref and solimp."""

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs import ContactAware, Exact
from drake_abs.contact.compliance import ContactCompliance, SoftRows, impedance
from drake_abs.contact.cone import FrictionCone
from drake_abs.contact.contact_lcp import contact_step
from drake_abs.contact.step_data import StepQuantities

H = 0.01
G = 9.81
MASS = 1.0


def components(q, v, u, k=4):
    """A point mass (x, y, z) against the ground z = 0, with a weak q-dependent mass matrix so
    that dW/dq is exercised: W, v_free, phi, Jn, Jt (k directions), N."""
    M = MASS * np.eye(3) + 0.02 * np.diag([np.sin(q[0]), 0.0, np.cos(q[1])])
    W = np.linalg.inv(M)
    v_free = v + H * W @ (u - np.array([0.0, 0.0, MASS * G]))
    angles = 2 * np.pi * np.arange(k) / k
    Jt = np.stack([np.cos(angles), np.sin(angles), np.zeros(k)], axis=1)
    return W, v_free, np.array([q[2]]), np.array([[0.0, 0.0, 1.0]]), Jt, np.eye(3)


def quantities(q, v, u, derivatives=True, rows=4):
    values = components(q, v, u)
    kwargs = {}
    if derivatives:
        p0 = np.concatenate([q, v, u])
        d = []
        for i, value in enumerate(values):

            def part(p, i=i):
                return components(p[:3], p[3:6], p[6:])[i].ravel()

            d.append(central_difference(part, p0, eps=1e-6).reshape(*value.shape, 9))
        kwargs = dict(dW=d[0], dv_free=d[1], dphi=d[2], dJn=d[3], dJt=d[4][:rows], dN=d[5])
        kwargs = {key: a[None] for key, a in kwargs.items()}
    W, v_free, phi, Jn, Jt, N = values
    return StepQuantities(q[None], v[None], W[None], v_free[None], phi[None], Jn[None],
                          Jt[None, :rows], N[None], **kwargs)  # fmt: skip


def cone_of(kind: str) -> FrictionCone:
    if kind == "frictionless":
        return FrictionCone(np.array([np.nan]), 4)
    return FrictionCone(np.array([1.0]), 4, formulation=kind)


def soft_rows(cone: FrictionCone, **kwargs) -> SoftRows:
    comp = ContactCompliance.uniform(1, 1.0 / MASS, condim=1 if cone.sizes()[2] == 0 else 3,
                                     **kwargs)  # fmt: skip
    return comp.rows(np.array([0]), 0, cone.coefficients, cone.formulation, 4, H)


def step(q, v, u, cone, soft, smoothing=None, derivatives=False):
    rows = cone.sizes()[1]
    quant = quantities(q, v, u, derivatives, rows)
    return contact_step(quant, cone, H, smoothing, compliance=soft)


def test_impedance_is_mujocos():
    # MuJoCo 4.0's efc_KBIP (impedance and its derivative) for HalfCheetah-v5's solimp at a
    # contact 4.045 mm below its margin (half_cheetah.xml, 150 Euler steps of 10 ms)
    solimp = np.array([[0.0, 0.8, 0.01, 0.5, 2.0]])
    d, dd = impedance(np.array([-0.0040452977823778324]), solimp)
    assert d[0] == pytest.approx(0.261898218, rel=1e-8)
    assert dd[0] == pytest.approx(-129.433348, rel=1e-8)
    # flat (Hopper-v5's .8 .8 .01): 0.8 everywhere, no slope
    d, dd = impedance(np.array([-0.02, -0.001, 0.0]), np.array([[0.8, 0.8, 0.01, 0.5, 2.0]]))
    assert np.all(d == 0.8) and np.all(dd == 0.0)
    # the derivative against central differences, on both branches and for power 1 and 3
    for p in (1.0, 2.0, 3.0):
        imp = np.array([[0.1, 0.95, 0.01, 0.3, p]])
        for r in (-0.001, -0.002, -0.006, 0.004):
            fd = (impedance(np.array([r + 1e-8]), imp)[0] - impedance(np.array([r - 1e-8]),
                  imp)[0]) / 2e-8  # fmt: skip
            assert impedance(np.array([r]), imp)[1][0] == pytest.approx(fd[0], rel=1e-6)
    # saturated past the width
    assert impedance(np.array([-0.5]), np.array([[0.1, 0.95, 0.01, 0.3, 2.0]]))[0][0] == 0.95


@pytest.mark.parametrize("kind", ["frictionless", "stewart_trinkle", "anitescu"])
def test_point_mass_rests_at_mujocos_penetration(kind):
    # MuJoCo's documentation: at rest under a load a_u, with A_hat = 1 / m and a constant
    # impedance d, the penetration is a_u (1 - d) timeconst^2 dampratio^2. With
    # friction 1 the pyramid's normal compliance equals the frictionless one (2 mu^2 (1 + mu^2)
    # / 4 = 1), so all three rest at the same depth.
    cone = cone_of(kind)
    d, tc, dr = 0.9, 0.05, 1.2
    soft = soft_rows(cone, solref=(tc, dr), solimp=(d, d, 0.01, 0.5, 2.0))
    q, v = np.array([0.0, 0.0, -1e-3]), np.zeros(3)
    for _ in range(400):
        r = step(q, v, np.zeros(3), cone, soft)
        assert r.converged.all()
        q, v = r.q_next[0], r.v_next[0]
    # at rest the impulse carries the weight, gamma = h m g, and the row reads
    # h R gamma + h^2 k r = 0: r = -(1 - d) timeconst^2 dampratio^2 g (m A_hat), with
    # A_hat = 1 / m here (the row's actual J W J^T differs by the 2 % perturbation of M, which
    # MuJoCo's rest depth does not see either)
    depth = -G * (1 - d) * tc**2 * dr**2
    assert q[2] == pytest.approx(depth, rel=1e-6)
    assert abs(v[2]) < 1e-8


@pytest.mark.parametrize("kind", ["frictionless", "stewart_trinkle", "anitescu"])
def test_hard_rows_of_a_soft_step_are_the_hard_step_bit_for_bit(kind):
    cone = cone_of(kind)
    soft = soft_rows(cone)
    hard = SoftRows(np.array([False]), soft.margin, soft.k0, soft.b, soft.solimp, soft.weight)
    q, v, u = np.array([0.1, 0.0, -0.002]), np.array([0.4, -0.1, -0.3]), np.array([1.0, 0, 0])
    for smoothing in (Exact(), ContactAware(1e-3, 0.02)):
        a = step(q, v, u, cone, None, smoothing, derivatives=True)
        b = step(q, v, u, cone, hard, smoothing, derivatives=True)
        for key in ("q_next", "v_next", "lam", "dx_dx", "dx_du", "dlam_dx"):
            assert np.array_equal(getattr(a, key), getattr(b, key)), key


SOFT_STATES = {
    # (r = phi - margin = -4.5 mm: off solimp's midpoint at -4 mm, where d'' jumps and central
    # differences lose their second order)
    "pressed": (np.array([0.1, 0.0, -0.0035]), np.array([0.0, 0.0, -0.2])),
    "sliding": (np.array([0.2, 0.1, -0.004]), np.array([1.5, 0.5, -0.1])),
}


@pytest.mark.parametrize("kind", ["frictionless", "stewart_trinkle", "anitescu"])
@pytest.mark.parametrize("state", list(SOFT_STATES))
@pytest.mark.parametrize("smoothing", [Exact(), ContactAware(1e-4, 0.02)], ids=["exact", "ca"])
def test_soft_step_jacobians_match_finite_differences(kind, state, smoothing):
    cone = cone_of(kind)
    # a sloped impedance (solimp's width 1 cm), so dR/dr and dk/dr are exercised
    soft = soft_rows(cone, solref=(0.03, 0.8), solimp=(0.2, 0.9, 0.01, 0.4, 2.0), margin=0.001)
    q, v = SOFT_STATES[state]
    u = np.array([2.0, -1.0, 0.5])
    r = step(q, v, u, cone, soft, smoothing, derivatives=True)
    assert r.converged.all() and r.lam[0, 0] > 0

    def x_next(p):
        s = step(p[:3], p[3:6], p[6:], cone, soft, smoothing)
        return np.concatenate([s.q_next[0], s.v_next[0]])

    fd = central_difference(x_next, np.concatenate([q, v, u]), eps=1e-7)
    J = np.concatenate([r.dx_dx[0], r.dx_du[0]], axis=1)
    scale = max(1.0, np.abs(fd).max())
    assert np.abs(J - fd).max() / scale < 1e-6


def test_soft_rows_carry_different_impulses_than_hard_ones():
    # the compliance changes the step: a pressed point mass is pushed back by the soft row's
    # spring (a hard row would stop it at z+ = 0 ... it is already below: it lifts to 0)
    cone = cone_of("frictionless")
    q, v = np.array([0.0, 0.0, -0.003]), np.zeros(3)
    soft = step(q, v, np.zeros(3), cone, soft_rows(cone))
    hard = step(q, v, np.zeros(3), cone, None)
    assert hard.q_next[0, 2] == pytest.approx(0.0, abs=1e-12)
    assert -0.003 < soft.q_next[0, 2] < -1e-4  # recovers gradually (timeconst 0.02 s)


def test_a_soft_row_beyond_its_margin_is_refused():
    cone = cone_of("frictionless")
    with pytest.raises(ValueError, match="beyond their margin"):
        step(np.array([0.0, 0.0, 0.01]), np.zeros(3), np.zeros(3), cone, soft_rows(cone))


def normal_complementarity(q, v, r, soft, kind) -> float:
    """The soft rows rebuilt from the step's outputs, ``s_j = h D_j v+ + h R_j b_j + c_j``
    (D: the normal row, or under Anitescu the generators ``J_n + alpha t_j`` with their
    impulses b_j; c, R: the module's formulas at the start state), and their complementarity:
    ``max_j |min(b_j, s_j)|`` relative to the row's scale (``max(1 m, |c|)``), the check that a
    converged flag is earned."""
    W, v_free, phi, Jn, Jt, N = components(q, v, np.zeros(3))
    if kind == "anitescu":
        D, b = Jn + 1.0 * Jt, r.lcp.lam[0]
    else:
        D, b = Jn, r.lam[0, :1]
    rows = soft.take(np.zeros(len(b), dtype=int))
    terms = rows.terms(np.full((1, len(b)), q[2]), (D @ v)[None], H)
    s_row = H * D @ r.v_next[0] + H * terms.R[0] * b + terms.c[0]
    scale = max(1.0, float(np.abs(terms.c).max()))
    return float(np.abs(np.minimum(b, s_row)).max()) / scale


def test_stiff_limit_approaches_the_hard_step():
    # d -> 0.9999 (R -> 1e-4 A_hat) and h b = h^2 k = 1 (timeconst = 2 h, dampratio 1/2,
    # dwidth ~ 1): the soft row tends to the hard row phi + h J v+ >= 0
    for kind in ("frictionless", "stewart_trinkle", "anitescu"):
        cone = cone_of(kind)
        stiff = soft_rows(cone, solref=(2 * H, 0.5), solimp=(0.9999, 0.9999, 0.001, 0.5, 2.0))
        q, v, u = np.array([0.0, 0.0, -0.002]), np.array([0.3, 0.0, -0.5]), np.zeros(3)
        a = step(q, v, u, cone, stiff)
        b = step(q, v, u, cone, None)
        assert a.converged.all() and b.converged.all()
        assert normal_complementarity(q, v, a, stiff, kind) < 1e-8
        assert np.abs(a.v_next - b.v_next).max() < 1e-3 * np.abs(b.v_next).max() + 1e-3, kind
        soft = step(q, v, u, cone, soft_rows(cone))  # MuJoCo's defaults: clearly not hard
        assert np.abs(soft.v_next - b.v_next).max() > 0.05, kind


@pytest.mark.parametrize("kind", ["frictionless", "stewart_trinkle", "anitescu"])
def test_very_soft_rows_stay_solvable_and_let_the_body_sink(kind):
    cone = cone_of(kind)
    soft = soft_rows(cone, solref=(100.0, 1.0), solimp=(1e-4, 1e-4, 0.001, 0.5, 2.0))
    q, v = np.array([0.0, 0.0, -0.001]), np.array([0.5, 0.0, -0.5])
    r = step(q, v, np.zeros(3), cone, soft, derivatives=True)
    assert r.converged.all()
    assert normal_complementarity(q, v, r, soft, kind) < 1e-8
    assert np.isfinite(r.dx_dx).all()
    # the row barely acts: the body keeps falling at almost its free velocity
    v_free = components(q, v, np.zeros(3))[1]
    assert r.v_next[0, 2] == pytest.approx(v_free[2], abs=1e-3)
    # stiff extreme with refsafe off (timeconst far below the step: the reference launches the
    # body, as MuJoCo's would) is still solved
    stiff = ContactCompliance.uniform(1, 1.0, solref=(1e-5, 1.0), refsafe=False,
                                      condim=1 if kind == "frictionless" else 3)  # fmt: skip
    rows = stiff.rows(np.array([0]), 0, cone.coefficients, cone.formulation, 4, H)
    r = step(q, v, np.zeros(3), cone, rows)
    assert r.converged.all() and np.isfinite(r.q_next).all()
    assert normal_complementarity(q, v, r, rows, kind) < 1e-8


def test_parameters_are_checked():
    with pytest.raises(ValueError, match="solref"):
        ContactCompliance.uniform(2, 1.0, solref=(0.02, -1.0))
    with pytest.raises(ValueError, match="solimp"):
        ContactCompliance.uniform(2, 1.0, solimp=(0.9, 1.2, 0.001, 0.5, 2.0))
    with pytest.raises(ValueError, match="margin"):
        ContactCompliance.uniform(2, 1.0, margin=-0.1)
    with pytest.raises(ValueError, match="inverse_weight"):
        ContactCompliance.uniform(2, 0.0)
    with pytest.raises(ValueError, match="condim"):
        ContactCompliance.uniform(2, 1.0, condim=4)
    with pytest.raises(ValueError, match="impratio"):
        ContactCompliance.uniform(2, 1.0, impratio=0.0)
