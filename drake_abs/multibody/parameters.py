"""The model parameters theta of a multibody scene's step (docs/math.md section 6d): their names
and values, the model with other values, and the derivatives of one step's quantities in them.

A :class:`~drake_abs.multibody.stepper.ComplementarityStepper` calls these for its
:attr:`~drake_abs.multibody.stepper.ComplementarityStepper.parameter_names` (which lists the
columns and their units),
:meth:`~drake_abs.multibody.stepper.ComplementarityStepper.parameter_values`,
:meth:`~drake_abs.multibody.stepper.ComplementarityStepper.with_parameters` and ``step(...,
parameters=...)``. The columns, in order: the ground height (m), each frictional candidate's
friction coefficient, each body's mass (kg), each point candidate's radius (m), each
one-velocity joint's damping (N m s / rad or N s / m; only under ``damping=True``), each point
candidate's offset (m, three columns), each body's unit rotational inertia (m^2, six columns),
then each one-velocity joint's spring stiffness (N m / rad or N / m) and spring reference (rad
or m; both only under ``springs=True``).

- :func:`damping_joints`, :func:`parameter_names`, :func:`parameter_values`: the columns and
  their values in a contact model;
- :func:`parameter_vector`, :func:`with_values`: new values, checked, and the contact model,
  joint damping and joint springs that carry them;
- :func:`parameter_columns`: the columns a step is asked for;
- :func:`parameter_derivatives`, :func:`damping_columns`: one batched step's theta block
  (:class:`~drake_abs.contact.step_data.ParameterDerivatives`), B states and T columns.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace

import numpy as np
from pydrake.multibody.plant import MultibodyPlant

from drake_abs.contact.cone import FrictionCone
from drake_abs.contact.damping import JointSprings
from drake_abs.contact.step_data import ParameterDerivatives, StepQuantities
from drake_abs.multibody.drake_dynamics import (
    INERTIA_ENTRIES,
    INERTIA_INDEX,
    ContactModelBase,
    central_unit_inertia,
    spatial_inertia,
)

#: the lower ends of the model parameters' ranges, by name prefix: (bound, strict, unit)
_PARAMETER_RANGES = {
    "friction[": (0.0, False, ""),
    "mass[": (0.0, True, " kg"),
    "radius[": (0.0, False, " m"),
    "damping[": (0.0, False, " N m s / rad or N s / m"),
    "stiffness[": (0.0, False, " N m / rad or N / m"),
}


def damping_joints(plant: MultibodyPlant) -> tuple[tuple[str, int], ...]:
    """``(name, velocity index)`` of every one-velocity joint of ``plant``, the joint-damping
    parameters. A name that occurs in several model instances is qualified as
    ``"instance::joint"``."""
    joints = [plant.get_joint(j) for j in plant.GetJointIndices()]
    joints = [j for j in joints if j.num_velocities() == 1]
    counts: dict[str, int] = {}
    for j in joints:
        counts[j.name()] = counts.get(j.name(), 0) + 1
    return tuple(
        (
            j.name()
            if counts[j.name()] == 1
            else f"{plant.GetModelInstanceName(j.model_instance())}::{j.name()}",
            int(j.velocity_start()),
        )
        for j in joints
    )


def parameter_names(
    model: ContactModelBase,
    joints: tuple[tuple[str, int], ...],
    spring_joints: tuple[tuple[str, int], ...] = (),
) -> tuple[str, ...]:
    """The names of the model parameters of ``model`` in column order (T,), with the damping
    columns of ``joints`` and the spring columns (stiffness, then reference) of
    ``spring_joints`` (:func:`damping_joints`, or none): see
    :attr:`~drake_abs.multibody.stepper.ComplementarityStepper.parameter_names`."""
    coeff = model.cone.coefficients
    points = model.point_contacts
    return (
        ("ground_height",)
        + tuple(f"friction[{i}]" for i in np.flatnonzero(~np.isnan(coeff)))
        + tuple(f"mass[{name}]" for name in model.massive_bodies)
        + tuple(f"radius[{i}]" for i in points)
        + tuple(f"damping[{name}]" for name, _ in joints)
        + tuple(f"offset[{i}].{axis}" for i in points for axis in "xyz")
        + tuple(
            f"unit_inertia[{name}].{entry}"
            for name in model.massive_bodies
            for entry in INERTIA_ENTRIES
        )
        + tuple(f"stiffness[{name}]" for name, _ in spring_joints)
        + tuple(f"springref[{name}]" for name, _ in spring_joints)
    )


def parameter_values(
    model: ContactModelBase,
    damping: np.ndarray,
    joints: tuple[tuple[str, int], ...],
    springs: JointSprings | None = None,
    spring_joints: tuple[tuple[str, int], ...] = (),
) -> np.ndarray:
    """The values (T,) of :func:`parameter_names` in ``model``, with the joint damping
    ``damping`` (nv,) of ``joints`` and the joint ``springs`` of ``spring_joints``; see
    :meth:`~drake_abs.multibody.stepper.ComplementarityStepper.parameter_values`."""
    if spring_joints and springs is None:
        raise ValueError("springs must be given with spring_joints")
    m = model
    coeff = m.cone.coefficients
    inertias = [m.body_spatial_inertia(index) for _, index in m._massive]
    rows, cols = np.array(INERTIA_INDEX).T
    points = [m.contacts[i] for i in m.point_contacts]
    return np.concatenate([
        [m.ground.height], coeff[~np.isnan(coeff)], [M.get_mass() for M in inertias],
        [c.radius for c in points],
        [damping[v] for _, v in joints],
        np.reshape([c.p_BC for c in points], -1),
        np.reshape([central_unit_inertia(M)[rows, cols] for M in inertias], -1),
        [springs.stiffness[v] for _, v in spring_joints],
        [springs.reference[v] for _, v in spring_joints],
    ]).astype(float)  # fmt: skip


def parameter_vector(
    values: np.ndarray | Mapping[str, float], names: tuple[str, ...], current: np.ndarray
) -> np.ndarray:
    """The parameter vector (T,) that
    :meth:`~drake_abs.multibody.stepper.ComplementarityStepper.with_parameters`'s ``values``
    give (an array in ``names`` order, or a mapping of some names to values, the others
    ``current``), checked: finite, and each within its range."""
    T = len(names)
    expected = (
        f"an array of all {T} parameter values in parameter_names order, or a mapping "
        "{name: value} of some of them"
    )
    if isinstance(values, Mapping):
        new = np.array(current, dtype=float)
        index = {n: j for j, n in enumerate(names)}
        for key, x in values.items():
            if key not in index:
                close = difflib.get_close_matches(str(key), names, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise ValueError(
                    f"values: unknown parameter name {key!r}{hint}; values must be {expected}, "
                    f"with names from parameter_names: {', '.join(names)}"
                )
            try:
                new[index[key]] = float(x)
            except (TypeError, ValueError):
                raise ValueError(f"values[{key!r}] must be a number; got {x!r}") from None
    else:
        try:
            new = np.array(values, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(
                f"values must be {expected}; got {type(values).__name__} {values!r:.80}"
            ) from None
        if new.shape != (T,):
            raise ValueError(f"values must be {expected}; got an array of shape {new.shape}")
    for j, name in enumerate(names):
        x = new[j]
        if not np.isfinite(x):
            raise ValueError(f"values[{name!r}] must be finite; got {x}")
        for prefix, (bound, strict, unit) in _PARAMETER_RANGES.items():
            if name.startswith(prefix) and (x <= bound if strict else x < bound):
                raise ValueError(
                    f"values[{name!r}] must be {'>' if strict else '>='} {bound:g}{unit}; got {x}"
                )
    return new


def with_values(
    model: ContactModelBase,
    damping: np.ndarray,
    joints: tuple[tuple[str, int], ...],
    names: tuple[str, ...],
    new: np.ndarray,
    current: np.ndarray,
    springs: JointSprings | None = None,
    spring_joints: tuple[tuple[str, int], ...] = (),
) -> tuple[ContactModelBase, np.ndarray, JointSprings | None, dict[str, float]]:
    """The contact model, joint damping (nv,) and joint springs whose parameter values are
    ``new`` (T,, checked: :func:`parameter_vector`), where ``model``, ``damping``, ``joints``,
    ``springs`` and ``spring_joints`` have ``current``; and the changed values ``{name:
    value}``.

    The plant is shared (its default inertias cannot change once finalized): where a value
    changed, the contact model is rebuilt on it with the bodies' inertias as overrides
    (:meth:`~drake_abs.multibody.drake_dynamics.ContactModelBase.rebuilt`); otherwise ``model``
    itself is returned.

    Raises:
        ValueError: for a unit inertia that is not physically valid (its moments must satisfy
            the triangle inequality).
    """
    value = dict(zip(names, new.tolist(), strict=True))
    changed = {n: x for n, x, old in zip(names, new.tolist(), current, strict=True) if x != old}
    m = model
    ground = m.ground
    if "ground_height" in changed:
        ground = replace(ground, height=value["ground_height"])
    rebuild = "ground_height" in changed
    contacts = list(m.contacts)
    for i, c in enumerate(contacts):
        fields = {}
        if f"friction[{i}]" in changed:
            fields["friction"] = value[f"friction[{i}]"]
        if f"radius[{i}]" in changed:
            fields["radius"] = value[f"radius[{i}]"]
        if any(f"offset[{i}].{a}" in changed for a in "xyz"):
            fields["p_BC"] = tuple(value[f"offset[{i}].{a}"] for a in "xyz")
        if fields:
            contacts[i] = replace(c, **fields)
            rebuild = True
    inertias = dict(m.spatial_inertias)
    for body, index in m._massive:
        keys = [f"mass[{body}]"] + [f"unit_inertia[{body}].{e}" for e in INERTIA_ENTRIES]
        if not any(k in changed for k in keys):
            continue
        G = [value[k] for k in keys[1:]]
        rebuild = True
        try:
            inertias[int(index)] = spatial_inertia(
                value[keys[0]], m.body_spatial_inertia(index).get_com(), G
            )
        except RuntimeError:  # Drake's check of the inertia's physical validity
            raise ValueError(
                f"values: unit_inertia[{body}] (xx, yy, zz, xy, xz, yz) = {tuple(G)} m^2 is "
                "not a physically valid unit inertia: its principal moments must be >= 0 and "
                "satisfy the triangle inequality"
            ) from None
    if rebuild:  # the provider, on the same plant
        model = m.rebuilt(contacts=contacts, ground=ground, spatial_inertias=inertias)
    damping = damping.copy()
    for joint, v in joints:
        damping[v] = value[f"damping[{joint}]"]
    if spring_joints:
        stiffness, reference = springs.stiffness.copy(), springs.reference.copy()
        for joint, v in spring_joints:
            stiffness[v] = value[f"stiffness[{joint}]"]
            reference[v] = value[f"springref[{joint}]"]
        springs = JointSprings(stiffness, reference, springs.q_index, springs.implicit)
    return model, damping, springs, changed


def parameter_columns(
    parameters: bool | Sequence[str], all_names: Callable[[], tuple[str, ...]]
) -> tuple[str, ...]:
    """The theta columns of ``parameters``: True (all), False (none) or some names, checked
    against ``all_names()`` (every column; called only when needed)."""
    if isinstance(parameters, (bool, np.bool_)):
        return all_names() if parameters else ()
    if isinstance(parameters, str):
        raise ValueError(f"parameters must be True, False or a sequence of names; got the "
                         f"string {parameters!r}")  # fmt: skip
    names = tuple(parameters)
    known = set(all_names())
    unknown = [n for n in names if n not in known]
    if unknown or len(set(names)) != len(names):
        raise ValueError(
            f"parameters must be distinct names among parameter_names; got {list(names)} "
            f"(unknown: {unknown})"
        )
    return names


def parameter_derivatives(
    model: ContactModelBase,
    idx: np.ndarray,
    cone: FrictionCone,
    q: np.ndarray,
    v: np.ndarray,
    u: np.ndarray,
    names: tuple[str, ...],
) -> ParameterDerivatives:
    """The theta block of one group's quantities (states q (B, nq), v (B, nv), inputs u
    (B, nu); contact candidates ``idx`` (n,) under ``cone``) for the T columns ``names``: every
    contact's distance falls by the ground height's increase; each frictional contact's
    coefficient is its own column; the masses and unit inertias move W and the free velocity; a
    point candidate's radius and offset move its distance and its rows
    (:meth:`~drake_abs.multibody.drake_dynamics.ContactModelBase.point_parameter_derivatives`);
    the smoothing parameters (trailing columns) move mu only. The joint-damping and
    joint-spring columns are filled in later, on the damped step (:func:`damping_columns`)."""
    column = {name: j for j, name in enumerate(names)}
    B, T = q.shape[0], len(names)
    nv = model.nv
    dphi = np.zeros((B, idx.size, T))
    if "ground_height" in column:
        dphi[:, :, column["ground_height"]] = -1.0
    dfriction = np.zeros((cone.frictional.size, T))
    for f, local in enumerate(cone.frictional):
        j = column.get(f"friction[{idx[local]}]")
        if j is not None:
            dfriction[f, j] = 1.0
    # the inertial columns asked for, and their columns of the provider's derivatives
    # (inertial_derivatives: every mass, then every body's six unit-inertia entries)
    bodies = model.massive_bodies
    inertial = [f"mass[{n}]" for n in bodies] + [
        f"unit_inertia[{n}].{e}" for n in bodies for e in INERTIA_ENTRIES
    ]
    pairs = [(column[key], k) for k, key in enumerate(inertial) if key in column]
    dW = np.zeros((B, nv, nv, T))
    dv_free = np.zeros((B, nv, T))
    if pairs:
        to, of = (list(x) for x in zip(*pairs, strict=True))
        dW_i, dv_free_i = model.inertial_derivatives(q, v, u)
        dW[..., to], dv_free[..., to] = dW_i[..., of], dv_free_i[..., of]
    # each candidate's geometry columns: radius, offset x, y, z (-1: not a column)
    geometry = np.array(
        [
            [column.get(key, -1) for key in (f"radius[{i}]", *(f"offset[{i}].{a}" for a in "xyz"))]
            for i in idx
        ],
        dtype=np.int64,
    ).reshape(idx.size, 4)
    dJn = dJt = None
    if (geometry >= 0).any():
        g_phi, g_Jn, g_Jt = model.point_parameter_derivatives(q, idx)
        dJn = np.zeros((B, idx.size, nv, T))
        dJt = np.zeros((B, cone.sizes()[1], nv, T))
        k = cone.directions
        for local, c in zip(*np.nonzero(geometry >= 0), strict=True):
            j = geometry[local, c]
            dphi[:, local, j] += g_phi[:, local, c]
            dJn[:, local, :, j] = g_Jn[:, local, :, c]
        for f, local in enumerate(cone.frictional):  # its k tangent rows
            for c in np.flatnonzero(geometry[local] >= 0):
                dJt[:, f * k : (f + 1) * k, :, geometry[local, c]] = g_Jt[
                    :, f * k : (f + 1) * k, :, c
                ]
    smoothing = [j for name, j in column.items() if name.startswith("smoothing.")]
    return ParameterDerivatives(
        dphi, dfriction, dW, dv_free, dJn=dJn, dJt=dJt,
        smoothing_from=min(smoothing) if smoothing else None,
    )  # fmt: skip


def damping_columns(
    par: ParameterDerivatives,
    quant: StepQuantities,
    names: tuple[str, ...],
    joints: tuple[tuple[str, int], ...],
    h: float,
    springs: JointSprings | None = None,
    spring_joints: tuple[tuple[str, int], ...] = (),
) -> ParameterDerivatives:
    """``par`` with the joint-damping columns of ``names`` (those of ``joints``) and the
    joint-spring columns (``stiffness[...]``, ``springref[...]`` of ``spring_joints``, with the
    ``springs`` of the step) filled in, on the damped step's ``W' = (M + h D')^-1`` (``D' = D +
    h K``) and ``v_free'`` (``quant``, at positions ``quant.q``; with no damping and no spring
    the undamped ones, W' = W) of time step h (s): for joint velocity j (position i),

    - ``dW'/dD_j = -h W' e_j e_j' W'``, ``dv_free'/dD_j = -h W' e_j v_free'_j``;
    - ``dW'/dK_j = h dW'/dD_j``, ``dv_free'/dK_j = -h W' e_j (h v_free'_j + q_i - q_ref,j)``;
    - ``dv_free'/dq_ref,j = h K_j W' e_j`` (W' does not move);
    - explicit springs (``springs.implicit`` False: ``D' = D``, W' does not depend on K):
      ``dW'/dK_j = 0``, ``dv_free'/dK_j = -h W' e_j (q_i - q_ref,j)``

    (docs/math.md section 6d)."""
    column = {name: j for j, name in enumerate(names)}
    cols = [(column[f"damping[{name}]"], v) for name, v in joints if f"damping[{name}]" in column]
    stiff, refs = [], []
    for name, v in spring_joints:
        if f"stiffness[{name}]" in column:
            stiff.append((column[f"stiffness[{name}]"], v))
        if f"springref[{name}]" in column:
            refs.append((column[f"springref[{name}]"], v))
    if not (cols or stiff or refs):
        return par
    W, v_free = quant.W, quant.v_free
    dW, dv_free = par.dW.copy(), par.dv_free.copy()
    for j, v in cols:
        dW[..., j] = -h * W[:, :, v, None] * W[:, None, v, :]
        dv_free[..., j] = -h * W[:, :, v] * v_free[:, v, None]
    for j, v in stiff:
        stretch = quant.q[:, springs.q_index[v]] - springs.reference[v]  # (B,)
        if springs.implicit:
            dW[..., j] = -(h**2) * W[:, :, v, None] * W[:, None, v, :]
            dv_free[..., j] = -h * W[:, :, v] * (h * v_free[:, v] + stretch)[:, None]
        else:
            dW[..., j] = 0.0
            dv_free[..., j] = -h * W[:, :, v] * stretch[:, None]
    for j, v in refs:
        dW[..., j] = 0.0
        dv_free[..., j] = h * springs.stiffness[v] * W[:, :, v]
    return replace(par, dW=dW, dv_free=dv_free)
