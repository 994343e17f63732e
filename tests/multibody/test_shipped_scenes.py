"""The shipped scenes (``drake_abs/scenes/*.yaml``): each loads and builds; a short rollout
converges at every step, stays finite and is physically plausible; and the full one-step
Jacobian (``gradient="total"``) matches central finite differences of the step at a state in
contact, under exact contact and under contact-aware smoothing.

Rollouts: the ball and the box are unactuated or pushed by a constant force; the legged robots
(hopper, half-cheetah, solo12, go1) hold their initial joint angles with a PD law plus the constant
torques that hold that posture when the feet share the weight equally (they would fold under
their own weight without actuation: the step models no joint springs or damping). The PD is
explicit (torques from the state at the start of the step), so its gains were chosen below the
explicit-step stability limit of the lightest links (the spectral radius of the linearised
flight phase's step map, its floating-base modes aside, below 1).
"""

import functools
import warnings

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs import ContactAware, Exact, Fixed
from drake_abs.contact.contact_lcp import contact_step
from drake_abs.lcp.ipm import LCPConvergenceWarning
from drake_abs.multibody import ComplementarityStepper
from drake_abs.multibody.builder import build_scene_model
from drake_abs.multibody.packages import PACKAGE_DIR
from drake_abs.multibody.parsing import resolve_model_file
from drake_abs.multibody.posture import STANDING_GAINS, standing_controller, total_mass
from drake_abs.multibody.scene import Scene

G = 9.81
SCENES_DIR = PACKAGE_DIR / "scenes"
# scene: (nq, nv, nu, contact candidates); the ball floats on a quaternion (nq = nv + 1)
SIZES = {
    "ball_throw": (7, 6, 0, 1),
    "box_push": (3, 3, 1, 4),
    "hopper": (5, 5, 2, 1),
    "half_cheetah": (9, 9, 6, 4),
    "solo12_drop": (18, 18, 12, 12),  # four feet, the base's 8 bounding-box corners
    "go1_drop": (18, 18, 12, 4),  # example-robot-data's Unitree Go1 as published
    # gymnasium's MuJoCo files as published (their rollouts: tests/multibody/test_model_files.py)
    "gym_hopper": (6, 6, 3, 5),
    "gym_half_cheetah": (9, 9, 6, 16),  # both ends of every capsule
    "gym_walker2d": (9, 9, 6, 8),
    "gym_ant": (15, 14, 8, 13),  # a free torso on a quaternion (nq = nv + 1)
    "ur5_fall": (6, 6, 6, 4),  # example-robot-data's UR5 as published
    # a sphere pusher (x, y) and a free box: 8 box vertices and the pusher-box pair
    "pusher_box": (8, 8, 2, 9),
}


@functools.cache
def scene_model(name):
    return build_scene_model(Scene.from_yaml(SCENES_DIR / f"{name}.yaml"))


def test_every_shipped_scene_loads_and_builds():
    assert {p.stem for p in SCENES_DIR.glob("*.yaml")} == set(SIZES)
    for name, (nq, nv, nu, nc) in SIZES.items():
        scene = Scene.from_yaml(SCENES_DIR / f"{name}.yaml")
        assert scene.name == name
        assert Scene.from_yaml(scene.to_yaml()) == scene
        sm = scene_model(name)
        plant = sm.plant
        assert (plant.num_positions(), plant.num_velocities(), plant.num_actuators()) == (
            nq, nv, nu
        )  # fmt: skip
        assert len(sm.contact_model.contacts) == nc == scene.num_contacts
        assert sm.q0.shape == (nq,) and sm.v0.shape == (nv,)
        # nothing starts below the ground
        assert sm.contact_model.distances(sm.q0[None]).min() > -1e-12


def test_shipped_scenes_name_their_model_files_by_package_uri():
    """The shipped scenes show the form to use: ``package://<package>/<path>`` (the older
    ``drake_abs:`` ... prefixes are aliases), each resolving to an installed file."""
    for name in SIZES:
        for i, spec in enumerate(Scene.load(name).models):
            assert spec.file.startswith("package://"), (name, i, spec.file)
            assert resolve_model_file(spec).is_file()


