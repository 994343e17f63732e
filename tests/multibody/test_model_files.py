"""Model files as published: a free body's pose in the file is its default initial state (SDF
<pose>, MJCF body pos/quat with <freejoint/>, URDF floating joint <origin>); gymnasium's MuJoCo
files load with their joint ranges, damping, armature, gear and control ranges honoured (or
applied by drake_abs where Drake drops them: settotalmass, effort limits in torque units,
keyframes), and what the step does not model is refused, naming the element and attribute."""

import math
from xml.etree import ElementTree

import numpy as np
import pytest
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

from drake_abs import Exact
from drake_abs.multibody.builder import build_scene_model
from drake_abs.multibody.drake_dynamics import MultibodyContactModel
from drake_abs.multibody.model_files import format_model_report, read_mjcf
from drake_abs.multibody.packages import gymnasium_assets_dir
from drake_abs.multibody.scene import ContactSpec, ModelSpec, Scene

# a 0.2 m cube of 1 kg, its corners the contacts
CORNERS = tuple((x, y, -0.1) for x in (-0.1, 0.1) for y in (-0.1, 0.1))
INERTIA = 1.0 * 0.2**2 / 6


def _scene(path, body="box", **spec):
    return Scene(
        name="file_pose",
        models=(ModelSpec(file=str(path), **spec),),
        contacts=(ContactSpec(body=body, points=CORNERS, friction=0.5),),
        activation_distance=0.5,
        friction_model="anitescu",  # (a face landing flat: the monotone LCP)
    )


def _sdf(tmp_path, z=0.3, yaw=0.2):
    path = tmp_path / "box.sdf"
    path.write_text(f"""<?xml version="1.0"?>
<sdf version="1.7"><model name="m"><link name="box"><pose>0 0 {z} 0 0 {yaw}</pose>
<inertial><mass>1</mass><inertia><ixx>{INERTIA}</ixx><iyy>{INERTIA}</iyy><izz>{INERTIA}</izz>
<ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia></inertial></link></model></sdf>""")
    return path


def _mjcf(tmp_path, extra="", joint="<freejoint/>", body_extra=""):
    path = tmp_path / "box.xml"
    path.write_text(f"""<mujoco model="m"><worldbody>
<body name="box" pos="0 0 0.3" quat="{math.cos(0.1)} 0 0 {math.sin(0.1)}">{joint}
<geom type="box" size="0.1 0.1 0.1" mass="1"/>{body_extra}</body></worldbody>{extra}</mujoco>""")
    return path


def _drop(sm, steps=100):
    """The zero-input exact-contact rollout's heights of the box (max, last)."""
    stepper = sm.stepper(smoothing=Exact())
    x = sm.x0[None]
    zs = []
    for _ in range(steps):
        r = stepper.step(x, np.zeros((1, stepper.sizes[2])), jacobians=False)
        assert r.converged[0]
        x = r.x_next
        zs.append(x[0, 2])
    return max(zs), zs[-1]


def test_an_sdf_free_body_starts_at_its_pose_and_is_not_thrown(tmp_path):
    sm = build_scene_model(_scene(_sdf(tmp_path)))
    # the Euler-angle chain: (x, y, z, yaw, pitch, roll)
    np.testing.assert_allclose(sm.q0, [0, 0, 0.3, 0.2, 0, 0], atol=1e-12)
    np.testing.assert_array_equal(sm.v0, 0)
    top, last = _drop(sm)
    assert top <= 0.3 + 1e-12  # it falls from rest, nothing pushes it out of the ground
    assert last == pytest.approx(0.1, abs=1e-3)  # resting on its face


def test_an_mjcf_freejoint_body_starts_at_its_pos_and_quat(tmp_path):
    sm = build_scene_model(_scene(_mjcf(tmp_path)))
    np.testing.assert_allclose(sm.q0, [0, 0, 0.3, 0.2, 0, 0], atol=1e-12)  # quat: yaw 0.2
    top, last = _drop(sm)
    assert top <= 0.3 + 1e-12 and last == pytest.approx(0.1, abs=1e-3)


def test_initial_state_still_overrides_the_file_pose(tmp_path):
    scene = _scene(_sdf(tmp_path))
    scene = Scene.from_dict({**scene.to_dict(), "initial_state": {"q": [1, 0, 0.5, 0, 0, 0]}})
    assert build_scene_model(scene).q0.tolist() == [1, 0, 0.5, 0, 0, 0]


