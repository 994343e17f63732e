"""Contact candidates from collision geometry: body-ground shapes expanded to exact point
candidates, body-body pairs in closed form (Drake provider, AutoDiffXd derivatives), and the
pusher_box manipulation scene."""

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs import Exact, Fixed
from drake_abs.contact.contact_lcp import contact_step
from drake_abs.multibody.builder import build_scene_model, scene_contacts
from drake_abs.multibody.drake_dynamics import GroundPlane, MultibodyContactModel
from drake_abs.multibody.geometry_contacts import PairContact, Shape, pair_geometry
from drake_abs.multibody.scene import Scene

H = 0.01
CAPSULE_SDF = """<?xml version="1.0"?>
<sdf version="1.9"><model name="pill"><link name="pill">
  <pose>0 0 0.3 0 0 0</pose>
  <inertial><mass>0.3</mass><inertia><ixx>0.001</ixx><iyy>0.001</iyy><izz>0.0005</izz>
    <ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia></inertial>
  <collision name="c"><pose>0 0 0 0 1.5707963267948966 0</pose>
    <geometry><capsule><radius>0.04</radius><length>0.2</length></capsule></geometry>
  </collision>
</link></model></sdf>"""


def box_scene(contacts, **extra):
    return Scene.from_dict({
        "name": "geometry_box",
        "models": [{"file": "drake_abs:models/box_floating.sdf"}],
        "contacts": contacts,
        "friction_model": "anitescu",
        "initial_state": {"q": [0.0, 0.0, 0.2, 0.3, 0.2, -0.1], "v": [0.5, 0, -1, 0, 1, 0]},
        **extra,
    })  # fmt: skip


def rollout(sm, steps, policy=None):
    stepper = sm.stepper(smoothing=Exact())
    xs = [sm.x0]
    for _ in range(steps):
        u = np.zeros(sm.plant.num_actuators()) if policy is None else policy(xs[-1])
        r = stepper.step(xs[-1][None], u[None], jacobians=False)
        assert r.converged[0]
        xs.append(r.x_next[0])
    return np.array(xs)


def test_box_geometry_expands_to_its_eight_vertices_and_steps_as_listed_points():
    corners = [
        [sx * 0.1, sy * 0.1, sz * 0.05] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)
    ]
    listed = build_scene_model(box_scene([{"body": "box", "points": corners, "friction": 0.5}]))
    geometry = build_scene_model(
        box_scene([{"body": "box", "geometry": "collision", "friction": 0.5}])
    )
    assert sorted(c.p_BC for c in geometry.contact_model.contacts) == sorted(map(tuple, corners))
    assert geometry.scene.num_contacts == 8
    np.testing.assert_allclose(rollout(geometry, 60), rollout(listed, 60), atol=1e-12)


def test_dropped_box_and_capsule_rest_at_their_heights(tmp_path):
    box = rollout(build_scene_model(box_scene(
        [{"body": "box", "geometry": "collision", "friction": 0.5}])), 150)  # fmt: skip
    assert box[-1, 2] == pytest.approx(0.05, abs=2e-4)  # half its height (no tilt)
    assert abs(box[-1, 4]) < 1e-3 and abs(box[-1, 5]) < 1e-3
    path = tmp_path / "pill.sdf"
    path.write_text(CAPSULE_SDF)
    scene = Scene.from_dict({
        "name": "pill", "models": [{"file": str(path)}], "friction_model": "anitescu",
        "contacts": [{"body": "pill", "geometry": "collision", "friction": 0.5}],
    })  # fmt: skip
    sm = build_scene_model(scene)
    assert [c.radius for c in sm.contact_model.contacts] == [0.04, 0.04]
    # the end-cap centres are at +-0.1 along the capsule's axis (turned onto the body's x axis)
    centres = sorted(c.p_BC for c in sm.contact_model.contacts)
    np.testing.assert_allclose(centres, [[-0.1, 0, 0], [0.1, 0, 0]], atol=1e-12)
    x = rollout(sm, 150)
    assert x[-1, 2] == pytest.approx(0.04, abs=2e-4)  # lying on its side: its radius


