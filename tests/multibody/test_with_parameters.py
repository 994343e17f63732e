"""``ComplementarityStepper.with_parameters``: a stepper with other model parameters, each of
which takes effect (a step equals the step of the scene re-built with that parameter changed, for
both dynamics providers), that round-trips its values and pickles; and the unit-inertia columns of
``dx_dtheta`` (docs/math.md section 6d) against central differences of its steps."""

from __future__ import annotations

import pickle
from dataclasses import replace

import numpy as np
import pytest
from scene_variants import (
    contact_state,
    with_friction,
    with_inertia,
    with_joint_damping,
    with_mass,
)

from drake_abs.contact.smoothing import Exact, Fixed
from drake_abs.multibody import ComplementarityStepper, Scene, build_scene_model
from drake_abs.multibody.drake_dynamics import INERTIA_ENTRIES, central_unit_inertia

SCENES = ("box_push", "hopper", "gym_hopper", "ball_throw")
DYNAMICS = ("pinocchio", "drake")
#: agreement of a with_parameters step with the re-built scene's step, relative to each
#: array's largest entry (both evaluate the same numbers in another order)
SAME = 1e-10


def _scene(name: str, dynamics: str) -> Scene:
    return replace(Scene.load(name), dynamics=dynamics)


def _states(name: str, model) -> tuple[np.ndarray, np.ndarray]:
    """A state in contact with an input, per scene (away from contact-mode switches); the ball
    also spins, so that its inertia matters."""
    x, u = contact_state(name, model)
    if name == "ball_throw":
        x[7:10] = [2.0, -1.0, 0.5]
    return x, u


def _step(stepper: ComplementarityStepper, x, u):
    step = stepper.step(x[None], u, parameters=True)
    assert step.converged.all()
    return step


def _assert_same_step(got, want, what: str) -> None:
    """Two steps agree (the next state, impulses and every Jacobian), to SAME of each array's
    largest entry."""
    assert got.theta_names == want.theta_names
    for key in ("x_next", "impulse", "friction_impulse", "dx_dx", "dx_du", "dx_dtheta",
                "dimpulse_dtheta"):  # fmt: skip
        a, b = getattr(got, key), getattr(want, key)
        scale = 1.0 + np.abs(b).max(initial=0.0)
        err = np.abs(a - b).max(initial=0.0)
        assert err <= SAME * scale, f"{what}: {key} differs by {err:.3g} (largest {scale:.3g})"


def _candidates(scene: Scene) -> list[list[int]]:
    """The contact candidates of each ``contacts`` entry (listed points, in order)."""
    out, start = [], 0
    for spec in scene.contacts:
        out.append(list(range(start, start + len(spec.points))))
        start += len(spec.points)
    return out