def test_a_urdf_floating_joint_starts_at_its_origin(tmp_path):
    path = tmp_path / "ball.urdf"
    path.write_text("""<robot name="r"><link name="ball"><inertial><mass value="1"/>
<inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
<joint name="free" type="floating"><parent link="world"/><child link="ball"/>
<origin xyz="0.1 0.2 0.3" rpy="0 0 0.4"/></joint></robot>""")
    sm = build_scene_model(_scene(path, body="ball"))
    # (qw, qx, qy, qz, x, y, z): a yaw of 0.4 about z
    np.testing.assert_allclose(sm.q0, [math.cos(0.2), 0, 0, math.sin(0.2), 0.1, 0.2, 0.3])


# --- gymnasium's MuJoCo files ------------------------------------------------------------------


def _joint_attrs(path):
    """{joint name: attributes with the file's top-level <default><joint> filled in}."""
    root = ElementTree.parse(path).getroot()
    default = root.find("default/joint").attrib
    return {j.get("name"): {**default, **j.attrib} for j in root.iter("joint") if j.get("name")}


@pytest.mark.parametrize("name", ["hopper", "half_cheetah"])
def test_gym_scene_honours_the_files_limits_damping_armature_and_motors(name):
    path = gymnasium_assets_dir() / f"{name}.xml"
    root = ElementTree.parse(path).getroot()
    degrees = root.find("compiler").get("angle") == "degree"
    sm = build_scene_model(f"gym_{name}")
    report = sm.model_report()
    joints = {j["name"]: j for j in report["joints"]}
    attrs = _joint_attrs(path)
    assert list(joints) == list(attrs)  # the file's joints, in qpos order
    for k, (jname, a) in enumerate(attrs.items()):
        j = joints[jname]
        assert j["q_index"] == k
        if a.get("limited") == "true" and "range" in a:
            lo, hi = (float(x) * (math.pi / 180 if degrees else 1) for x in a["range"].split())
            assert (j["lower"], j["upper"]) == pytest.approx((lo, hi), rel=1e-12)
        else:
            assert (j["lower"], j["upper"]) == (-math.inf, math.inf)
        assert j["damping"] == float(a.get("damping", 0))
        assert j["stiffness"] == float(a.get("stiffness", 0))  # the joint springs
        assert j["springref"] == float(a.get("springref", 0))
        assert j["armature"] == pytest.approx(float(a.get("armature", 0)), rel=1e-12)
    motors = root.find("actuator").findall("motor")
    default_ctrl = root.find("default/motor").get("ctrlrange")
    assert [a["joint"] for a in report["actuators"]] == [m.get("joint") for m in motors]
    for a, m in zip(report["actuators"], motors, strict=True):
        gear = float(m.get("gear"))
        ctrl = float(m.get("ctrlrange", default_ctrl).split()[1])
        assert a["gear"] == gear
        assert a["effort_limit"] == pytest.approx(gear * ctrl, rel=1e-12)  # torque, N m
    assert sm.plant.num_actuators() == len(motors)
    assert "armature" in format_model_report(report)


def test_half_cheetah_total_mass_is_the_files_settotalmass_scaled_evenly():
    path = gymnasium_assets_dir() / "half_cheetah.xml"
    total = float(ElementTree.parse(path).getroot().find("compiler").get("settotalmass"))
    sm = build_scene_model("gym_half_cheetah")
    assert sm.model_report()["mass"] == pytest.approx(total, rel=1e-12)
    raw = MultibodyPlant(0.0)
    (instance,) = Parser(raw).AddModels(str(path))  # Drake alone: settotalmass ignored
    raw_bodies = {raw.get_body(i).name(): raw.get_body(i) for i in raw.GetBodyIndices(instance)}
    raw_total = sum(b.default_mass() for b in raw_bodies.values())
    assert raw_total > total + 1  # (21.2 kg: the geoms at density 1000)
    for name, body in raw_bodies.items():
        mine = sm.plant.GetBodyByName(name).default_spatial_inertia()
        theirs = body.default_spatial_inertia()
        scale = total / raw_total
        assert mine.get_mass() == pytest.approx(theirs.get_mass() * scale, rel=1e-12)
        np.testing.assert_allclose(mine.get_com(), theirs.get_com(), atol=1e-12)
        np.testing.assert_allclose(
            mine.CalcRotationalInertia().CopyToFullMatrix3(),
            theirs.CalcRotationalInertia().CopyToFullMatrix3() * scale,
            atol=1e-12,
        )


@pytest.mark.parametrize("name", ["gym_hopper", "gym_half_cheetah", "ur5_fall"])
def test_gym_scene_steps_from_the_files_initial_state(name):
    sm = build_scene_model(name)
    assert sm.contact_model.distances(sm.q0[None]).min() > 0.03  # dropped, not in the ground
    stepper = sm.stepper()
    x = sm.x0[None]
    u = np.zeros((1, stepper.sizes[2]))
    for _ in range(40):
        r = stepper.step(x, u, jacobians=True)
        assert r.converged[0] and np.isfinite(r.x_next).all() and np.isfinite(r.dx_dx).all()
        x = r.x_next
    nq = sm.plant.num_positions()
    assert sm.contact_model.distances(x[:, :nq]).min() > -1e-3
    assert r.impulse[0].max() > 1e-3  # landed