def test_geometry_entries_are_checked():
    with pytest.raises(ValueError, match="points .* or geometry, not both"):
        box_scene([{"body": "box", "geometry": "collision", "points": [[0, 0, 0]]}])
    with pytest.raises(ValueError, match="geometry must be one of"):
        box_scene([{"body": "box", "geometry": "visual"}])
    with pytest.raises(ValueError, match="no collision geometry"):
        scene_contacts(Scene.from_dict({
            "name": "x", "models": [{"file": "drake_abs:models/box_planar.sdf"}],
            "contacts": [{"body": "box", "geometry": "collision"}],
        }))  # fmt: skip


def test_closed_forms_against_hand_values():
    sphere, box = Shape("sphere", (0.1,)), Shape("box", (0.4, 0.2, 0.2))
    I, z = np.eye(3), np.zeros(3)
    # sphere above the box's top face: 0.05 clear
    phi, n, pa, pb = pair_geometry(PairContact("a", sphere, "b", box), I, [0.1, 0, 0.25], I, z)
    assert phi == pytest.approx(0.05)
    np.testing.assert_allclose(n, [0, 0, 1])
    np.testing.assert_allclose(pa, [0.1, 0, 0.15])
    np.testing.assert_allclose(pb, [0.1, 0, 0.1])
    # the same pair the other way round: normal from B (now the sphere) to A (the box)
    phi2, n2, pa2, pb2 = pair_geometry(PairContact("b", box, "a", sphere), I, z, I, [0.1, 0, 0.25])
    assert phi2 == pytest.approx(phi) and np.allclose(n2, -n) and np.allclose(pa2, pb)
    # off a corner edge: distance to the edge
    phi, n, _, _ = pair_geometry(PairContact("a", sphere, "b", box), I, [0.3, 0, 0.2], I, z)
    assert phi == pytest.approx(np.hypot(0.1, 0.1) - 0.1)
    # centre inside the box, nearest the +y face (depth 0.02): penetration depth + radius
    phi, n, _, _ = pair_geometry(PairContact("a", sphere, "b", box), I, [0.0, 0.08, 0.0], I, z)
    assert phi == pytest.approx(-0.02 - 0.1) and np.allclose(n, [0, 1, 0])
    # sphere against a capsule's side and its end cap
    capsule = Shape("capsule", (0.05, 0.4))
    phi, n, _, _ = pair_geometry(PairContact("a", sphere, "b", capsule), I, [0.2, 0, 0.1], I, z)
    assert phi == pytest.approx(0.2 - 0.15) and np.allclose(n, [1, 0, 0])
    phi, n, _, _ = pair_geometry(PairContact("a", sphere, "b", capsule), I, [0, 0, 0.5], I, z)
    assert phi == pytest.approx(0.3 - 0.15) and np.allclose(n, [0, 0, 1])
    with pytest.raises(NotImplementedError, match="sphere on one side"):
        PairContact("a", box, "b", box)


def pusher_model(pairs):
    sm = build_scene_model("pusher_box")
    ground = sm.contact_model.contacts[:8]
    return sm, MultibodyContactModel(sm.plant, ground + pairs, GroundPlane(), H, 4)


PUSH_STATE = (  # the pusher pressed into the box's -x face, off-centre, box tilted and turning
    np.array([0.0, 0.03, 0.0, 0.0, 0.0505, 0.1, 0.02, -0.01]),
    np.array([0.3, 0.1, 0.1, -0.05, -0.05, 0.2, 0.3, -0.2]),
)


@pytest.mark.parametrize("order", ["sphere_first", "box_first"])
@pytest.mark.parametrize("policy", [Exact(), Fixed(1e-5)], ids=repr)
def test_pair_step_jacobian_matches_finite_differences(order, policy):
    sphere, box = Shape("sphere", (0.03,)), Shape("box", (0.2, 0.2, 0.1))
    pair = (PairContact("pusher", sphere, "box", box, 0.3) if order == "sphere_first"
            else PairContact("box", box, "pusher", sphere, 0.3))  # fmt: skip
    sm, model = pusher_model([pair])
    model.cone = model.cone.with_formulation("anitescu")
    q, v = PUSH_STATE
    q = q.copy()
    q[0] = 0.01  # the sphere about 5 mm into the box's -x face (the pusher starts 5 mm off)
    u = np.array([20.0, -5.0])
    nq, nv = model.nq, model.nv
    r = contact_step(model.quantities(q[None], v[None], u[None]), model.cone, H, policy,
                     gradient="total")  # fmt: skip
    assert r.converged.all()
    assert model.distances(q[None])[0, -1] < 0
    assert r.lam[0, len(model.contacts) - 1] > 1e-3  # the pair pushes

    def step(p):
        quant = model.quantities(p[None, :nq], p[None, nq : nq + nv], p[None, nq + nv :])
        out = contact_step(quant, model.cone, H, policy)
        return np.concatenate([out.q_next[0], out.v_next[0]])

    fd = central_difference(step, np.concatenate([q, v, u]), eps=1e-7)
    analytic = np.concatenate([r.dx_dx[0], r.dx_du[0]], axis=1)
    np.testing.assert_allclose(analytic, fd, atol=1e-6 * (1 + np.abs(fd).max()))