def test_solo12_is_the_floating_example_robot_data_robot_with_twelve_actuators():
    plant = scene_model("solo12_drop").plant
    names = plant.GetPositionNames()
    base = ["x_x", "y_x", "z_x", "yaw_q", "pitch_q", "roll_q"]  # the floating base's joints
    assert names[:6] == [f"solo_base_link_{c}" for c in base]
    legs = [f"{leg}_{j}" for leg in ("FL", "FR", "HL", "HR") for j in ("HAA", "HFE", "KFE")]
    assert names[6:] == [f"solo_{j}_q" for j in legs]
    actuated = [plant.get_joint_actuator(a).joint().name() for a in plant.GetJointActuatorIndices()]
    assert actuated == legs
    assert total_mass(scene_model("solo12_drop")) == pytest.approx(2.5, abs=1e-3)


# --- rollouts ----------------------------------------------------------------------------------


def controller(name, sm):
    if name == "ball_throw":
        return lambda x: np.zeros(0)
    if name == "box_push":
        return lambda x: np.array([2.0])  # N, less than friction's 0.5 m g = 4.9 N
    feet, kp, kd = STANDING_GAINS[name]  # hopper, half_cheetah, solo12_drop, go1_drop
    return standing_controller(sm, feet, kp, kd)[0]


STEPS = {
    "ball_throw": 60,
    "box_push": 60,
    "hopper": 100,
    "half_cheetah": 100,
    "solo12_drop": 120,
    "go1_drop": 120,
}


@functools.cache
def rollout(name):
    """The scene's exact-contact rollout from its initial state: states (T + 1, nx), normal
    impulses (T, nc), iterations (T,)."""
    sm = scene_model(name)
    stepper = sm.stepper(smoothing=Exact())
    policy = controller(name, sm)
    xs = [np.concatenate([sm.q0, sm.v0])]
    impulses, iterations = [], []
    for k in range(STEPS[name]):
        x = xs[-1]
        r = stepper.step(x[None], policy(x)[None], jacobians=False)
        assert r.converged[0], f"{name}: step {k} did not converge from x = {x.tolist()}"
        assert np.all(np.isfinite(r.x_next))
        xs.append(r.x_next[0])
        impulses.append(r.impulse[0])
        iterations.append(r.iterations[0])
    return np.array(xs), np.array(impulses), np.array(iterations)


@pytest.mark.parametrize("name", STEPS)
def test_rollout_converges_and_nothing_falls_through_the_ground(name):
    sm = scene_model(name)
    xs, impulses, iterations = rollout(name)
    nq = sm.plant.num_positions()
    distances = sm.contact_model.distances(xs[:, :nq])
    assert distances.min() > -1e-3, f"{name}: a contact sank {-distances.min():.2e} m"
    assert np.all(impulses >= 0)
    assert iterations.max() <= 60  # the solver's budget is 200


def test_ball_lands_and_rolls_at_five_sevenths_of_its_speed():
    """Inelastic landing, then sliding until it rolls: friction at the contact keeps the angular
    momentum about the contact point, so a solid ball rolls on at 5/7 of its horizontal speed,
    v_y = -r w_x, about the x axis only."""
    xs, impulses, _ = rollout("ball_throw")
    r = 0.05
    # q = (qw, qx, qy, qz, x, y, z), v = (wx, wy, wz, vx, vy, vz) (world frame)
    quat, p, w, v = xs[-1, :4], xs[-1, 4:7], xs[-1, 7:10], xs[-1, 10:]
    assert impulses[:25].max() < 1e-12 and impulses[-1, 0] > 1e-3  # flies, then on the ground
    assert p[2] == pytest.approx(r, abs=1e-9) and abs(v[2]) < 1e-9
    assert v[1] == pytest.approx(5 / 7, abs=1e-9)
    assert v[1] + r * w[0] == pytest.approx(0, abs=1e-9)  # rolling: the contact point is still
    np.testing.assert_allclose([p[0], v[0], w[1], w[2], quat[2], quat[3]], 0, atol=1e-12)
    assert np.linalg.norm(xs[:, :4], axis=1) == pytest.approx(1.0, abs=1e-14)  # unit quaternion