def test_gym_hopper_inputs_are_joint_torques_limited_at_gear_times_ctrlrange():
    """Drake keeps ctrlrange (+-1) as the effort limit while its input is the joint torque; the
    scene's limit is 200 N m: 150 N m passes unclipped, 1000 N m acts as 200. (Negative: the
    thigh starts at its upper limit, 0.)"""
    sm = build_scene_model("gym_hopper")
    stepper = sm.stepper()
    x = sm.x0[None]

    def thigh(u):
        return stepper.step(x, np.array([[u, 0.0, 0.0]]), jacobians=False).x_next[0]

    assert thigh(-150.0)[9] < thigh(-1.0)[9] < 0  # the thigh's rate
    assert thigh(-1000.0)[9] == thigh(-200.0)[9] < thigh(-150.0)[9]
    np.testing.assert_array_equal(thigh(-1000.0), thigh(-200.0))


def test_armature_is_in_the_dynamics_whichever_provider():
    """The file's armature is the motors' reflected inertia, in Drake's mass matrix; the
    pinocchio provider is used only where its model carries it too (else "auto" falls back to
    Drake's and "pinocchio" is refused, naming it)."""
    path = gymnasium_assets_dir() / "hopper.xml"
    plants = []
    for armature in (True, False):
        plant = MultibodyPlant(0.0)
        Parser(plant).AddModels(str(path))
        for i in plant.GetJointActuatorIndices():
            if not armature:
                plant.get_joint_actuator(i).set_default_rotor_inertia(0.0)
        plant.Finalize()
        plants.append(plant)
    M = [p.CalcMassMatrix(p.CreateDefaultContext()) for p in plants]
    np.testing.assert_allclose(M[0] - M[1], np.diag([0, 0, 0, 1.0, 1.0, 1.0]), atol=1e-12)
    scene = Scene.load("gym_hopper")
    for dynamics in ("auto", "pinocchio"):  # pinocchio carries it as its joint armature
        varied = Scene.from_dict({**scene.to_dict(), "dynamics": dynamics})
        cm = build_scene_model(varied).contact_model
        assert not isinstance(cm, MultibodyContactModel)
        np.testing.assert_allclose(cm.pin_model.armature, [0, 0, 0, 1, 1, 1])


def test_half_cheetah_springs_come_from_the_file_unless_ignored():
    """The scene lists nothing to ignore: the file's joint springs are in the plant (Drake's
    RevoluteSpring force elements) and in the step; ``ignore: [joint.stiffness]`` drops
    them, and says so."""
    scene = Scene.load("gym_half_cheetah")
    assert scene.models[0].ignore == ()
    stepper = build_scene_model(scene).stepper()
    assert stepper.springs.stiffness.tolist() == [0, 0, 0, 240, 180, 120, 180, 120, 60]
    model = {**scene.to_dict()["models"][0], "ignore": ["joint.stiffness"]}
    dropped = build_scene_model(Scene.from_dict({**scene.to_dict(), "models": [model]}))
    assert not dropped.stepper().springs.active
    path = gymnasium_assets_dir() / "half_cheetah.xml"
    info = read_mjcf(path, ("joint.stiffness",))
    assert info.springs == () and len(info.dropped) == 6
    assert "joint 'bthigh': stiffness=240 (a joint spring)" in info.dropped


@pytest.mark.parametrize(
    ("extra", "joint", "match"),
    [
        ("", '<joint name="h" type="ball" frictionloss="1"/>',
         r"joint 'h': frictionloss=1 \(dry friction on a ball joint"),
        ("", '<joint name="h" type="slide" axis="0 0 1" frictionloss="-1"/>',
         r"joint 'h': frictionloss=-1"),
        ("", '<joint name="h" type="slide" axis="0 0 1" armature="0.5"/>',
         r"joint 'h': armature=0.5 \(armature of a joint no motor drives\)"),
        ('<actuator><position joint="h" kp="10"/></actuator>',
         '<joint name="h" type="slide" axis="0 0 1"/>', r"actuator <position>.*only <motor>"),
        ('<actuator><motor joint="h" ctrlrange="-1 2"/></actuator>',
         '<joint name="h" type="slide" axis="0 0 1"/>', r"ctrlrange must be symmetric"),
        ('<actuator><motor joint="h" gear="1 0 0 0 0 1"/></actuator>',
         '<joint name="h" type="slide" axis="0 0 1"/>', r"gear must be one number"),
        ('<tendon><fixed name="t"><joint joint="h" coef="1"/></fixed></tendon>',
         '<joint name="h" type="slide" axis="0 0 1"/>', r"<tendon> <fixed> 't'"),
    ],
)  # fmt: skip
def test_what_the_step_does_not_model_is_refused(tmp_path, extra, joint, match):
    with pytest.raises(ValueError, match=match):
        build_scene_model(_scene(_mjcf(tmp_path, extra=extra, joint=joint)))


