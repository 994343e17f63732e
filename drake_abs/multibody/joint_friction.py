"""Dry joint friction (an MJCF joint's ``frictionloss``) as complementarity rows of the step's
LCP (docs/math.md section 6e).

A joint velocity ``v_j`` with a Coulomb friction of bound F (N m or N) takes, over a step h, a
friction impulse ``p`` with ``|p| <= h F`` that opposes ``v_j+``: ``p = -h F sign(v_j+)`` while it
slides, any value in ``[-h F, h F]`` that holds it at ``v_j+ = 0`` while it sticks. These are the
rows of a friction cone whose normal impulse is the constant ``h F``:

    0 <= beta_m  perp  s_m v_j+ + omega >= 0          (m = 1..k, s_m = +1, -1, +1, ...)
    0 <= omega   perp  h F - sum_m beta_m >= 0

with ``p = sum_m s_m beta_m`` and ``omega`` the sliding speed ``|v_j+|``. In the step they are
a *pinned* contact of the LCP (:class:`~drake_abs.contact.cone.FrictionCone`, ``pinned``): a
frictional contact of coefficient 1 whose normal row has no velocity and whose normal impulse
is given, ``gamma = h F``; its k tangent rows are ``s_m e_j``, so one LCP holds the
contacts, the joint limits and the joint friction. The cone's k is the scene's number of
friction directions; a joint's rows alternate in sign, so any k >= 2 gives the bound h F both
ways (with k > 2 rows repeat, and the cone's tangential regularization splits their impulses).

Smoothing: the rows are smoothed by the scene's smoothing as the friction rows of a contact are
(mu / h on the tangent and cone rows), with the mu the smoothing gives a contact at distance 0
(the joint is always "in contact" with its friction) whose compliance is the joint's own,
``h e_j' W e_j`` (:class:`JointFrictionSmoothing`); on the pinned normal row that mu moves the
bound by at most ``sqrt(mu / kappa)`` (:data:`~drake_abs.contact.cone.PINNED_STIFFNESS`).
Under :class:`~drake_abs.contact.smoothing.Exact` the friction is exact Coulomb; under
:class:`~drake_abs.contact.smoothing.ContactAware` it takes the same mu as every contact; under
barrier smoothing a sticking joint creeps, as a sticking contact does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JointIndex

from drake_abs.contact.cone import PINNED_STIFFNESS
from drake_abs.contact.smoothing import Smoothing


@dataclass(frozen=True)
class JointFrictionRows:
    """The dry friction of a plant's velocities: ``nj`` of them, velocity ``v_index[i]`` with the
    bound ``bound[i]`` (N m or N, > 0), named ``names[i]`` (the joint's name, with the index of
    the velocity for a joint of several)."""

    v_index: np.ndarray
    bound: np.ndarray
    names: tuple[str, ...]

    @classmethod
    def of(cls, plant: MultibodyPlant, friction: np.ndarray | None) -> JointFrictionRows:
        """The rows of the velocities whose entry of ``friction`` (nv,) (N m or N; None: none) is
        > 0. Raises a ValueError naming ``joint_friction`` unless it is nv finite numbers >= 0."""
        nv = plant.num_velocities()
        F = np.zeros(nv) if friction is None else np.asarray(friction, dtype=float)
        if F.shape != (nv,) or not np.all(np.isfinite(F)) or np.any(F < 0):
            raise ValueError(
                f"joint_friction must be {nv} finite numbers >= 0 (a dry friction bound per "
                f"velocity, N m or N; 0: none); got {friction!r}"
            )
        label = {}
        for j in plant.GetJointIndices():
            joint = plant.get_joint(JointIndex(int(j)))
            for k in range(joint.num_velocities()):
                name = joint.name() if joint.num_velocities() == 1 else f"{joint.name()}[{k}]"
                label[joint.velocity_start() + k] = name
        on = np.flatnonzero(F > 0)
        return cls(on.astype(np.int64), F[on], tuple(label.get(int(v), f"v{v}") for v in on))

    @property
    def size(self) -> int:
        return self.v_index.size

    @staticmethod
    def signs(k: int) -> np.ndarray:
        """The signs ``s_m`` (k,) of a joint's k tangent rows: +1, -1, +1, ..."""
        return np.where(np.arange(k) % 2 == 0, 1.0, -1.0)

    def rows(
        self, rows: np.ndarray, B: int, nv: int, k: int, h: float, P: int | None = None
    ) -> dict[str, np.ndarray]:
        """The pinned contacts of the friction rows ``rows`` (r,) for B states: ``phi`` (B, r) =
        ``-kappa h F`` (the given normal impulse ``h F``, N m s or N s, times
        :data:`~drake_abs.contact.cone.PINNED_STIFFNESS`, negated), ``Jn`` (B, r, nv) = 0,
        ``Jt`` (B, r k, nv) with row ``s_m e_j``; with P (derivative columns), ``dphi``,
        ``dJn``, ``dJt`` of zeros (none of them moves with the state)."""
        r = len(rows)
        out = {
            "phi": np.broadcast_to(-PINNED_STIFFNESS * h * self.bound[rows], (B, r)).copy(),
            "Jn": np.zeros((B, r, nv)),
            "Jt": np.zeros((B, r * k, nv)),
        }
        signs = self.signs(k)
        for i, row in enumerate(rows):
            out["Jt"][:, i * k + np.arange(k), self.v_index[row]] = signs
        if P is not None:
            out.update(
                dphi=np.zeros((B, r, P)),
                dJn=np.zeros((B, r, nv, P)),
                dJt=np.zeros((B, r * k, nv, P)),
            )
        return out

    def impulses(self, beta: np.ndarray) -> np.ndarray:
        """The friction impulse ``p = sum_m s_m beta_m`` (B, r) along each joint's velocity, from
        the tangent impulses ``beta`` (B, r, k) of r friction rows."""
        return beta @ self.signs(beta.shape[-1])