def test_pushed_box_decelerates_as_discrete_coulomb_and_stays_stuck():
    """Pushed at 2 N while sliding at 1 m/s: it slows by (0.5 g - 2) h per step, stops, and
    static friction then holds the push."""
    xs, _, _ = rollout("box_push")
    dv = (0.5 * G - 2.0) * 0.01
    k = np.arange(1, int(1.0 / dv) + 1)
    assert xs[-1, 0] == pytest.approx(0.01 * np.sum(1.0 - dv * k), abs=1e-9)
    np.testing.assert_allclose(xs[-10:, 3:], 0, atol=1e-9)  # at rest
    np.testing.assert_allclose(xs[-1, 1:3], [0.1, 0.0], atol=1e-9)  # flat on the ground


def test_hopper_lands_on_its_foot_and_stands():
    xs, impulses, _ = rollout("hopper")
    x, z, pitch, hip, leg = xs[-1, :5]
    assert impulses[-20:, 0].min() > 1e-3  # standing on the foot
    assert z == pytest.approx(0.52 + leg, abs=1e-3) and abs(leg) < 5e-3
    np.testing.assert_allclose([x, pitch, hip], 0, atol=1e-9)  # dropped upright: stays upright
    assert np.abs(xs[-1, 5:]).max() < 0.01
    # the impulse of the weight once settled
    assert impulses[-1, 0] == pytest.approx(4.0 * G * 0.01, rel=0.02)


def test_half_cheetah_lands_on_both_feet_and_stands():
    sm = scene_model("half_cheetah")
    xs, impulses, _ = rollout("half_cheetah")
    assert impulses[-20:, :2].min() > 1e-3 and impulses[:, 2:].max() < 1e-12  # feet only
    assert sm.contact_model.distances(xs[-1:, :9])[0, 2:].min() > 0.5  # torso well clear
    z, pitch = xs[-1, 1], xs[-1, 2]
    assert 0.70 < z < 0.74 and abs(pitch) < 1e-6 and abs(xs[-1, 0]) < 1e-6
    assert np.abs(xs[-1, 9:12]).max() < 0.05  # torso nearly still
    assert impulses[-1, :2].sum() == pytest.approx(10.4 * G * 0.01, rel=0.1)


def test_solo12_lands_on_four_feet_and_stands():
    xs, impulses, _ = rollout("solo12_drop")
    q, v = xs[-1, :18], xs[-1, 18:]
    assert impulses[:15].max() < 1e-12  # falls freely at first
    assert impulses[-20:, :4].min() > 1e-3  # then stands on all four feet
    assert impulses[:, 4:].max() < 1e-12  # never on its base
    assert 0.22 < q[2] < 0.26
    np.testing.assert_allclose(q[[0, 1, 3, 4, 5]], 0, atol=1e-3)  # level, not drifting
    assert np.abs(v[:6]).max() < 0.05
    assert impulses[-1].sum() == pytest.approx(2.5 * G * 0.005, rel=0.1)


def test_go1_lands_on_four_feet_and_stands():
    """Go1 (13.1 kg) from 1 cm up: its feed-forward torques extend the light lower legs at once, so
    the feet touch within the first step; it then stands on all four feet for the last second,
    level, the hind feet carrying more (its centre of mass is 3 cm behind the feet's centroid)."""
    sm = scene_model("go1_drop")
    assert sm.scene.friction_model == "anitescu"
    xs, impulses, _ = rollout("go1_drop")
    q, v = xs[-1, :18], xs[-1, 18:]
    assert impulses[-100:].min() > 1e-3  # on all four feet for the last 1 s
    assert 0.26 < q[2] < 0.28  # the feet touch at base z = 0.2738 m
    np.testing.assert_allclose(q[[0, 1, 3, 4, 5]], 0, atol=1e-2)  # level, not drifting
    np.testing.assert_allclose(q[6:], sm.q0[6:], atol=2e-2)  # holds its standing posture
    assert np.abs(v).max() < 0.05
    assert impulses[-1].sum() == pytest.approx(total_mass(sm) * G * 0.01, rel=0.02)
    assert impulses[-1][2:].min() > impulses[-1][:2].max()  # hind feet (RR, RL) carry more


