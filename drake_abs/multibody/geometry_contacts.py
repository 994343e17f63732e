"""Contact candidates from collision geometry.

Two kinds of candidate come from a body's collision shapes (read from the SceneGraph inspector
of a plant built with the scene's model files):

* body against the ground: each shape becomes exact point candidates
  (:class:`~drake_abs.multibody.drake_dynamics.PointContact`). A sphere is its centre with its
  radius; a capsule its two end-cap centres with its radius (the deepest point of a capsule
  below a plane always lies on an end cap); a box its 8 vertices (the deepest point of a box
  below a plane is always a vertex). Other shapes are refused.
* body against body: a :class:`PairContact` per pair of collision shapes of the two bodies that
  the model's collision filters leave in, evaluated in closed form: sphere-sphere,
  sphere-box and sphere-capsule (either order). The closed forms below are written on plain
  arrays so that they evaluate on doubles and on AutoDiffXd alike (branches are chosen by the
  values), which gives the Drake provider its derivatives.

Sign conventions of a pair (A, B): ``phi`` is the signed distance (negative in penetration),
``n`` the unit normal pointing from B towards A, ``p_A``, ``p_B`` the witness points on A and
B (world frame): the normal velocity is ``n . (v_A(p_A) - v_B(p_B))``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import AutoDiffXd

#: The shapes a pair candidate may be made of.
PAIR_SHAPES = ("sphere", "box", "capsule")


@dataclass(frozen=True)
class Shape:
    """A collision shape on a body: ``kind`` ("sphere", "box" or "capsule"), ``size`` (sphere:
    (radius,); box: its full side lengths (x, y, z); capsule: (radius, length), the length of
    the segment along the shape's z axis), and its pose in the body frame: ``p_BG`` (m) and the
    rotation ``R_BG`` (row-major 3 x 3)."""

    kind: str
    size: tuple[float, ...]
    p_BG: tuple[float, float, float] = (0.0, 0.0, 0.0)
    R_BG: tuple[tuple[float, float, float], ...] = (
        (1.0, 0.0, 0.0),
        (0.0, 1.0, 0.0),
        (0.0, 0.0, 1.0),
    )

    def __post_init__(self):
        if self.kind not in PAIR_SHAPES:
            raise ValueError(f"shape kind must be one of {PAIR_SHAPES}; got {self.kind!r}")
        sizes = {"sphere": 1, "box": 3, "capsule": 2}
        if len(self.size) != sizes[self.kind] or not all(s > 0 for s in self.size):
            raise ValueError(
                f"a {self.kind} needs {sizes[self.kind]} positive sizes; got {self.size}"
            )


@dataclass(frozen=True)
class PairContact:
    """A body-body contact candidate: ``shape_a`` on ``body_a`` against ``shape_b`` on
    ``body_b`` (see the module docstring for the signs); ``friction`` the Coulomb coefficient
    (None: frictionless); ``model_a``, ``model_b`` the bodies' model instances (None: the body
    name is unique)."""

    body_a: str
    shape_a: Shape
    body_b: str
    shape_b: Shape
    friction: float | None = None
    model_a: str | None = None
    model_b: str | None = None

    def __post_init__(self):
        kinds = {self.shape_a.kind, self.shape_b.kind}
        if "sphere" not in kinds:
            raise NotImplementedError(
                f"pair {self.body_a!r}-{self.body_b!r}: {self.shape_a.kind}-{self.shape_b.kind} "
                "has no closed form here; pairs need a sphere on one side (sphere-sphere, "
                "sphere-box, sphere-capsule)"
            )


def _value(x) -> float:
    return x.value() if isinstance(x, AutoDiffXd) else float(x)


def _norm(x):
    return np.sqrt(x @ x)


def _cross(a, b):
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def shape_pose_in_world(shape: Shape, R_WB, p_WB):
    """(R_WG, p_WG) of ``shape`` for its body's world pose (R_WB (3, 3), p_WB (3,)), in the
    pose's scalar type."""
    R_BG = np.asarray(shape.R_BG, float)
    return R_WB @ R_BG, p_WB + R_WB @ np.asarray(shape.p_BG, float)


def _sphere_sphere(c_a, r_a, c_b, r_b):
    d = c_a - c_b
    length = _norm(d)
    if _value(length) == 0.0:
        raise ValueError("coincident sphere centres: the contact normal is undefined")
    n = d / length
    return length - r_a - r_b, n, c_a - r_a * n, c_b + r_b * n


