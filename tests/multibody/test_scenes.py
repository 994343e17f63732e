"""Scenes: YAML loading and validation, the complementarity plant built from them (only the
declared contacts, pruning far ones), and its AutoDiffXd gradient."""

import numpy as np
import pytest
import yaml
from numdiff import central_difference
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.systems.analysis import Simulator, Simulator_
from pydrake.systems.framework import DiagramBuilder

from drake_abs import ContactAware, Exact, Fixed
from drake_abs.multibody import ComplementarityStepper
from drake_abs.multibody.builder import build_scene_model
from drake_abs.multibody.packages import PACKAGE_DIR
from drake_abs.multibody.scene import Scene
from drake_abs.systems import ComplementarityPlant, autodiff

BOX = PACKAGE_DIR / "scenes" / "box_push.yaml"


def test_yaml_round_trip_and_validation():
    scene = Scene.from_yaml(BOX)
    assert scene.num_contacts == 4 and scene.friction_directions == 2
    assert Scene.from_yaml(scene.to_yaml()) == scene
    with pytest.raises(ValueError, match=r"smoothing.kind must be one of \['contact_aware'"):
        Scene.from_dict({**scene.to_dict(), "smoothing": {"kind": "magic"}})
    with pytest.raises(ValueError, match="unknown key 'smoothing.mu';"):
        Scene.from_dict({**scene.to_dict(), "smoothing": {"kind": "fixed", "mu": 1.0}})
    # a parameter of another kind: the kind's own parameters are named
    with pytest.raises(ValueError, match=r"bad smoothing parameters .* takes \['value'\]"):
        Scene.from_dict({**scene.to_dict(), "smoothing": {"kind": "fixed", "mu_max": 1.0}})
    with pytest.raises(ValueError, match=r"time_step must be a number > 0 \(s\); got 0.0"):
        Scene.from_dict({**scene.to_dict(), "time_step": 0.0})
    with pytest.raises(ValueError, match="unknown key 'gravity'; a scene takes the keys name,"):
        Scene.from_dict({**scene.to_dict(), "gravity": 3.0})
    with pytest.raises(FileNotFoundError, match="model file 'drake_abs:models/none.sdf'"):
        build_scene_model(
            Scene.from_dict({**scene.to_dict(), "models": [{"file": "drake_abs:models/none.sdf"}]})
        )


def test_plant_has_only_the_declared_contacts():
    model = build_scene_model(Scene.from_yaml(BOX)).contact_model
    assert len(model.contacts) == 4
    assert model.cone.sizes() == (4, 8, 4)


def test_sliding_box_matches_discrete_coulomb_and_stops():
    """Pushed off at 1 m/s with friction 0.5: v_k = 1 - 0.5 g h k until it stops, so the box
    travels h sum_k v_k (0.0970 m; the continuous answer v0^2 / (2 mu g) is 0.1019 m)."""
    sm = build_scene_model(Scene.from_yaml(BOX))
    stepper = ComplementarityStepper(sm.contact_model, Exact(), activation_distance=0.05)
    x = np.concatenate([sm.q0, sm.v0])
    for _ in range(60):
        r = stepper.step(x[None], np.zeros((1, 1)), jacobians=False)
        assert r.converged.all()
        x = r.x_next[0]
    dv = 0.5 * 9.81 * 0.01
    k = np.arange(1, int(1.0 / dv) + 1)
    expected = 0.01 * np.sum(1.0 - dv * k)
    assert x[0] == pytest.approx(expected, abs=1e-9)
    assert abs(x[3]) < 1e-9 and abs(x[1] - 0.1) < 1e-9  # at rest on the ground


def test_pruning_far_contacts_is_exact_for_hard_contact():
    """The two upper corners are 0.2 m above the ground: under exact contact, leaving them out
    of the LCP changes nothing beyond the solver tolerance."""
    sm = build_scene_model(Scene.from_yaml(BOX))
    full = ComplementarityStepper(sm.contact_model, Exact())
    pruned = ComplementarityStepper(sm.contact_model, Exact(), activation_distance=0.05)
    x = np.concatenate([sm.q0, sm.v0])[None]
    u = np.array([[3.0]])
    for _ in range(30):
        a, b = full.step(x, u), pruned.step(x, u)
        assert a.active.sum() == 4 and b.active.sum() == 2
        np.testing.assert_allclose(b.x_next, a.x_next, rtol=0, atol=1e-10)
        np.testing.assert_allclose(b.dx_dx, a.dx_dx, rtol=0, atol=1e-7)
        x = a.x_next