def test_ignore_drops_the_listed_attributes_and_says_so(tmp_path):
    path = _mjcf(tmp_path, joint='<joint name="h" type="slide" axis="0 0 1" frictionloss="1"/>')
    assert read_mjcf(path).frictionloss == (("h", 1.0),)  # read: the step takes it
    assert build_scene_model(_scene(path)).joint_friction.tolist() == [1.0]
    info = read_mjcf(path, ("joint.frictionloss",))
    assert info.dropped == ("joint 'h': frictionloss=1 (dry joint friction)",)
    assert info.frictionloss == ()
    dropped = build_scene_model(_scene(path, ignore=["joint.frictionloss"]))
    assert dropped.q0.tolist() == [0.0] and dropped.joint_friction.tolist() == [0.0]


def test_motor_effort_limit_is_gear_times_the_smaller_of_ctrl_and_force_range(tmp_path):
    extra = (
        '<default><motor ctrlrange="-2 2"/></default><actuator>'
        '<motor joint="h" gear="10" forcerange="-1.5 1.5"/><motor joint="h" gear="-3"/>'
        '<motor joint="h" gear="4" ctrllimited="false"/></actuator>'
    )
    sm = build_scene_model(
        _scene(_mjcf(tmp_path, extra=extra, joint='<joint name="h" type="slide" axis="0 0 1"/>'))
    )
    limits = [a["effort_limit"] for a in sm.model_report()["actuators"]]
    assert limits == [15.0, 6.0, math.inf]


def test_a_keyframe_sets_the_initial_positions(tmp_path):
    keys = (
        '<keyframe><key name="up" qpos="0.1 0 0.5 1 0 0 0 0.25"/>'
        '<key name="moving" qvel="0 0 0 0 0 1 0"/></keyframe>'
    )
    hinge = '<body name="lid" pos="0 0 0.1"><joint name="hinge" axis="0 1 0"/>'
    hinge += '<geom type="box" size="0.1 0.1 0.01" mass="0.1"/></body>'
    path = _mjcf(tmp_path, extra=keys, body_extra=hinge)
    sm = build_scene_model(_scene(path, keyframe="up"))
    # chain (x, y, z, yaw, pitch, roll), then the hinge
    np.testing.assert_allclose(sm.q0, [0.1, 0, 0.5, 0, 0, 0, 0.25], atol=1e-12)
    assert build_scene_model(_scene(path)).q0[2] == pytest.approx(0.3)  # no keyframe: the file
    with pytest.raises(ValueError, match=r"keyframe must name .*\['moving', 'up'\]; got 'down'"):
        build_scene_model(_scene(path, keyframe="down"))
    with pytest.raises(ValueError, match=r"keyframe 'moving' has a nonzero qvel"):
        build_scene_model(_scene(path, keyframe="moving"))


def test_keyframe_and_ignore_are_for_mjcf_files_only(tmp_path):
    with pytest.raises(ValueError, match=r"models\[0\]: ignore and keyframe apply to MuJoCo"):
        build_scene_model(_scene(_sdf(tmp_path), keyframe="up"))
    with pytest.raises(ValueError, match=r"models\[0\]\.ignore must be a list of some of"):
        _scene(_sdf(tmp_path), ignore=["joint.damping"])
    with pytest.raises(ValueError, match=r"models\[0\]\.keyframe must be a string"):
        _scene(_sdf(tmp_path), keyframe=3)


def test_ur5_from_example_robot_data_keeps_its_world_joint_transmissions_and_limits():
    """The URDF as published: welded to the world by its own joint, one actuator per
    <transmission>, effort and position limits from its <limit> tags."""
    from drake_abs.multibody.packages import example_robot_data_dir

    path = example_robot_data_dir() / "robots/ur_description/urdf/ur5_robot.urdf"
    root = ElementTree.parse(path).getroot()
    moving = [j for j in root.iter("joint") if j.get("type") == "revolute"]
    report = build_scene_model("ur5_fall").model_report()
    assert [j["name"] for j in report["joints"]] == [j.get("name") for j in moving]
    assert [a["joint"] for a in report["actuators"]] == [j.get("name") for j in moving]
    for j, a, urdf in zip(report["joints"], report["actuators"], moving, strict=True):
        limit = urdf.find("limit")
        assert (j["lower"], j["upper"]) == (float(limit.get("lower")), float(limit.get("upper")))
        assert a["effort_limit"] == float(limit.get("effort"))