def _body_inertia(model, body: str) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass (kg), com (m), unit inertia about the com (m^2, the six entries)) of ``body``."""
    cm = model.contact_model
    index = dict(cm._massive)[body]
    M = cm.body_spatial_inertia(index)
    G = central_unit_inertia(M)
    return M.get_mass(), np.asarray(M.get_com()), G[[0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]]


def _variants(name: str, scene: Scene, model, folder):
    """``(kind, {name: value}, the scene re-built with that change)`` for each kind of
    parameter."""
    cm = model.contact_model
    specs = _candidates(scene)
    # ground height
    yield "ground", {"ground_height": 0.003}, replace(scene, ground_height=0.003)
    # friction: one entry moves the coefficient of all its points
    for k, spec in enumerate(scene.contacts):
        value = spec.friction + 0.15
        changes = {f"friction[{i}]": value for i in specs[k]}
        yield f"friction{k}", changes, with_friction(scene, k, 0.15)
    # masses (centre of mass and unit inertia held)
    for body in cm.massive_bodies:
        m, com, G = _body_inertia(model, body)
        factor = 1.2
        if scene.models[0].file.endswith(".xml"):  # MJCF: inertia from the geoms
            other = with_inertia(scene, body, m * factor, G, folder, com=com)
        else:
            other = with_mass(scene, body, factor, folder)
        yield f"mass[{body}]", {f"mass[{body}]": m * factor}, other
    # unit inertias: every entry of one body at a time (moments scaled alike, which keeps the
    # triangle inequality, and small products)
    for body in cm.massive_bodies:
        m, com, G = _body_inertia(model, body)
        new = G.copy()
        new[:3] *= 1.1
        new[3:] += np.array([0.03, -0.02, 0.01]) * G[:3].min()
        changes = {
            f"unit_inertia[{body}].{e}": x for e, x in zip(INERTIA_ENTRIES, new, strict=True)
        }
        yield f"inertia[{body}]", changes, with_inertia(scene, body, m, new, folder, com=com)
    # radius and offset of the first entry's first point, and its radius for all its points
    spec = scene.contacts[0]
    i = specs[0][0]
    radii = {f"radius[{j}]": spec.radius + 0.01 for j in specs[0]}
    yield "radius", radii, replace(scene, contacts=(replace(spec, radius=spec.radius + 0.01),
                                                    *scene.contacts[1:]))  # fmt: skip
    points = [list(p) for p in spec.points]
    points[0] = [points[0][0] + 0.01, points[0][1] - 0.02, points[0][2] + 0.005]
    moved = replace(spec, points=tuple(tuple(p) for p in points))
    offsets = {f"offset[{i}].{a}": x for a, x in zip("xyz", points[0], strict=True)}
    yield "offset", offsets, replace(scene, contacts=(moved, *scene.contacts[1:]))
    # joint damping (one-velocity joints only: the ball has none)
    joints = [n[len("damping[") : -1] for n in model.stepper().parameter_names
              if n.startswith("damping[")]  # fmt: skip
    if joints:
        joint = joints[-1]
        yield "damping", {f"damping[{joint}]": 2.5}, with_joint_damping(scene, joint, 2.5, folder)


CASES = [(n, d) for n in SCENES for d in DYNAMICS]


@pytest.mark.parametrize("name, dynamics", CASES, ids=["-".join(c) for c in CASES])
def test_each_parameter_takes_effect_as_in_the_rebuilt_scene(name, dynamics, tmp_path):
    """A step of ``with_parameters`` (next state, impulses, every Jacobian, the parameter
    columns included) equals the step of the scene re-built with that parameter changed; the
    original stepper is left as it was."""
    scene = _scene(name, dynamics)
    model = build_scene_model(scene)
    stepper = model.stepper(smoothing=Fixed(1e-3))
    x, u = _states(name, model)
    before = _step(stepper, x, u)
    values = stepper.parameter_values()
    kinds = set()
    for kind, changes, other in _variants(name, scene, model, tmp_path):
        changed = stepper.with_parameters(changes)
        assert type(changed.model) is type(model.contact_model)
        reference = build_scene_model(other).stepper(smoothing=Fixed(1e-3))
        got, want = _step(changed, x, u), _step(reference, x, u)
        _assert_same_step(got, want, kind)
        np.testing.assert_allclose(
            changed.parameter_values(), reference.parameter_values(), rtol=1e-13, atol=1e-16
        )
        moved = max(np.abs(got.x_next - before.x_next).max(),
                    np.abs(got.impulse - before.impulse).max())  # fmt: skip
        assert moved > 1e-9 or kind.startswith("friction"), f"{kind} did not move the step"
        kinds.add(kind.split("[")[0].rstrip("0123456789"))
    assert {"ground", "friction", "mass", "inertia", "radius", "offset"} <= kinds
    assert ("damping" in kinds) == (name != "ball_throw")
    # the original is untouched
    np.testing.assert_array_equal(stepper.parameter_values(), values)
    _assert_same_step(_step(stepper, x, u), before, "original")


@pytest.mark.parametrize("name", SCENES)
def test_parameter_values_round_trip(name):
    model = build_scene_model(name)
    stepper = model.stepper()
    names, values = stepper.parameter_names, stepper.parameter_values()
    # the scene's own values: the same step
    same = stepper.with_parameters(values)
    np.testing.assert_array_equal(same.parameter_values(), values)
    assert same.model is stepper.model  # nothing changed: the provider is shared
    # every column moved (each within its range): read back as given
    rng = np.random.default_rng(7)
    new = values * (1.0 + 0.05 * rng.uniform(0.5, 1.0, values.size)) + 0.001 * (values == 0)
    inertia = [j for j, n in enumerate(names) if n.startswith("unit_inertia[")]
    products = [j for j in inertia if names[j][-2:] in ("xy", "xz", "yz")]
    new[products] = values[products]  # (kept physically valid below)
    for j in products:  # small products
        body = names[j][len("unit_inertia[") : names[j].index("]")]
        moments = [new[names.index(f"unit_inertia[{body}].{e}")] for e in ("xx", "yy", "zz")]
        new[j] = 0.01 * min(moments)
    for body in model.contact_model.massive_bodies:  # moments: one common scale per body
        cols = [names.index(f"unit_inertia[{body}].{e}") for e in ("xx", "yy", "zz")]
        new[cols] = values[cols] * 1.07
    other = stepper.with_parameters(new)
    np.testing.assert_allclose(other.parameter_values(), new, rtol=1e-13, atol=1e-17)
    assert not np.array_equal(other.parameter_values(), values)
    np.testing.assert_array_equal(stepper.parameter_values(), values)  # untouched
    # and back again
    back = other.with_parameters(values)
    np.testing.assert_allclose(back.parameter_values(), values, rtol=1e-13, atol=1e-17)
    # a mapping changes its names only
    first = names.index(f"mass[{model.contact_model.massive_bodies[0]}]")
    partial = stepper.with_parameters({names[first]: 2.0 * values[first], "ground_height": -0.01})
    want = values.copy()
    want[first], want[0] = 2.0 * values[first], -0.01
    got = partial.parameter_values()
    assert got[first] == want[first] and got[0] == want[0]  # stored as given
    # the body's unit inertia is re-derived (shifted to its origin and back): to rounding
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-17)


@pytest.mark.parametrize("dynamics", DYNAMICS)
@pytest.mark.parametrize("name", SCENES)
def test_a_stepper_with_parameters_pickles(name, dynamics):
    model = build_scene_model(_scene(name, dynamics))
    stepper = model.stepper(smoothing=Fixed(1e-3))
    x, u = _states(name, model)
    names, values = stepper.parameter_names, stepper.parameter_values()
    new = values.copy()
    for j, n in enumerate(names):  # a change of every kind
        if n.startswith(("friction[", "mass[", "radius[", "damping[")) or n == "ground_height":
            new[j] = values[j] * 1.1 + 0.002
        elif n.startswith("offset["):
            new[j] = values[j] + 0.003
        elif n.startswith("unit_inertia[") and n[-2] == n[-1]:  # moments
            new[j] = values[j] * 1.05
    changed = stepper.with_parameters(new).with_smoothing(Fixed(2e-3))
    restored = pickle.loads(pickle.dumps(changed))
    assert type(restored.model) is type(changed.model)
    np.testing.assert_array_equal(restored.parameter_values(), changed.parameter_values())
    assert restored.smoothing == changed.smoothing
    a, b = _step(changed, x, u), _step(restored, x, u)
    for key in ("x_next", "impulse", "dx_dx", "dx_du", "dx_dtheta"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key), err_msg=key)
    # a second change is carried along with the first
    twice = changed.with_parameters({"ground_height": 0.004})
    again = pickle.loads(pickle.dumps(twice))
    np.testing.assert_array_equal(again.parameter_values(), twice.parameter_values())
    # a stepper built from a contact model has no scene to send, with parameters or not
    bare = ComplementarityStepper(model.contact_model).with_parameters({"ground_height": 0.01})
    with pytest.raises(TypeError, match="cannot be pickled"):
        pickle.dumps(bare)


def _inertial_columns(names, body: str) -> list[int]:
    return [names.index(f"mass[{body}]")] + [
        names.index(f"unit_inertia[{body}].{e}") for e in INERTIA_ENTRIES
    ]


#: the relative step of the differences (of each body's largest moment, or of its mass)
REL_EPS = 1e-4
#: relative agreement with the differences demanded, of the block's largest entry
RTOL = 1e-5


@pytest.mark.parametrize("dynamics", DYNAMICS)
@pytest.mark.parametrize("smoothing", [Exact(), Fixed(1e-3)], ids=["exact", "fixed"])
@pytest.mark.parametrize("name", SCENES)
def test_inertia_columns_match_central_differences(name, smoothing, dynamics):
    """Each body's mass and unit-inertia columns of dx_dtheta and dimpulse_dtheta against
    central differences of ``with_parameters`` steps. The physics: a planar model (the hoppers,
    the box: every rotation about y) depends on the yy entries only."""
    model = build_scene_model(_scene(name, dynamics))
    stepper = model.stepper(smoothing=smoothing)
    x, u = _states(name, model)
    r = _step(stepper, x, u)
    assert r.active.any() and (r.impulse > 1e-6).any()
    names, values = stepper.parameter_names, stepper.parameter_values()
    bodies = model.contact_model.massive_bodies
    columns = [j for body in bodies for j in _inertial_columns(names, body)]
    analytic = np.concatenate([r.dx_dtheta[0], r.dimpulse_dtheta[0]])
    block = np.abs(analytic[:, columns]).max()
    worst = 0.0
    for body in bodies:
        moments = values[[names.index(f"unit_inertia[{body}].{e}") for e in ("xx", "yy", "zz")]]
        for j in _inertial_columns(names, body):
            eps = REL_EPS * (values[j] if names[j].startswith("mass[") else moments.max())

            def f(d, j=j):
                s = _step(stepper.with_parameters({names[j]: values[j] + d}), x, u)
                return np.concatenate([s.x_next[0], s.impulse[0]])

            fd = (f(eps) - f(-eps)) / (2 * eps)
            err = np.abs(analytic[:, j] - fd).max()
            assert err <= RTOL * block, f"{names[j]}: error {err:.3g}, block {block:.3g}"
            worst = max(worst, err / block)
    planar = name != "ball_throw"
    for body in bodies:
        for e in INERTIA_ENTRIES:
            column = analytic[:, names.index(f"unit_inertia[{body}].{e}")]
            if planar and e != "yy":  # rotations about y only: these entries never enter
                assert np.abs(column).max() <= 1e-12 * block, (body, e)
    if name == "hopper":  # in contact, torques applied: the inertias matter
        yy = [names.index(f"unit_inertia[{b}].yy") for b in bodies]
        assert np.abs(analytic[:, yy]).max() > 1.0
    if name == "ball_throw":  # a spinning ball sliding on the ground: its inertia matters
        moments = [names.index(f"unit_inertia[ball].{e}") for e in ("xx", "yy", "zz")]
        assert np.abs(analytic[:, moments]).max() > 1.0


def test_bad_parameters_are_refused_with_the_expected_form():
    model = build_scene_model("hopper")
    stepper = model.stepper()
    names, values = stepper.parameter_names, stepper.parameter_values()
    T = len(names)
    with pytest.raises(ValueError, match=rf"values must be an array of all {T} .*parameter_names "
                                         r"order, or a mapping .*shape \(3,\)"):  # fmt: skip
        stepper.with_parameters(values[:3])
    with pytest.raises(ValueError, match="values must be an array"):
        stepper.with_parameters(np.ones((2, T)))
    with pytest.raises(ValueError, match="values must be an array"):
        stepper.with_parameters("ground_height")
    with pytest.raises(ValueError, match=r"unknown parameter name 'mass\[bdy\]' \(did you mean "
                                         r"'mass\[body\]'\?\).*parameter_names"):  # fmt: skip
        stepper.with_parameters({"mass[bdy]": 1.0})
    with pytest.raises(ValueError, match=r"values\['ground_height'\] must be a number"):
        stepper.with_parameters({"ground_height": "high"})
    for bad in (np.nan, np.inf):
        with pytest.raises(ValueError, match=r"values\['radius\[0\]'\] must be finite"):
            stepper.with_parameters({"radius[0]": bad})
        array = values.copy()
        array[names.index("offset[0].z")] = bad
        with pytest.raises(ValueError, match=r"values\['offset\[0\]\.z'\] must be finite"):
            stepper.with_parameters(array)
    cases = {
        "mass[body]": (0.0, r"> 0 kg"),
        "radius[0]": (-0.01, r">= 0 m"),
        "friction[0]": (-0.1, r">= 0"),
        "damping[hip]": (-1.0, r">= 0 N m s / rad or N s / m"),
    }
    for key, (bad, form) in cases.items():
        with pytest.raises(ValueError, match=rf"values\['{key.replace('[', r'\[')}'\] must be "
                                             rf"{form}; got"):  # fmt: skip
            stepper.with_parameters({key: bad})
    with pytest.raises(ValueError, match=r"unit_inertia\[upper_leg\].*not a physically valid"):
        stepper.with_parameters({"unit_inertia[upper_leg].zz": 0.1})  # > xx + yy
    with pytest.raises(ValueError, match=r"unit_inertia\[body\].*not a physically valid"):
        stepper.with_parameters({"unit_inertia[body].xx": -1e-3})
    # the edges of the ranges are allowed
    edge = stepper.with_parameters({"radius[0]": 0.0, "friction[0]": 0.0, "damping[hip]": 0.0})
    assert edge.parameter_values()[names.index("radius[0]")] == 0.0
    np.testing.assert_array_equal(stepper.parameter_values(), values)  # untouched throughout


def test_the_providers_check_their_inertia_overrides():
    from pydrake.multibody.tree import SpatialInertia

    cm = build_scene_model("box_push").contact_model
    box = int(dict(cm._massive)["box"])
    with pytest.raises(ValueError, match="spatial_inertias: 0 is not the index"):
        cm.rebuilt(spatial_inertias={0: SpatialInertia.SolidSphereWithMass(1.0, 0.1)})
    with pytest.raises(ValueError, match=r"spatial_inertias\[\d+\] must be a physically valid"):
        cm.rebuilt(spatial_inertias={box: "heavy"})
    heavy = cm.rebuilt(spatial_inertias={box: SpatialInertia.SolidSphereWithMass(2.0, 0.1)})
    assert heavy.body_spatial_inertia(box).get_mass() == 2.0
    assert cm.body_spatial_inertia(box).get_mass() == 1.0
    # its dynamics use it: the mass matrix of the translating box doubles
    q = np.zeros((1, cm.nq))
    W0 = cm.quantities(q, q, np.zeros((1, cm.nu)), derivatives=False).W
    W1 = heavy.quantities(q, q, np.zeros((1, cm.nu)), derivatives=False).W
    np.testing.assert_allclose(W1[0, :2, :2], W0[0, :2, :2] / 2.0, rtol=1e-14)