def test_pruning_under_smoothing_changes_results_by_the_dropped_impulses():
    """With mu > 0 a far contact still pushes (force at a distance, about mu / distance): pruning
    drops exactly that, so the change is bounded by the far contacts' impulses."""
    sm = build_scene_model(Scene.from_yaml(BOX))
    mu = 1e-5
    full = ComplementarityStepper(sm.contact_model, Fixed(mu))
    pruned = ComplementarityStepper(sm.contact_model, Fixed(mu), activation_distance=0.05)
    x = np.concatenate([sm.q0, sm.v0])[None]
    a, b = full.step(x, np.zeros((1, 1))), pruned.step(x, np.zeros((1, 1)))
    far = ~b.active[0]
    dropped = a.impulse[0, far]
    assert np.all(dropped > 0) and np.all(dropped < 2 * mu / 0.19)  # ~ mu / phi, phi ~ 0.2 m
    quant = sm.contact_model.quantities(x[:, :3], x[:, 3:], np.zeros((1, 1)))
    mobility = np.abs(quant.W[0] @ quant.Jn[0].T).max()  # velocity change per unit impulse
    dv = np.abs(a.x_next - b.x_next).max()
    assert 0 < dv <= 10 * dropped.sum() * mobility


def test_plant_diagram_gradient_matches_stepper_chain_rule_and_finite_differences():
    sm = build_scene_model(Scene.from_yaml(BOX))
    stepper = ComplementarityStepper(sm.contact_model, ContactAware(1e-3, 0.02), "total", 0.05)
    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("box", ComplementarityPlant(stepper))
    builder.ExportInput(plant.actuation_port, "push")
    diagram = builder.Build()
    x0 = np.concatenate([sm.q0 + [0.0, 0.02, 0.1], [0.5, -0.5, 0.0]])  # lands tilted
    u = np.array([2.0])
    n = 15

    # the core chain rule over n steps
    J = np.eye(6)
    x = x0.copy()
    for _ in range(n):
        r = stepper.step(x[None], u[None])
        J = r.dx_dx[0] @ J
        x = r.x_next[0]
    # Drake AutoDiffXd through the whole diagram
    ad = diagram.ToAutoDiffXd()
    sim = Simulator_[AutoDiffXd](ad)
    ctx = sim.get_mutable_context()
    p = ad.GetSubsystemByName("box")
    p.SetInitialState(
        p.GetMyMutableContextFromRoot(ctx), InitializeAutoDiff(x0.reshape(-1, 1)).ravel()
    )
    u_ad = InitializeAutoDiff(u.reshape(-1, 1), np.zeros((1, 6))).ravel()  # u held constant
    ad.get_input_port(0).FixValue(ctx, u_ad)
    sim.AdvanceTo(n * 0.01)
    (xN,), (g,) = autodiff.split([p.state_port.Eval(p.GetMyContextFromRoot(ctx))])
    np.testing.assert_array_equal(xN, x)
    np.testing.assert_allclose(g, J, rtol=1e-10, atol=1e-12)

    def final(x_init):
        s = Simulator(diagram)
        c = s.get_mutable_context()
        pp = diagram.GetSubsystemByName("box")
        pp.SetInitialState(pp.GetMyMutableContextFromRoot(c), x_init)
        diagram.get_input_port(0).FixValue(c, u)
        s.AdvanceTo(n * 0.01)
        return pp.state_port.Eval(pp.GetMyContextFromRoot(c)).copy()

    fd = central_difference(final, x0, eps=1e-7)
    np.testing.assert_allclose(J, fd, atol=1e-5 * (1 + np.abs(fd).max()))


def test_free_flight_step_has_the_free_jacobian():
    """No contact within the activation distance: no LCP, and the Jacobian is the free step's
    (regression: it was left uninitialised)."""
    sm = build_scene_model(Scene.from_yaml(BOX))
    stepper = ComplementarityStepper(sm.contact_model, Exact(), activation_distance=0.05)
    x = np.concatenate([sm.q0 + [0.0, 0.5, 0.0], [1.0, 0.0, 0.0]])  # 0.5 m up
    r = stepper.step(x[None], np.array([[1.0]]))
    assert not r.active.any()

    def step(p):
        return stepper.step(p[None, :6], p[None, 6:], jacobians=False).x_next[0]

    fd = central_difference(step, np.concatenate([x, [1.0]]), eps=1e-6)
    np.testing.assert_allclose(np.concatenate([r.dx_dx[0], r.dx_du[0]], axis=1), fd, atol=1e-8)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda d: d["contacts"][0].update(radius=float("nan")), "radius must be a finite"),
        (lambda d: d["contacts"][0].update(points=[[0.0, float("nan"), 0.0]]), "3 finite"),
        (
            lambda d: d["contacts"][0].update(points=[[0.0, 0.1]]),
            r"contacts\[0\].points\[0\] must be a point \[x, y, z\]: 3 numbers",
        ),
        (lambda d: d["contacts"][0].update(points=[["a", 0, 0]]), r"contacts\[0\].points"),
        (lambda d: d["contacts"][0].update(frction=0.5), r"unknown key 'contacts\[0\].frction'"),
        (lambda d: d["contacts"][0].update(friction=float("inf")), "friction must be"),
        (lambda d: d.update(ground_height=float("nan")), "ground_height must be finite"),
        (lambda d: d.update(ground_normal=[0, 0, 0]), "ground_normal"),
        (lambda d: d.update(initial_state={"qq": [0, 0, 0]}), "unknown key 'initial_state.qq'"),
        (lambda d: d["models"][0].update(weld_to="x"), r"models\[0\]"),
    ],
)
def test_hostile_scene_files_are_refused_naming_the_key(change, match):
    data = yaml.safe_load((PACKAGE_DIR / "scenes" / "box_push.yaml").read_text())
    change(data)
    with pytest.raises(ValueError, match=match):
        Scene.from_dict(data)


