"""The losses of drake_abs.learning.scene_losses on multibody scenes: the violation-implicit loss
on a falling box equals the 1-D toy's (an independent implementation), every loss's gradient
equals central differences of the loss at moved parameters, and on data from the model itself
the losses vanish at the true parameters and not elsewhere."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from drake_abs.contact.smoothing import ContactAware, Exact
from drake_abs.learning import GroundToy
from drake_abs.learning.scene_losses import (
    ModelLoss,
    explicit_loss,
    naive_implicit_loss,
    violation_implicit_loss,
)
from drake_abs.multibody import Scene, build_scene_model

# a 1 kg box on prismatic x and z joints, one frictionless point 0.1 m below its centre: the
# vertical motion is the toy's point mass (time step 5 ms, as the toy's)
FALLING_BOX = {
    "name": "falling_box",
    "time_step": 0.005,
    "models": [{"file": "drake_abs:models/box_translating.sdf"}],
    "contacts": [{"body": "box", "points": [[0.0, 0.0, -0.1]]}],
    "friction_directions": 2,
}  # fmt: skip


@pytest.mark.parametrize("eps", [0.25, 1e-2])
def test_violation_loss_on_a_falling_box_equals_the_toys(eps):
    toy = GroundToy()
    stepper = build_scene_model(Scene.from_dict(FALLING_BOX)).stepper()
    assert stepper.parameter_names[0] == "ground_height"
    rng = np.random.default_rng(0)
    theta_true, theta = 0.0, 0.03
    z, v, y = toy.sample(rng, 200, theta_true, noise=0.05)
    z = np.minimum(z, 0.05)  # near the ground, so that contact and the violation matter
    N = z.size
    x = np.stack([np.zeros(N), z + 0.1, np.zeros(N), v], axis=1)  # q = (x, z_box), v = (vx, vz)
    x_next = np.stack([np.zeros(N), z + 0.1 + toy.dt * y, np.zeros(N), y], axis=1)
    # weights: only vz, with 2 = the toy's prediction term has no 1/2
    ours = violation_implicit_loss(
        stepper.with_parameters({"ground_height": theta}), x, np.zeros((N, 1)), x_next, eps,
        names=["ground_height"], weights=[0.0, 0.0, 0.0, 2.0],
    )  # fmt: skip
    ref = toy.violation_implicit_loss(theta, z, v, y, eps)
    assert ours.all_converged and ref.converged.all()
    np.testing.assert_allclose(ours.per_transition, ref.loss, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(ours.grad[0], ref.grad[:, 0].mean(), rtol=1e-9, atol=1e-12)
    assert ours.loss > 0 and abs(ours.grad[0]) > 1e-3


def _data(name: str, friction: str, n: int = 48, seed: int = 0):
    """Transitions of the scene's own exact stepper from states around x0 (in contact)."""
    scene = replace(Scene.load(name), friction_model=friction)
    model = build_scene_model(scene)
    stepper = model.stepper()
    nq, nv, nu, _ = stepper.sizes
    rng = np.random.default_rng(seed)
    x = np.repeat(model.x0[None], n, axis=0)
    x[:, nq:] += 0.3 * rng.standard_normal((n, nv))
    if name == "hopper":  # the foot just above the ground, falling
        x[:, nq + 1] -= 2.0
    u = rng.uniform(-3.0, 3.0, (n, nu))
    step = stepper.step(x, u, jacobians=False)
    assert step.converged.all() and step.active.any()
    return stepper, x, u, step.x_next


CASES = [("box_push", "stewart_trinkle"), ("box_push", "anitescu"), ("hopper", "anitescu")]