# --- one-step Jacobians against finite differences ---------------------------------------------


def _x(q, v):
    return np.array([*q, *v], float)


def _solo_state():
    """Rolled 0.02 rad and pitched -0.01 rad with the lowest foot (HR) 0.5 mm above the ground,
    the others 4 to 11 mm above (inside the activation distance), base moving at (1, 0.3,
    -0.3) m/s: HR slides, the others are near, so contact-aware smoothing acts."""
    sm = scene_model("solo12_drop")
    q = sm.q0.copy()
    q[5], q[4] = 0.02, -0.01  # roll, pitch
    q[2] -= sm.contact_model.distances(q[None]).min() - 5e-4
    v = np.zeros(18)
    v[0:3] = [1.0, 0.3, -0.3]
    return _x(q, v)


def _half_cheetah_state():
    """Pitched nose-up 0.03 rad with the back foot 0.5 mm above the ground and the front one
    2.7 cm above, moving forwards at 2 m/s with the back foot swinging forwards (20 rad/s): the
    back foot slides (the light foot would otherwise stick at once: a clearly non-degenerate
    state, not one at the stick/slip boundary)."""
    sm = scene_model("half_cheetah")
    q = np.array([0.0, 0.7226, -0.03, 0.4, -0.8, 0.4, -0.4, 0.8, -0.4])
    q[1] -= sm.contact_model.distances(q[None])[0, 0] - 5e-4
    return _x(q, [2.0, -0.3, 0, 0, 0, -20.0, 0, 0, 0])


# the ball's orientation in the finite-difference states: a unit quaternion (qw, qx, qy, qz)
# well away from the identity (the central differences move all four entries, off the unit
# sphere too: the step projects back onto it, and its Jacobian says so)
_TILT = tuple(np.array([0.8, 0.3, -0.4, 0.2]) / np.linalg.norm([0.8, 0.3, -0.4, 0.2]))


# scene: {label: (x, u)}. "contact": a contact is pressed, and it slides (a sticking contact is
# non-degenerate only through the friction regularisation's ~1e-9 slacks, and a sticking ball
# with no sideways load is degenerate in the unloaded directions). Single-contact scenes also
# have "approach" (the contact a little above the ground, closing), where contact-aware
# smoothing acts; at "contact" every contact is active and it gives mu = mu_min = 0.
FD_STATES = {
    "ball_throw": {
        # landing at 0.3 m/s while moving at 1 m/s: too little normal impulse to stop the slip
        # (q = (qw, qx, qy, qz, x, y, z), v = (wx, wy, wz, vx, vy, vz); tilted, spinning)
        "contact": lambda: (
            _x([*_TILT, 0, 0, 0.0505], [0.5, -0.3, 2.0, 0, 1.0, -0.3]),
            np.zeros(0),
        ),
        "approach": lambda: (_x([*_TILT, 0, 0, 0.06], [2.0, 0.3, -1.0, 0, 1.0, -0.5]), np.zeros(0)),
    },
    "box_push": {
        # tilted 0.1 rad, landing on its right corner (the left one 4 cm up), sliding
        "contact": lambda: (_x([0.0, 0.12, 0.1], [0.5, -0.5, 0.0]), np.array([2.0])),
    },
    "hopper": {
        # leaning forwards, landing while moving at 1.5 m/s (sliding)
        "contact": lambda: (
            _x([0, 0.5214, 0.05, -0.1, 0], [1.5, -0.3, 0, 0, 0]),
            np.array([0.0, 30.0]),
        ),
        "approach": lambda: (
            _x([0, 0.535, 0.05, -0.1, 0], [0.5, -0.5, 0, 0, 0]),
            np.array([0.0, 30.0]),
        ),
    },
    "half_cheetah": {"contact": lambda: (_half_cheetah_state(), np.full(6, 2.0))},
    "solo12_drop": {"contact": lambda: (_solo_state(), np.full(12, 0.2))},
}
CASES = [(name, label) for name, states in FD_STATES.items() for label in states]