def _set_contact(**kw):
    return lambda d: d["contacts"][0].update(**kw)


def _set_model(**kw):
    return lambda d: d["models"][0].update(**kw)


def _set_smoothing(kind, **kw):
    return lambda d: d.update(smoothing={"kind": kind, **kw})


@pytest.mark.parametrize(
    ("change", "key"),
    [
        (lambda d: d.update(time_step="abc"), "time_step"),
        (lambda d: d.update(time_step=True), "time_step"),
        (lambda d: d.update(friction_directions="x"), "friction_directions"),
        (lambda d: d.update(friction_directions=2.5), "friction_directions"),
        (lambda d: d.update(ground_normal="up"), "ground_normal"),
        (lambda d: d.update(ground_normal=[0, 0, "1"]), "ground_normal"),
        (lambda d: d.update(ground_height=[1]), "ground_height"),
        (lambda d: d.update(activation_distance="far"), "activation_distance"),
        (lambda d: d.update(name=5), "name"),
        (lambda d: d.update(models="drake_abs:models/box_planar.sdf"), "models"),
        (lambda d: d.update(contacts={"body": "box"}), "contacts"),
        (_set_contact(radius="big"), r"contacts\[0\].radius"),
        (_set_contact(friction="high"), r"contacts\[0\].friction"),
        (_set_contact(points=[["0", "0", "0"]]), r"contacts\[0\].points"),
        (_set_contact(points=["123"]), r"contacts\[0\].points"),
        (_set_contact(points="abc"), r"contacts\[0\].points"),
        (_set_contact(body=3), r"contacts\[0\].body"),
        (_set_contact(model=[1]), r"contacts\[0\].model"),
        (_set_model(file=3), r"models\[0\].file"),
        (_set_model(actuate="hip"), r"models\[0\].actuate"),
        (_set_model(actuate=5), r"models\[0\].actuate"),
        (_set_model(name=[1]), r"models\[0\].name"),
        (_set_model(weld=2), r"models\[0\].weld"),
        (lambda d: d.update(smoothing="fixed"), "smoothing"),
        (lambda d: d.update(smoothing={"kind": 3}), "smoothing.kind"),
        (lambda d: d.update(smoothing={"kind": "fixed", "value": "big"}), "smoothing.value"),
        (_set_smoothing("contact_aware", mu_max=[1], length=0.1), "smoothing.mu_max"),
        (_set_smoothing("fixed", value=1e-3, reference_time_step="0.01"), "reference_time_step"),
        (lambda d: d.update(dynamics=3), "dynamics"),
        (lambda d: d.update(friction_model=["anitescu"]), "friction_model"),
        (lambda d: d.update(initial_state=[1, 2]), "initial_state"),
        (lambda d: d.update(initial_state={"q": "abc"}), r"initial_state.q"),
        (lambda d: d.update(initial_state={"q": [0, "a", 0]}), r"initial_state.q"),
        (lambda d: d.update(initial_state={"v": 5}), r"initial_state.v"),
    ],
)
def test_wrongly_typed_scene_values_are_refused_naming_the_key(change, key):
    """Issue 13: each of these failed with a message that did not name the key (or was taken
    silently: a string ``actuate`` became its letters, a string point its digits)."""
    data = yaml.safe_load((PACKAGE_DIR / "scenes" / "box_push.yaml").read_text())
    change(data)
    with pytest.raises(ValueError, match=key) as err:
        Scene.from_dict(data)
    if key != "name":
        assert "scene 'box_push'" in str(err.value)