@pytest.mark.parametrize("name, friction", CASES, ids=["-".join(c) for c in CASES])
@pytest.mark.parametrize("kind", ["explicit", "violation_implicit"])
def test_loss_gradients_match_central_differences(name, friction, kind):
    stepper, x, u, x_next = _data(name, friction)
    if kind == "explicit":
        stepper = stepper.with_smoothing(ContactAware(1e-3, 0.02))  # differentiable everywhere
    rng = np.random.default_rng(1)
    observed = x_next + 0.01 * rng.standard_normal(x_next.shape)  # the data are not the model's
    all_names, values = stepper.parameter_names, stepper.parameter_values()
    # every kind of column: a tied friction coefficient, masses, radii (where not at their
    # bound 0), two offsets, an inertia
    names = ["ground_height", "friction[*]"]
    names += [n for n in all_names if n.startswith("mass[")][:3]
    names += [
        n for n, v in zip(all_names, values, strict=True) if n.startswith("radius[") and v > 0
    ][:2]
    names += [n for n in all_names if n.startswith("offset")][:2]
    names += [n for n in all_names if n.startswith("unit_inertia") and n.endswith(".yy")][:1]
    loss = ModelLoss(stepper, x, u, observed, names, kind, eps=1e-2)
    theta = np.array([values[all_names.index(n.replace("*", "0"))] for n in names])
    at = loss(theta)
    assert at.all_converged and at.loss > 0
    for j, name_j in enumerate(names):
        d = 1e-6 * max(1.0, abs(theta[j]))
        plus, minus = theta.copy(), theta.copy()
        plus[j] += d
        minus[j] -= d
        fd = (loss(plus).loss - loss(minus).loss) / (2 * d)
        np.testing.assert_allclose(at.grad[j], fd, rtol=1e-4, atol=1e-6 * (1 + abs(at.loss)),
                                   err_msg=name_j)  # fmt: skip
    assert np.abs(at.grad).max() > 1e-4


@pytest.mark.parametrize("name, friction", [("box_push", "anitescu"), ("hopper", "anitescu")])
def test_losses_vanish_at_the_true_parameters_only(name, friction):
    """On the model's own (Anitescu, exact) data every loss is ~0 at the true parameters, and
    clearly positive with the ground 2 cm off."""
    stepper, x, u, x_next = _data(name, friction)
    for kind in ("explicit", "naive_implicit", "violation_implicit"):
        loss = ModelLoss(stepper, x, u, x_next, ["ground_height"], kind, eps=1e-2)
        h0 = stepper.parameter_values()[0]
        assert loss(np.array([h0])).loss < 1e-10, kind
        assert loss(np.array([h0 + 0.02])).loss > 1e-6, kind


def test_naive_implicit_is_the_exact_explicit_loss():
    stepper, x, u, x_next = _data("box_push", "stewart_trinkle")
    smoothed = stepper.with_smoothing(ContactAware(1e-2, 0.05))
    observed = x_next + 0.01
    naive = naive_implicit_loss(smoothed, x, u, observed)
    exact = explicit_loss(stepper.with_smoothing(Exact()), x, u, observed)
    smooth = explicit_loss(smoothed, x, u, observed)
    np.testing.assert_array_equal(naive.per_transition, exact.per_transition)
    assert not np.allclose(smooth.per_transition, exact.per_transition)


def test_bad_input_is_named():
    stepper, x, u, x_next = _data("box_push", "anitescu", n=4)
    with pytest.raises(ValueError, match="x_next"):
        explicit_loss(stepper, x, u, x_next[:, :-1])
    bad = x_next.copy()
    bad[1, 2] = np.nan
    with pytest.raises(ValueError, match="x_next must be finite"):
        violation_implicit_loss(stepper, x, u, bad, 1e-2)
    with pytest.raises(ValueError, match="x must have shape"):
        explicit_loss(stepper, x[:, :, None], u, x_next)
    with pytest.raises(ValueError, match="u must"):
        explicit_loss(stepper, x, u[:, :0], x_next)
    with pytest.raises(ValueError, match="eps"):
        violation_implicit_loss(stepper, x, u, x_next, 0.0)
    with pytest.raises(ValueError, match="names"):
        ModelLoss(stepper, x, u, x_next, ["no_such_parameter"])
    with pytest.raises(ValueError, match="kind"):
        ModelLoss(stepper, x, u, x_next, ["ground_height"], "implicit")
    with pytest.raises(ValueError, match="eps"):
        ModelLoss(stepper, x, u, x_next, ["ground_height"], "violation_implicit")
    with pytest.raises(ValueError, match="weights"):
        explicit_loss(stepper, x, u, x_next, weights=np.ones(2))
    with pytest.raises(ValueError, match="theta"):
        ModelLoss(stepper, x, u, x_next, ["ground_height"])(np.zeros(2))


