"""Plant + policy + reward as a Drake diagram: its return and AutoDiffXd gradient dJ/dtheta
equal the batched engine's (the same noise samples) to 1e-8 relative, for the LCS plant and for
a rigid-body scene's complementarity plant; and a Drake MultibodyPlant scene closes the loop."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs import ContactAware, Fixed, point_mass_lcs
from drake_abs.contact.lcs import LcsStepper
from drake_abs.diagrams.policy_diagram import build_policy_diagram, rollout_return
from drake_abs.engine import rollout
from drake_abs.multibody import ComplementarityStepper
from drake_abs.multibody.builder import build_scene_model
from drake_abs.multibody.packages import PACKAGE_DIR
from drake_abs.multibody.scene import Scene
from drake_abs.policy.policies import LinearPolicy, MLPPolicy
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.reference.drake_twin import make_drake_twin
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
    engine = rollout(
        LcsStepper(lcs, smoothing, gradient), policy, theta, x0, noise[None], reward, sigma=0.5
    )
    assert engine.x[0, :, 1].min() < 0.01  # it hits the ground
    pd = build_policy_diagram(
        LcsPlant(lcs, smoothing, gradient), policy, reward, theta, noise, H_STEP,
        sigma=0.5, input_port="actuation",
    )  # fmt: skip
    r = rollout_return(pd, theta, x0)
    J, grad = r.value, r.gradient
    assert r.converged is True
    J_double = rollout_return(pd, theta, x0, gradient=False).value
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
    engine = rollout(stepper, policy, theta, x0, noise[None], reward, sigma=0.5)
    assert engine.converged.all()
    pd = build_policy_diagram(
        ComplementarityPlant(stepper), policy, reward, theta, noise, scene.time_step,
        sigma=0.5, input_port="actuation",
    )  # fmt: skip
    r = rollout_return(pd, theta, x0)
    J, grad = r.value, r.gradient
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
    r = rollout_return(pd, theta, x0)
    J, grad = r.value, r.gradient
    eps = 1e-5
    e = np.zeros(theta.size)
    e[-1] = eps
    fd = (rollout_return(pd, theta + e, x0, gradient=False).value
          - rollout_return(pd, theta - e, x0, gradient=False).value) / (2 * eps)  # fmt: skip
    assert np.isfinite(J) and grad[-1] == pytest.approx(fd, rel=1e-4)


def _ball_loop(lcs, theta_scale=0.2, horizon=30, rng=None):
    rng = rng or np.random.default_rng(5)
    policy = LinearPolicy(4, 2)
    theta = theta_scale * rng.standard_normal(policy.n_params)
    noise = rng.standard_normal((horizon, 2))
    pd = build_policy_diagram(
        LcsPlant(lcs, ContactAware(1e-2, 0.1)), policy, ball_reward(), theta, noise,
        H_STEP, sigma=0.5, input_port="actuation",
    )  # fmt: skip
    return pd, theta, np.array([0.0, 0.3, 1.0, -1.0])


def test_no_silent_results_on_the_diagram_path():
    """A horizon of 0 is refused; an unconverged step is reported (and its derivatives are NaN,
    the plant's default); the engine and the diagram agree on what they report."""
    from dataclasses import replace

    from drake_abs.contact.unconverged import UnconvergedStepWarning
    from drake_abs.lcp.ipm import LCPConvergenceWarning

    lcs = point_mass_lcs(2, time_step=H_STEP)
    with pytest.raises(ValueError, match="H >= 1"):
        build_policy_diagram(LcsPlant(lcs), LinearPolicy(4, 2), ball_reward(),
                             np.zeros(10), np.zeros((0, 2)), H_STEP)  # fmt: skip
    pd, theta, x0 = _ball_loop(lcs)
    r = rollout_return(pd, theta, x0)
    assert r.converged is True and np.isfinite(r.gradient).all()
    starved = replace(lcs, solver_options={**lcs.solver_options, "max_iterations": 3})
    pd, theta, x0 = _ball_loop(starved)
    with pytest.warns(LCPConvergenceWarning), pytest.warns(UnconvergedStepWarning):
        bad = rollout_return(pd, theta, x0)
    assert bad.converged is False and np.isnan(bad.gradient).all()
    assert rollout_return(pd, theta, x0, gradient=False).converged is False


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the policy's output overflows
def test_a_non_finite_rollout_raises_instead_of_returning_bare():
    lcs = point_mass_lcs(2, time_step=H_STEP)
    pd, theta, x0 = _ball_loop(lcs, theta_scale=1e150, horizon=5)
    with pytest.raises(ValueError, match="finite"):
        rollout_return(pd, theta, x0)