def test_initial_state_of_the_wrong_length_is_refused_when_the_plant_is_built():
    data = yaml.safe_load((PACKAGE_DIR / "scenes" / "box_push.yaml").read_text())
    data["initial_state"] = {"q": [0.0, 0.1]}
    with pytest.raises(ValueError, match="initial_state q"):
        build_scene_model(Scene.from_dict(data))


def test_yaml_exponent_numbers_are_numbers_and_quoted_ones_are_not():
    """PyYAML reads ``1e-3`` (no dot) as a string; scene files read it as the number."""
    text = BOX.read_text().replace("time_step: 0.01", "time_step: 1e-2")
    assert Scene.from_yaml(text).time_step == 0.01
    with pytest.raises(ValueError, match="time_step"):
        Scene.from_yaml(text.replace("time_step: 1e-2", "time_step: '1e-2'"))


def test_scenes_built_in_python_are_checked_and_normalised_too():
    scene = Scene.from_yaml(BOX)
    same = Scene(**{**scene.__dict__, "time_step": 1, "ground_normal": [0, 0, 1]})
    assert same.time_step == 1.0 and isinstance(same.time_step, float)
    assert same.ground_normal == (0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="ground_height"):
        Scene(**{**scene.__dict__, "ground_height": "0"})


def _barrier_box(time_step: float, reference_time_step: float | None) -> Scene:
    """The box under ContactAware(1e-2, 0.05), every corner in the LCP."""
    smoothing = {"kind": "contact_aware", "mu_max": 1e-2, "length": 0.05}
    if reference_time_step is not None:
        smoothing["reference_time_step"] = reference_time_step
    data = {**Scene.from_yaml(BOX).to_dict(), "time_step": time_step, "smoothing": smoothing}
    return Scene.from_dict({**data, "activation_distance": float("inf")})


def test_reference_time_step_wraps_the_scene_smoothing_and_reaches_the_stepper():
    from drake_abs.contact.smoothing import TimeStepScaled

    scene = _barrier_box(1e-3, 0.01)
    smoothing = scene.make_smoothing()
    assert isinstance(smoothing, TimeStepScaled) and smoothing.scale == pytest.approx(0.1)
    assert smoothing.smoothing == ContactAware(1e-2, 0.05)
    assert build_scene_model(scene).stepper().smoothing == smoothing
    assert Scene.from_yaml(scene.to_yaml()) == scene
    assert _barrier_box(0.01, 0.01).make_smoothing() == ContactAware(1e-2, 0.05)
    assert _barrier_box(1e-3, None).make_smoothing() == ContactAware(1e-2, 0.05)
    gaussian = {"kind": "gaussian_matched", "sigma": 0.002, "reference_time_step": 0.01}
    with pytest.raises(ValueError, match="reference_time_step"):
        Scene.from_dict({**scene.to_dict(), "smoothing": gaussian})
    negative = {"kind": "fixed", "value": 1e-3, "reference_time_step": -0.01}
    with pytest.raises(ValueError, match="reference_time_step"):
        Scene.from_dict({**scene.to_dict(), "smoothing": negative})


def _box_heights(scene: Scene, x0: np.ndarray, duration: float):
    """The box's heights z (m) per step from x0, and the last state."""
    sm = build_scene_model(scene)
    stepper = sm.stepper()
    x, u = x0[None], np.zeros((1, sm.contact_model.nu))
    z = []
    for _ in range(int(round(duration / scene.time_step))):
        step = stepper.step(x, u, jacobians=False)
        assert step.converged.all()
        x = step.x_next
        z.append(x[0, 1])
    return np.array(z), x[0]


def test_a_box_resting_on_the_barrier_is_not_launched_at_a_finer_step():
    """Settled at h = 10 ms the box floats 6.6 cm up (z = 0.1665 m). At h = 1 ms with the
    smoothing stated at 10 ms it stays there (measured: max z 0.1674 m); stated at 1 ms (the
    default reference, the same mu) it is thrown to 0.50 m."""
    rest = _barrier_box(0.01, None)
    sm = build_scene_model(rest)
    _, x_rest = _box_heights(rest, np.concatenate([sm.q0, np.zeros(3)]), 3.0)
    z_rest = x_rest[1]
    assert 0.15 < z_rest < 0.18 and abs(x_rest[4]) < 0.01  # floating, nearly still
    scaled, _ = _box_heights(_barrier_box(1e-3, 0.01), x_rest, 0.3)
    assert scaled.max() < z_rest + 0.002 and scaled[-1] == pytest.approx(z_rest, abs=0.002)
    unscaled, _ = _box_heights(_barrier_box(1e-3, None), x_rest, 0.3)
    assert unscaled.max() > z_rest + 0.2
