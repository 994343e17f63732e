"""A batch of states steps exactly as each state alone: no state's kinematics, contacts or
damping may leak into another's. Regression: the damped pinocchio pass read the contact
placements from the undamped model's data (stale kinematics of another state), so a batched
step of a scene with joint damping (gymnasium's hopper and half-cheetah) used wrong contacts
while reporting converged."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from drake_abs.multibody import Scene, build_scene_model

# scenes with joint damping (gym_*) and without, on both rigid-body providers
CASES = [
    ("gym_hopper", "pinocchio"),
    ("gym_half_cheetah", "pinocchio"),
    ("gym_hopper", "drake"),
    ("hopper", "pinocchio"),
    ("box_push", "pinocchio"),
]


def _states(model, B: int, rng) -> np.ndarray:
    """B states around x0, every other one lowered so that its feet touch or penetrate the
    ground: a batch mixing contact and free flight, different contact sets per state."""
    nq = model.contact_model.nq
    x = np.repeat(model.x0[None], B, axis=0)
    x[:, nq:] += 0.5 * rng.standard_normal((B, x.shape[1] - nq))
    x[:, 2:nq] += 0.2 * rng.standard_normal((B, nq - 2)) if nq > 2 else 0.0
    lowest = model.contact_model.distances(x[:, :nq]).min(axis=1)
    x[::2, 1] -= lowest[::2] + rng.uniform(-0.01, 0.005, x[::2].shape[0])
    return x


@pytest.mark.parametrize("name, dynamics", CASES, ids=["-".join(c) for c in CASES])
@pytest.mark.parametrize("activation_distance", [float("inf"), 0.05])
def test_a_batch_steps_as_its_states_alone(name, dynamics, activation_distance):
    scene = replace(Scene.load(name), dynamics=dynamics, activation_distance=activation_distance)
    model = build_scene_model(scene)
    stepper = model.stepper()
    rng = np.random.default_rng(3)
    B = 8
    x = _states(model, B, rng)
    u = rng.uniform(-1.0, 1.0, (B, model.contact_model.nu)) * 20.0
    batch = stepper.step(x, u, parameters=True)
    alone = [stepper.step(x[b : b + 1], u[b], parameters=True) for b in range(B)]
    pushed = (batch.impulse > 1e-9).any(axis=1)  # states in contact
    assert pushed.sum() >= 2 and (not pushed.all() or name == "box_push")
    for b, one in enumerate(alone):
        assert batch.converged[b] == one.converged[0]
        for key in ("x_next", "impulse", "dx_dx", "dx_du", "dx_dtheta"):
            np.testing.assert_allclose(
                getattr(batch, key)[b], getattr(one, key)[0], rtol=1e-9, atol=1e-9,
                err_msg=f"{key}, state {b}",
            )  # fmt: skip


@pytest.mark.parametrize("name", ["gym_hopper", "box_push"])
def test_the_contact_problem_is_the_steps_own(name):
    """``contact_problem`` hands out the inputs of the step's LCP: solving them with the same
    smoothing gives the step (the scene's pruning leaves an exact step unchanged)."""
    from drake_abs.contact.contact_lcp import contact_step

    model = build_scene_model(name)
    stepper = model.stepper()
    rng = np.random.default_rng(4)
    x = _states(model, 6, rng)
    u = rng.uniform(-1.0, 1.0, (6, model.contact_model.nu)) * 20.0
    prob = stepper.contact_problem(x, u, parameters=["ground_height"])
    r = contact_step(prob.quantities, prob.cone, prob.h, stepper.smoothing)
    step = stepper.step(x, u, parameters=["ground_height"])
    nq = model.contact_model.nq
    np.testing.assert_allclose(np.concatenate([r.q_next, r.v_next], axis=1), step.x_next,
                               rtol=1e-9, atol=1e-9)  # fmt: skip
    assert prob.theta_names == ("ground_height",) and prob.parameters.dphi.shape[-1] == 1
    assert step.theta_names == ("ground_height",) and r.q_next.shape[1] == nq
    # a subset of the columns is those columns of the whole set (the same solve)
    full = stepper.step(x, u, parameters=True)
    some = ["ground_height", full.theta_names[-1], full.theta_names[2]]
    np.testing.assert_allclose(
        stepper.step(x, u, parameters=some).dx_dtheta,
        full.dx_dtheta[:, :, [full.theta_names.index(n) for n in some]],
        rtol=1e-12, atol=1e-12,
    )  # fmt: skip
    with pytest.raises(ValueError, match="u must have shape"):
        stepper.step(x, np.zeros(model.contact_model.nu + 1))
    with pytest.raises(ValueError, match="u must have shape"):
        stepper.contact_problem(x, np.zeros((2, model.contact_model.nu)))
    with pytest.raises(ValueError, match="parameters must be distinct names"):
        stepper.step(x, u, parameters=["no_such_parameter"])
