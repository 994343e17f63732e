"""Step quantities of a plant whose dynamics are affine in the state: one evaluation serves every
state of every step (docs/math.md section 6).

A plant qualifies when every joint is prismatic or a weld and gravity is its only force
element. Then the mass matrix M, the bias forces (gravity) and every contact Jacobian are
constant, the free velocity ``v + h M^-1 (B u - n)`` is affine in (v, u), and each contact's
signed distance is affine in q (its point only translates). The quantities of any batch follow
from one evaluation of the provider at a reference state and its derivatives:

    W(p) = W_0,   v_free(p) = v_free,0 + dv_free (p - p_0),   phi(p) = phi_0 + dphi (p - p_0),
    J_n, J_t, N constant,   dW = dJ = dN = 0,                      with p = (q, v, u).

This is exact, not an approximation: the construction checks the structure (joint types and
force elements), then checks the affine prediction against the provider at a second state. It
is "model only what a scene requires": a translating box, a point mass, a gantry steps without
the per-state rigid-body algorithms.
"""

from __future__ import annotations

import numpy as np

from drake_abs.contact.step_data import StepQuantities

_AFFINE_JOINTS = ("prismatic", "weld")
CHECK_RTOL = 1e-9  # the affine prediction against the provider at a second state


class AffineDynamics:
    """The constant and affine parts of a qualifying provider's quantities, for all contacts.

    Build with :meth:`of`, which returns None when the plant does not qualify.
    """

    def __init__(self, model, reference: dict, p0: np.ndarray):
        self.nq, self.nv, self.nu = model.nq, model.nv, model.nu
        self.W = reference["W"]
        self.v_free0 = reference["v_free"]
        self.phi0 = reference["phi"]
        self.Jn, self.Jt, self.N = reference["Jn"], reference["Jt"], reference["N"]
        self.dv_free = reference["dv_free"]
        dphi = np.asarray(reference["dphi"])  # may be narrow (its q columns): padded to P
        self.dphi = np.zeros((dphi.shape[0], p0.size))
        self.dphi[:, : dphi.shape[-1]] = dphi
        self.p0 = p0
        self._rows = _tangent_rows(model)

    @classmethod
    def of(cls, model) -> AffineDynamics | None:
        """The affine quantities of ``model`` (a ContactModelBase), or None if its plant's
        dynamics are not affine (a revolute or floating joint, a force element other than
        gravity) or the check at a second state fails."""
        plant = model.plant
        joints = [plant.get_joint(j) for j in plant.GetJointIndices()]
        if any(j.type_name() not in _AFFINE_JOINTS for j in joints):
            return None
        if plant.num_force_elements() != 1:  # element 0 is the gravity field
            return None
        if plant.num_positions() != plant.num_velocities():
            return None
        P = model.nq + model.nv + model.nu
        p0 = np.zeros(P)
        every = np.arange(len(model.contacts))
        ref = model._one(p0[: model.nq], p0[model.nq : model.nq + model.nv],
                         p0[model.nq + model.nv :], every, True)  # fmt: skip
        affine = cls(model, ref, p0)
        rng = np.random.default_rng(0)
        p1 = rng.uniform(-1.0, 1.0, P)
        q1, v1, u1 = np.split(p1, [model.nq, model.nq + model.nv])
        check = model._one(q1, v1, u1, every, False)
        pred = affine.quantities(q1[None], v1[None], u1[None], every, derivatives=False)
        for name in ("W", "v_free", "phi", "Jn", "Jt"):
            want, got = np.asarray(check[name]), getattr(pred, name)[0]
            scale = 1.0 + np.abs(want).max() if want.size else 1.0
            if not np.allclose(got, want, rtol=0.0, atol=CHECK_RTOL * scale):
                return None
        return affine

    def distances(self, q: np.ndarray) -> np.ndarray:
        """Signed distances (B, nc) in m: affine in q."""
        return self.phi0 + (q - self.p0[: self.nq]) @ self.dphi[:, : self.nq].T

    def quantities(
        self, q: np.ndarray, v: np.ndarray, u: np.ndarray, active: np.ndarray, *,
        derivatives: bool = True,
    ) -> StepQuantities:  # fmt: skip
        """The quantities of a batch q (B, nq), v (B, nv), u (B, nu) for the contacts
        ``active`` (indices), as the provider would give them."""
        q, v, u = (np.asarray(a, float) for a in (q, v, u))
        B = q.shape[0]
        p = np.concatenate([q, v, u], axis=1) - self.p0
        active = np.asarray(active, dtype=np.int64)
        rows = np.concatenate([self._rows[i] for i in active]) if active.size else np.zeros(0, int)
        Jn, Jt = self.Jn[active], self.Jt[rows]
        dphi = self.dphi[active]
        fields = dict(
            q=q,
            v=v,
            W=np.broadcast_to(self.W, (B,) + self.W.shape),
            v_free=self.v_free0 + p @ self.dv_free.T,
            phi=self.phi0[active] + p @ dphi.T,
            Jn=np.broadcast_to(Jn, (B,) + Jn.shape),
            Jt=np.broadcast_to(Jt, (B,) + Jt.shape),
            N=np.broadcast_to(self.N, (B,) + self.N.shape),
        )
        if derivatives:
            P = p.shape[1]
            fields.update(
                dv_free=np.broadcast_to(self.dv_free, (B,) + self.dv_free.shape),
                dphi=np.broadcast_to(dphi, (B,) + dphi.shape),
                dJn=np.zeros(Jn.shape + (P,)),
                dJt=np.zeros(Jt.shape + (P,)),
                dN=np.zeros(self.N.shape + (P,)),
                dW=np.zeros(self.W.shape + (P,)),
            )
            for name in ("dJn", "dJt", "dN", "dW"):
                fields[name] = np.broadcast_to(fields[name], (B,) + fields[name].shape)
        return StepQuantities(**fields)


def _tangent_rows(model) -> list[np.ndarray]:
    """The rows of J_t that belong to each contact (k consecutive rows per frictional one)."""
    k = model.cone.directions
    out, start = [], 0
    for frictional in ~np.isnan(model.cone.coefficients):
        n = k if frictional else 0
        out.append(np.arange(start, start + n))
        start += n
    return out