BALL_SDF = """<?xml version="1.0"?>
<sdf version="1.9"><model name="ball"><link name="ball">
  <inertial><mass>0.2</mass><inertia><ixx>0.0002</ixx><iyy>0.0002</iyy><izz>0.0002</izz>
    <ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia></inertial>
  <collision name="c"><geometry><sphere><radius>0.05</radius></sphere></geometry></collision>
</link></model></sdf>"""


def test_ball_dropped_on_the_box_rests_on_it_without_penetrating(tmp_path):
    path = tmp_path / "ball.sdf"
    path.write_text(BALL_SDF)
    scene = Scene.from_dict({
        "name": "ball_on_box", "friction_model": "anitescu",
        "models": [{"file": "drake_abs:models/box_floating.sdf"}, {"file": str(path)}],
        "contacts": [{"body": "box", "geometry": "collision", "friction": 0.5}],
        "pairs": [{"a": "ball", "b": "box", "friction": 0.5}],
        "activation_distance": 0.05,
        # the ball 5 cm above the box's top face, off its centre, falling
        "initial_state": {"q": [0, 0, 0.05, 0, 0, 0, 0.04, -0.02, 0.2, 0, 0, 0],
                          "v": [0] * 12},
    })  # fmt: skip
    sm = build_scene_model(scene)
    assert type(sm.contact_model).__name__ == "MultibodyContactModel"  # auto fell back to Drake
    xs = rollout(sm, 80)
    phi = sm.contact_model.distances(xs[:, :12])[:, -1]
    assert phi.min() > -1e-6  # never into the box
    assert xs[-1, 8] == pytest.approx(0.1 + 0.05, abs=5e-4)  # on the top face (z = 0.1)
    assert np.abs(xs[-1, 12:]).max() < 1e-2  # at rest
    assert xs[-1, 2] == pytest.approx(0.05, abs=5e-4)  # the box still on the ground
    with pytest.raises(NotImplementedError, match="body-body pairs"):
        build_scene_model(Scene.from_dict({**scene.to_dict(), "dynamics": "pinocchio"}))


def push(y0, steps=150, speed=0.1):
    """The pusher_box rollout with the pusher driven at ``speed`` along +x from y = ``y0``."""
    sm = build_scene_model("pusher_box")
    sm = type(sm)(sm.scene, sm.plant, sm.contact_model, np.r_[0.0, y0, sm.q0[2:]], sm.v0)
    return rollout(sm, steps, lambda x: 250.0 * (np.array([speed, 0.0]) - x[8:10]))


def test_pushing_the_box_through_its_centre_moves_it_straight_with_the_pusher():
    xs = push(0.0)
    v_pusher, v_box = xs[-20:, 8], xs[-20:, 10]
    assert v_box.min() > 0.08  # the box is pushed ...
    np.testing.assert_allclose(v_box, v_pusher, atol=1e-6)  # ... at the pusher's speed
    assert np.abs(xs[:, 3]).max() < 1e-9 and np.abs(xs[:, 5]).max() < 1e-9  # straight, no yaw
    gap = xs[-1, 2] - 0.1 - (xs[-1, 0] - 0.135) - 0.03  # box face - sphere surface
    assert abs(gap) < 1e-3


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_pushing_off_centre_turns_the_box_away_from_the_pusher(side):
    xs = push(side * 0.05)
    yaw = xs[-1, 5]
    # pushing along +x at +y of the centre turns the box clockwise seen from above (yaw < 0)
    assert -side * yaw > 0.2
    assert xs[-1, 2] > 0.05  # and it moves on along x