class JointFrictionSmoothing(Smoothing):
    """A smoothing as the step's joint friction rows see it (module docstring): ``inner`` sees
    every normal row as it is but the pinned ones, ``rows`` (r,) of the normal rows, which it
    sees as touching contacts (distance 0) of compliance ``compliance`` (B, r) (the joints'
    ``h e_j' W e_j``, rad / (N m s) or m / (N s)). Their mu is held constant in the distances of
    the pinned rows (they have none) and in the compliance (as every contact's mu is in F)."""

    def __init__(self, inner: Smoothing, rows: np.ndarray, compliance: np.ndarray) -> None:
        if not isinstance(inner, Smoothing):
            raise ValueError(f"inner must be a Smoothing; got {type(inner).__name__}")
        self.inner = inner
        self.rows = np.asarray(rows, dtype=np.int64)
        self.compliance = np.asarray(compliance, dtype=float)

    @property
    def is_constant(self) -> bool:
        return self.inner.is_constant

    @property
    def is_exact(self) -> bool:
        return self.inner.is_exact

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return self.inner.parameter_names

    def _view(self, z: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        z = np.array(z, dtype=float)
        z[..., self.rows] = 0.0
        F = np.array(np.broadcast_to(F, z.shape + z.shape[-1:]), dtype=float)
        F[..., self.rows, self.rows] = self.compliance
        return z, F

    def mu(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return self.inner.mu(*self._view(z, F))

    def dmu_dz(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        d = np.array(self.inner.dmu_dz(*self._view(z, F)))
        d[..., self.rows] = 0.0  # the pinned rows' distances are not read
        return d

    def dmu_dparameters(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return self.inner.dmu_dparameters(*self._view(z, F))

    def dmu_dF_diagonal(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        d = np.array(self.inner.dmu_dF_diagonal(*self._view(z, F)))
        d[..., self.rows] = 0.0  # the pinned rows' diagonal is replaced
        return d
