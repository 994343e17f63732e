"""Plant + policy + reward as a Drake diagram: its return and AutoDiffXd gradient dJ/dtheta
equal the batched engine's (the same noise samples) to 1e-8 relative, for the LCS plant and for
a rigid-body scene's complementarity plant; and a Drake MultibodyPlant scene closes the loop."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs import ContactAware, Fixed, point_mass_lcs
from drake_abs.diagrams.drake_twin import make_drake_twin
from drake_abs.diagrams.policy_diagram import build_policy_diagram, rollout_return
from drake_abs.multibody import ComplementarityStepper
from drake_abs.multibody.builder import PACKAGE_DIR, build_scene_model
from drake_abs.multibody.scene import Scene
from drake_abs.policy.policies import LinearPolicy, MLPPolicy
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.policy.rollout import LcsStepper, rollout_policy
from drake_abs.systems import ComplementarityPlant, LcsPlant

H_STEP = 0.02


def ball_reward():
    return QuadraticReward(
        Q=np.diag([0.0, 1.0, 0.0, 0.01]), R=0.01 * np.eye(2),
        x_goal=np.array([1.0, 0.2, 0.0, 0.0]), Q_final=np.diag([10.0, 1.0, 0.0, 0.0]),
    )  # fmt: skip


@pytest.mark.parametrize(
    ("policy", "smoothing", "gradient"),
    [
        (LinearPolicy(4, 2), Fixed(1e-3), "frozen"),
        (MLPPolicy(4, 2, (6,)), ContactAware(mu_max=1e-2, length=0.1), "total"),
    ],
)
def test_lcs_diagram_gradient_equals_the_batched_engine(policy, smoothing, gradient, rng):
    lcs = point_mass_lcs(2, time_step=H_STEP)
    reward = ball_reward()
    theta = 0.2 * rng.standard_normal(policy.n_params)
    noise = rng.standard_normal((30, 2))
    x0 = np.array([0.0, 0.3, 1.0, -1.0])
    engine = rollout_policy(
        LcsStepper(lcs, smoothing, gradient), policy, theta, x0, noise[None], reward, sigma=0.5
    )
    assert engine.x[0, :, 1].min() < 0.01  # it hits the ground
    pd = build_policy_diagram(
        LcsPlant(lcs, H_STEP, smoothing, gradient), policy, reward, theta, noise, H_STEP,
        sigma=0.5, input_port="u",
    )  # fmt: skip
    J, grad = rollout_return(pd, theta, x0)
    J_double, _ = rollout_return(pd, theta, x0, gradient=False)
    assert J == pytest.approx(engine.returns[0], rel=1e-12)
    assert J_double == pytest.approx(engine.returns[0], rel=1e-12)
    np.testing.assert_allclose(grad, engine.grad[0], rtol=1e-8, atol=1e-8 * np.abs(grad).max())


def test_rigid_body_scene_diagram_gradient_equals_the_batched_engine(rng):
    scene = Scene.from_yaml(PACKAGE_DIR / "scenes" / "box_push.yaml")
    sm = build_scene_model(scene)
    stepper = ComplementarityStepper(sm.contact_model, activation_distance=0.05)
    policy = LinearPolicy(6, 1)
    reward = QuadraticReward(
        Q=np.diag([1.0, 0, 0, 0.1, 0, 0]), R=0.01 * np.eye(1),
        x_goal=np.array([0.3, 0.1, 0.0, 0.0, 0.0, 0.0]),
    )  # fmt: skip
    theta = np.concatenate([0.1 * rng.standard_normal(6), [1.0]])
    noise = rng.standard_normal((15, 1))
    x0 = np.concatenate([sm.q0, sm.v0])
    engine = rollout_policy(stepper, policy, theta, x0, noise[None], reward, sigma=0.5)
    assert engine.converged.all()
    pd = build_policy_diagram(
        ComplementarityPlant(stepper), policy, reward, theta, noise, scene.time_step,
        sigma=0.5, input_port="actuation",
    )  # fmt: skip
    J, grad = rollout_return(pd, theta, x0)
    assert J == pytest.approx(engine.returns[0], rel=1e-12)
    np.testing.assert_allclose(grad, engine.grad[0], rtol=1e-8, atol=1e-8 * np.abs(grad).max())


def test_drake_multibody_plant_scene_in_the_loop(rng):
    """The same box as Drake's own SAP plant: the loop closes, J is finite and its AutoDiffXd
    gradient matches a central difference of the double diagram."""
    scene = Scene.from_yaml(PACKAGE_DIR / "scenes" / "box_push.yaml")
    sm = build_scene_model(scene)
    twin = make_drake_twin(scene, "sap", sampled_outputs=False)
    policy = LinearPolicy(6, 1)
    reward = QuadraticReward(Q=np.diag([1.0, 0, 0, 0, 0, 0]), R=0.01 * np.eye(1),
                             x_goal=np.array([0.3, 0.1, 0, 0, 0, 0]))  # fmt: skip
    theta = np.concatenate([np.zeros(6), [3.0]])
    x0 = np.concatenate([sm.q0, sm.v0])
    pd = build_policy_diagram(
        twin.diagram, policy, reward, theta, np.zeros((10, 1)), scene.time_step,
        state_port="state", input_port="actuation",
    )  # fmt: skip
    J, grad = rollout_return(pd, theta, x0)
    eps = 1e-5
    e = np.zeros(theta.size)
    e[-1] = eps
    fd = (rollout_return(pd, theta + e, x0, gradient=False)[0]
          - rollout_return(pd, theta - e, x0, gradient=False)[0]) / (2 * eps)  # fmt: skip
    assert np.isfinite(J) and grad[-1] == pytest.approx(fd, rel=1e-4)