def _sphere_box(c, r, R_WG, p_WG, half):
    """A sphere (centre c, radius r) against a box (pose R_WG, p_WG; half sizes)."""
    local = R_WG.T @ (c - p_WG)
    vals = [_value(x) for x in local]
    inside = all(abs(vals[i]) <= half[i] for i in range(3))
    if not inside:
        clamped = [local[i] if abs(vals[i]) <= half[i] else np.sign(vals[i]) * half[i]
                   for i in range(3)]  # fmt: skip
        closest = np.array(clamped, dtype=local.dtype)
        diff = local - closest
        length = _norm(diff)
        n_local, phi = diff / length, length - r
    else:  # the face of least depth
        depth = [half[i] - abs(vals[i]) for i in range(3)]
        i = int(np.argmin(depth))
        sign = 1.0 if vals[i] >= 0 else -1.0
        n_local = np.zeros(3)
        n_local[i] = sign
        closest = np.array(list(local), dtype=local.dtype)
        closest[i] = sign * half[i]
        phi = -(half[i] - sign * local[i]) - r
    n = R_WG @ n_local
    return phi, n, c - r * n, p_WG + R_WG @ closest


def pair_geometry(contact: PairContact, R_WA, p_WA, R_WB, p_WB):
    """``(phi, n, p_A, p_B)`` of a pair candidate (module docstring) at the bodies' world poses,
    on doubles or AutoDiffXd arrays."""
    a, b = contact.shape_a, contact.shape_b
    flip = a.kind != "sphere"  # the sphere goes first; the result is turned back below
    if flip:
        a, b, R_WA, p_WA, R_WB, p_WB = b, a, R_WB, p_WB, R_WA, p_WA
    _, c_a = shape_pose_in_world(a, R_WA, p_WA)
    r_a = a.size[0]
    R_WG, p_WG = shape_pose_in_world(b, R_WB, p_WB)
    if b.kind == "sphere":
        phi, n, p_a, p_b = _sphere_sphere(c_a, r_a, p_WG, b.size[0])
    elif b.kind == "box":
        phi, n, p_a, p_b = _sphere_box(c_a, r_a, R_WG, p_WG, [s / 2 for s in b.size])
    else:  # capsule: the sphere against the closest point of the capsule's segment
        radius, length = b.size
        axis = R_WG[:, 2]
        t = (c_a - p_WG) @ axis
        t_val = min(max(_value(t), -length / 2), length / 2)
        t = t if abs(t_val - _value(t)) == 0.0 else t_val
        phi, n, p_a, p_b = _sphere_sphere(c_a, r_a, p_WG + t * axis, radius)
    if flip:
        return phi, -n, p_b, p_a
    return phi, n, p_a, p_b


def pair_tangents(n, k: int):
    """k directions (k, 3) orthogonal to the unit normal ``n`` (doubles or AutoDiffXd), evenly
    spread; the same construction as the ground's tangents."""
    seed = np.array([1.0, 0.0, 0.0]) if abs(_value(n[0])) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = seed - n * (seed @ n)
    t1 = t1 / _norm(t1)
    t2 = _cross(n, t1)
    angles = 2 * np.pi * np.arange(k) / k
    return np.array([np.cos(a) * t1 + np.sin(a) * t2 for a in angles])


# --- reading collision geometry -----------------------------------------------------------


def shape_of(inspector, geometry_id) -> tuple[str, tuple[float, ...]] | None:
    """``(kind, size)`` of a SceneGraph geometry for the shapes handled here, else None."""
    from pydrake.geometry import Box, Capsule, Sphere

    shape = inspector.GetShape(geometry_id)
    if isinstance(shape, Sphere):
        return "sphere", (shape.radius(),)
    if isinstance(shape, Box):
        return "box", tuple(float(s) for s in shape.size())
    if isinstance(shape, Capsule):
        return "capsule", (shape.radius(), shape.length())
    return None


def ground_points(shape: Shape) -> list[tuple[tuple[float, float, float], float]]:
    """The exact point candidates of ``shape`` against a half-space: ``[(p_B, radius)]`` in the
    body frame (module docstring)."""
    R = np.asarray(shape.R_BG, float)
    p = np.asarray(shape.p_BG, float)
    if shape.kind == "sphere":
        local, radius = [np.zeros(3)], shape.size[0]
    elif shape.kind == "capsule":
        half = shape.size[1] / 2
        local, radius = [np.array([0.0, 0.0, -half]), np.array([0.0, 0.0, half])], shape.size[0]
    else:
        hx, hy, hz = (s / 2 for s in shape.size)
        local = [np.array([sx * hx, sy * hy, sz * hz])
                 for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]  # fmt: skip
        radius = 0.0
    return [(tuple(float(x) for x in p + R @ c), float(radius)) for c in local]