def test_fits_lower_the_loss_and_respect_bounds():
    """Both fitters on the box's own data, from a ground 2 cm up and a mass 30 % off: the loss
    falls, random search is reproducible by its seed, the bounds hold (a start on a bound, to
    rounding, is accepted), and a start outside them is refused by name."""
    from drake_abs.learning import fit_gradient, fit_random_search

    stepper, x, u, x_next = _data("box_push", "anitescu", n=24)
    names = ["ground_height", "mass[box]"]
    loss = ModelLoss(stepper, x, u, x_next, names, "violation_implicit", eps=1e-2)
    start, scale = np.array([0.02, 0.7]), np.array([0.01, 0.1])
    lo, hi = np.array([-0.1, 0.7 * (1 - 1e-12)]), np.array([0.1, 2.0])
    g = fit_gradient(loss, start, scale, iterations=15, lower=lo, upper=hi)
    assert g.loss < 1e-3 * g.start_loss and np.all(g.theta >= lo) and np.all(g.theta <= hi)
    assert abs(g.theta[0]) < 1e-3  # the ground found again (the data's is 0)
    explicit = ModelLoss(stepper, x, u, x_next, names, "explicit", gradient=False)
    r1 = fit_random_search(explicit, start, scale, iterations=4, directions=3, seed=5)
    r2 = fit_random_search(explicit, start, scale, iterations=4, directions=3, seed=5)
    assert r1.loss < r1.start_loss and np.array_equal(r1.theta, r2.theta)
    assert r1.evaluations == 1 + 4 * (2 * 3 + 1)
    with pytest.raises(ValueError, match="lower <= theta0 <= upper"):
        fit_gradient(loss, np.array([0.02, 0.5]), scale, lower=lo, upper=hi)
    with pytest.raises(ValueError, match="gradient=False"):
        ModelLoss(stepper, x, u, x_next, names, "violation_implicit", eps=1e-2, gradient=False)


def test_random_search_skips_failed_evaluations():
    """A loss that fails (is not finite) on part of the space: random search leaves those
    directions out, never steps on them, and still finds the minimum of the rest."""
    from types import SimpleNamespace

    from drake_abs.learning import fit_random_search

    def loss(theta):  # a bowl at (1, -1), failing beyond |theta_0| > 2
        value = np.inf if abs(theta[0]) > 2.0 else float(np.sum((theta - [1.0, -1.0]) ** 2))
        return SimpleNamespace(loss=value, all_converged=bool(np.isfinite(value)))

    r = fit_random_search(loss, [0.0, 0.0], [1.0, 1.0], iterations=40, directions=4,
                          noise=1.0, step_size=0.3, seed=0)  # fmt: skip
    assert np.isfinite(r.loss) and r.loss < 0.05 * r.start_loss
    assert abs(r.theta[0]) <= 2.0 and r.unconverged_evaluations > 0


@pytest.mark.parametrize("eps", [1e-9, 1e-3, 1e4])
@pytest.mark.parametrize("name", ["box_push", "hopper"])
def test_violation_loss_at_extreme_eps_and_fast_impacts(name, eps):
    """Impacts 40 m/s faster than the data above, eps from nearly hard to nearly free: every
    inner minimisation converges and the gradient is still the central difference's."""
    stepper, x, u, _ = _data(name, "anitescu")
    x = x.copy()
    x[:, stepper.sizes[0] + 1] -= 40.0
    step = stepper.step(x, u, jacobians=False)
    assert step.converged.all()
    loss = ModelLoss(stepper, x, u, step.x_next + 0.01, ["ground_height", "friction[*]"],
                     "violation_implicit", eps=eps)  # fmt: skip
    theta = stepper.parameter_values()[:2]
    at = loss(theta)
    assert at.all_converged and np.isfinite(at.loss) and np.isfinite(at.grad).all()
    for j in range(2):
        d = np.zeros(2)
        d[j] = 1e-7
        fd = (loss(theta + d).loss - loss(theta - d).loss) / 2e-7
        np.testing.assert_allclose(at.grad[j], fd, rtol=1e-4, atol=1e-6 * (1 + abs(at.loss)))