def contact_aware(sm):
    """mu ~ impulse x distance: the weight's impulse over a step times 5 mm; decay over 2 cm."""
    return ContactAware(mu_max=total_mass(sm) * G * sm.scene.time_step * 5e-3, length=0.02)


@pytest.mark.parametrize("policy", ["exact", "contact_aware"])
@pytest.mark.parametrize(("name", "label"), CASES, ids=[f"{n}-{s}" for n, s in CASES])
def test_step_jacobian_matches_finite_differences(name, label, policy):
    sm = scene_model(name)
    model, scene = sm.contact_model, sm.scene
    smoothing = Exact() if policy == "exact" else contact_aware(sm)
    stepper = sm.stepper(smoothing=smoothing, gradient="total")
    x, u = FD_STATES[name][label]()
    nx = x.size
    r = stepper.step(x[None], u[None])
    assert r.converged[0]
    # the LCP's contacts stay the same under the perturbations
    margin = np.abs(model.distances(x[None, : model.nq]) - scene.activation_distance).min()
    assert margin > 1e-3
    if label == "contact":
        assert r.impulse[0].max() > 1e-4
    engaged = policy == "contact_aware" and (label == "approach" or len(model.contacts) > 1)
    assert (r.mu[0].max() > 1e-12) == engaged  # (exact contact solves to a floor ~1e-25)
    # strict complementarity: every LCP row has its variable or its slack clearly positive
    idx = np.flatnonzero(r.active[0])
    quant = model.quantities(
        x[None, : model.nq], x[None, model.nq :], u[None], idx, derivatives=False
    )
    lcp = contact_step(quant, model.cone_for(idx), model.h, smoothing).lcp
    assert np.maximum(lcp.lam, lcp.slack).min() > 1e-6

    def step(p):
        return stepper.step(p[None, :nx], p[None, nx:], jacobians=False).x_next[0]

    fd = central_difference(step, np.concatenate([x, u]), eps=1e-7)
    analytic = np.concatenate([r.dx_dx[0], r.dx_du[0]], axis=1)
    np.testing.assert_allclose(analytic, fd, atol=1e-6 * (1 + np.abs(fd).max()))


def test_overflowing_dynamics_are_flagged_not_passed_as_converged():
    """The half-cheetah has no joint damping or limits: under large random torques its light feet
    spin up and the explicit Coriolis terms diverge (measured: |x| ~ 1e26 within 20 steps). A
    step that overflows must come back flagged, with a warning, not as a converged result."""
    from drake_abs.multibody import StepOverflowWarning

    scene = Scene.from_yaml(PACKAGE_DIR / "scenes" / "half_cheetah.yaml")
    sm = build_scene_model(scene)
    stepper = sm.stepper(smoothing=Fixed(1e-2))
    rng = np.random.default_rng(0)
    x = np.tile(np.concatenate([sm.q0, sm.v0]), (4, 1))
    flagged = False
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LCPConvergenceWarning)
        warnings.simplefilter("error", StepOverflowWarning)
        for _ in range(100):
            u = 20.0 * rng.standard_normal((4, stepper.sizes[2]))
            try:
                r = stepper.step(x, u, jacobians=True)
            except StepOverflowWarning:
                flagged = True
                break
            assert np.isfinite(r.x_next).all() or not r.converged.all()
            x = np.where(np.isfinite(r.x_next), r.x_next, x)
    assert flagged
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = stepper.step(x, u, jacobians=True)
    bad = ~np.isfinite(r.x_next).all(axis=1) | ~np.isfinite(r.dx_dx).all(axis=(1, 2))
    assert bad.any() and not r.converged[bad].any()


def test_an_empty_batch_gives_empty_results():
    scene = Scene.from_yaml(PACKAGE_DIR / "scenes" / "box_push.yaml")
    sm = build_scene_model(scene)
    stepper = ComplementarityStepper(sm.contact_model, activation_distance=0.1)
    nq, nv, nu, nc = stepper.sizes
    r = stepper.step(np.zeros((0, nq + nv)), np.zeros((0, nu)))
    assert r.x_next.shape == (0, nq + nv) and r.dx_dx.shape == (0, nq + nv, nq + nv)
    assert r.impulse.shape == (0, nc) and r.converged.shape == (0,)
