"""Unit quaternions of free bodies after a step.

A free body on a quaternion floating joint (Drake's ``QuaternionFloatingJoint``: q = (qw, qx,
qy, qz, x, y, z), v = (w_W, v_W), the angular then the translational velocity in the world)
has no singular orientation, unlike Euler angles. The step's position update
``q+ = q + h N(q) v+`` moves a unit quaternion along its tangent, so its norm grows by about
``h^2 |w|^2 / 8`` per step: after the update each quaternion block is projected back onto the
unit sphere, ``P(q) = q / |q|``, and the step's Jacobians are chained through the projection's
Jacobian ``dP = (I - u u^T) / |q|`` (``u = q / |q|``) so that they stay the derivatives of the map
the step computes.
"""

from __future__ import annotations

import numpy as np

#: the step outputs whose rows are derivatives of the next state
_STATE_JACOBIANS = ("dx_dx", "dx_du", "dx_dtheta")


def quaternion_starts(plant) -> tuple[int, ...]:
    """The position index of the first entry (qw) of every unit quaternion of a finalized
    ``plant``: one per quaternion floating joint, in position order."""
    starts = []
    for i in plant.GetJointIndices():
        joint = plant.get_joint(i)
        if joint.type_name() == "quaternion_floating":
            starts.append(int(joint.position_start()))
    return tuple(sorted(starts))


def normalize_quaternions(out: dict, starts: tuple[int, ...]) -> None:
    """Project the quaternion blocks (4 entries from each of ``starts``) of ``out["x_next"]``
    (B, nx) onto the unit sphere, in place, and chain the rows of the state Jacobians present
    in ``out`` (``dx_dx``, ``dx_du``, ``dx_dtheta``: (B, nx, n)) through the projection. Rows
    with a non-finite or zero quaternion are left as they are (the stepper flags non-finite
    steps)."""
    if not starts:
        return
    x = out["x_next"]
    for s in starts:
        q = x[:, s : s + 4]
        norm = np.linalg.norm(q, axis=1)
        ok = np.isfinite(norm) & (norm > 0.0)
        if not ok.any():
            continue
        rows = np.flatnonzero(ok)
        unit = q[rows] / norm[rows, None]
        for key in _STATE_JACOBIANS:
            jac = out.get(key)
            if jac is None:
                continue
            block = jac[rows, s : s + 4]  # (b, 4, n)
            # dP @ block with dP = (I - u u^T) / |q|, without forming dP
            radial = np.einsum("bi,bin->bn", unit, block)
            jac[rows, s : s + 4] = (block - unit[:, :, None] * radial[:, None, :]) / norm[
                rows, None, None
            ]
        x[rows, s : s + 4] = unit
