"""Hostile input on the surfaces above the solver: the gradient estimators, the learning fits,
the Ray runner, sweeps, saved policies and policy files, the locomotion tasks and the gymnasium
environment, and the command line.

The promise checked here is the solver's: bad input is refused before any work starts, with a
ValueError (TypeError where the type is wrong) that names the argument and the form it expects;
nothing is returned as a silent wrong answer (a fit that did not run never says it converged, a
state inside the ground is never stepped as if it were free). The estimators are also checked
number for number against their formulas at small M, worked out by hand here, so that a defect
that only shifts an estimate by a constant factor (a leave-one-out baseline that includes its
own sample) cannot hide behind a statistical test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drake_abs import Fixed, point_mass_lcs
from drake_abs.contact.lcs import LcsStepper
from drake_abs.learning.fitting import STATUSES, fit_gradient, fit_random_search
from drake_abs.learning.scene_losses import LossValue
from drake_abs.policy.estimators import (
    PolicyObjective,
    alpha_order,
    first_order,
    zeroth_order,
)
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.policy.rollouts import RolloutJob, RolloutStats, noise_key, rollout_stats

NX, NU = 4, 2  # the 2-D point mass: x = (p_x, p_z, v_x, v_z), u = force


def point_mass_objective(horizon: int = 6, sigma: float = 0.3) -> PolicyObjective:
    """A 2-D ball thrown at the ground (it bounces within the horizon), a linear policy."""
    lcs = point_mass_lcs(2, time_step=0.02)
    reward = QuadraticReward(
        Q=np.diag([0.0, 1.0, 0.0, 0.01]), R=0.01 * np.eye(NU),
        x_goal=np.array([1.0, 0.2, 0.0, 0.0]), Q_final=np.diag([10.0, 1.0, 0.0, 0.0]),
    )  # fmt: skip
    return PolicyObjective(
        LcsStepper(lcs, Fixed(1e-3), "frozen"), LinearPolicy(NX, NU), reward,
        np.array([0.0, 0.05, 1.0, -1.0]), horizon, sigma,
    )  # fmt: skip


# ====================================================================== estimators, small M


class FixedRunner:
    """A runner that returns given per-rollout numbers (returns R, gradients G, scores S, and
    which rollouts are usable) instead of running anything: the estimators' reductions are then
    checked exactly against the formulas."""

    def __init__(self, R, G, S, used=None):
        self.R, self.G, self.S = (np.asarray(a, dtype=float) for a in (R, G, S))
        self.used = np.ones(self.R.size, bool) if used is None else np.asarray(used, bool)

    def run(self, objective, jobs, *, gradient, score):
        (job,) = jobs
        assert job.size == self.R.size
        return [
            RolloutStats(
                returns=self.R.copy(), used=self.used.copy(),
                unconverged=np.zeros(self.R.size, dtype=int), horizon=objective.horizon,
                grad=self.G.copy() if gradient else None, score=self.S.copy() if score else None,
                env_steps=np.full(self.R.size, objective.horizon),
            )
        ]  # fmt: skip


def _numbers(M: int, P: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fixed, distinct per-rollout returns (M,), gradients (M, P) and scores (M, P)."""
    R = np.array([1.0, 3.0, -2.0, 0.5, 4.0])[:M]
    G = np.arange(M * P, dtype=float).reshape(M, P) / 7.0 - 1.0
    S = np.cos(np.arange(M * P, dtype=float)).reshape(M, P)
    return R, G, S


def test_zeroth_order_at_two_samples_is_the_leave_one_out_formula():
    """M = 2: g = 1/2 [(R_1 - R_2) s_1 + (R_2 - R_1) s_2]. A baseline that included the sample
    itself (the mean of both) would give exactly half of this."""
    obj = point_mass_objective()
    P = obj.policy.n_params
    R, _, S = _numbers(2, P)
    by_hand = 0.5 * ((R[0] - R[1]) * S[0] + (R[1] - R[0]) * S[1])
    est = zeroth_order(obj, np.zeros(P), np.random.default_rng(0), 2,
                       runner=FixedRunner(R, np.zeros((2, P)), S))  # fmt: skip
    np.testing.assert_allclose(est.grad, by_hand, rtol=1e-14, atol=1e-15)
    assert not np.allclose(est.grad, by_hand / 2)
    assert est.value == pytest.approx(R.mean()) and est.rollouts == 2


def test_zeroth_order_at_three_samples_and_with_a_dropped_rollout():
    """M = 3: b_m is the mean of the other two returns. With a fourth rollout dropped (an
    unconverged step), the baseline and the mean run over the three usable ones only."""
    obj = point_mass_objective()
    P = obj.policy.n_params
    R, _, S = _numbers(3, P)
    b = np.array([(R[1] + R[2]) / 2, (R[0] + R[2]) / 2, (R[0] + R[1]) / 2])
    by_hand = sum((R[m] - b[m]) * S[m] for m in range(3)) / 3
    est = zeroth_order(obj, np.zeros(P), np.random.default_rng(0), 3,
                       runner=FixedRunner(R, np.zeros((3, P)), S))  # fmt: skip
    np.testing.assert_allclose(est.grad, by_hand, rtol=1e-14, atol=1e-15)
    # the same three with a dropped rollout between them (its numbers are NaN, as the engine's)
    R4 = np.array([R[0], np.nan, R[1], R[2]])
    S4 = np.vstack([S[0], np.full(P, np.nan), S[1], S[2]])
    est4 = zeroth_order(obj, np.zeros(P), np.random.default_rng(0), 4,
                        runner=FixedRunner(R4, np.zeros((4, P)), S4, [1, 0, 1, 1]))  # fmt: skip
    np.testing.assert_allclose(est4.grad, by_hand, rtol=1e-14, atol=1e-15)
    assert est4.dropped == 1 and est4.value == pytest.approx(R.mean())


@pytest.mark.parametrize("M", [2, 3])
def test_first_order_and_alpha_order_are_their_formulas(M):
    """FO: the mean of the per-rollout gradients; alpha-order: alpha FO + (1 - alpha) ZO of the
    same rollouts, with ZO's leave-one-out baseline."""
    obj = point_mass_objective()
    P = obj.policy.n_params
    R, G, S = _numbers(M, P)
    fo = first_order(obj, np.zeros(P), np.random.default_rng(0), M, runner=FixedRunner(R, G, S))
    np.testing.assert_allclose(fo.grad, G.sum(axis=0) / M, rtol=1e-14, atol=1e-15)
    loo = np.array([(R.sum() - R[m]) / (M - 1) for m in range(M)])
    zo = sum((R[m] - loo[m]) * S[m] for m in range(M)) / M
    alpha = 0.25
    est = alpha_order(obj, np.zeros(P), np.random.default_rng(0), M, alpha,
                      runner=FixedRunner(R, G, S))  # fmt: skip
    np.testing.assert_allclose(est.grad, alpha * G.mean(axis=0) + (1 - alpha) * zo,
                               rtol=1e-13, atol=1e-15)  # fmt: skip


def test_the_likelihood_score_of_a_linear_policy_is_its_formula():
    """The zeroth-order estimate from real rollouts at M = 2 and 3, recomputed by hand from the
    states the rollouts visited: for u = K x + k + sigma xi, the score of rollout m is
    sum_t (xi_t / sigma) x_t^T (for K) and sum_t xi_t / sigma (for k)."""
    obj = point_mass_objective(horizon=5, sigma=0.3)
    P = obj.policy.n_params
    theta = 0.1 * np.cos(np.arange(P))
    for M in (2, 3):
        est = zeroth_order(obj, theta, np.random.default_rng(5), M)
        key = noise_key(np.random.default_rng(5))  # the key the estimator drew
        noise = obj.noise(np.random.default_rng(5), M)
        traj = obj.rollout(theta, noise, gradient=False)
        R = np.asarray(traj.returns)
        scores = []
        for m in range(M):
            xi = noise[m] / obj.sigma  # (H, nu)
            dK = sum(np.outer(xi[t], traj.x[m, t]) for t in range(obj.horizon))
            scores.append(np.concatenate([dK.ravel(), xi.sum(axis=0)]))
        loo = np.array([(R.sum() - R[m]) / (M - 1) for m in range(M)])
        by_hand = sum((R[m] - loo[m]) * scores[m] for m in range(M)) / M
        np.testing.assert_allclose(est.grad, by_hand, rtol=1e-10, atol=1e-12)
        stats = rollout_stats(obj, RolloutJob(theta, key, 0, M), gradient=False, score=True)
        np.testing.assert_allclose(stats.score, np.array(scores), rtol=1e-12, atol=1e-12)


# ================================================================================ the fits


class _ConstantLoss:
    """A loss that is the same everywhere (value ``value``, gradient 0)."""

    def __init__(self, value: float, P: int = 1):
        self.value, self.P = value, P

    def __call__(self, theta) -> LossValue:
        return LossValue(self.value, np.zeros(self.P), np.array([self.value]), np.ones(1, bool),
                         tuple(f"p{i}" for i in range(self.P)))  # fmt: skip


@pytest.mark.parametrize("bad", [0, -3, 1.5, True, "5", None])
def test_fits_refuse_iteration_counts_that_are_not_whole_numbers_from_one(bad):
    with pytest.raises(ValueError, match=r"iterations must be an integer >= 1"):
        fit_gradient(_ConstantLoss(1.0), [0.0], 1.0, iterations=bad)
    with pytest.raises(ValueError, match=r"iterations must be an integer >= 1"):
        fit_random_search(_ConstantLoss(1.0), [0.0], 1.0, iterations=bad)
    with pytest.raises(ValueError, match=r"directions must be an integer >= 1"):
        fit_random_search(_ConstantLoss(1.0), [0.0], 1.0, directions=bad)


def test_a_fit_whose_every_loss_is_infinite_does_not_say_converged():
    """L-BFGS-B, given inf and a zero gradient, reports "CONVERGENCE: NORM OF PROJECTED
    GRADIENT <= PGTOL"; the result's status says nothing was fitted."""
    for value in (np.inf, np.nan):
        result = fit_gradient(_ConstantLoss(value), [0.0, 1.0], 1.0, iterations=5)
        assert result.status == "no_finite_loss" and not result.converged
        search = fit_random_search(_ConstantLoss(value), [0.0], 1.0, iterations=2)
        assert search.status == "no_finite_loss" and not search.converged
    flat = fit_gradient(_ConstantLoss(2.0), [0.0], 1.0, iterations=5)
    assert flat.status == "converged" and flat.loss == 2.0
    assert set(STATUSES) >= {flat.status, result.status}


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"lower": [0.0, 0.0, 0.0]}, r"lower must be None, a number or \(2,\) numbers"),
        ({"upper": np.ones((2, 2))}, r"upper must be None, a number or \(2,\) numbers"),
        ({"lower": "low"}, r"lower must be None, a number or \(2,\) numbers"),
        ({"scale": [1.0, 1.0, 1.0]}, r"scale must be a number or \(2,\) numbers"),
        ({"theta0": [1j, 0.0]}, r"theta0 must be a vector of real numbers"),
        ({"tol": 0.0}, r"tol must be a finite number > 0"),
    ],
)
def test_fit_bounds_scales_and_starts_of_the_wrong_form_are_named(kwargs, message):
    args = {"theta0": [0.5, 0.5], "scale": 1.0} | kwargs
    theta0, scale = args.pop("theta0"), args.pop("scale")
    with pytest.raises(ValueError, match=message):
        fit_gradient(_ConstantLoss(1.0, 2), theta0, scale, iterations=3, **args)


# a 1 kg box on prismatic x and z joints, one frictionless point 0.1 m below its centre
FALLING_BOX = {
    "name": "falling_box",
    "time_step": 0.005,
    "models": [{"file": "drake_abs:models/box_translating.sdf"}],
    "contacts": [{"body": "box", "points": [[0.0, 0.0, -0.1]]}],
    "friction_directions": 2,
}  # fmt: skip


@pytest.fixture(scope="module")
def box_stepper():
    from drake_abs.multibody import Scene, build_scene_model

    return build_scene_model(Scene.from_dict(FALLING_BOX)).stepper()


def _box_data(stepper, n: int = 4):
    x = np.tile([0.0, 0.102, 0.0, -0.5], (n, 1))  # just above the ground, falling
    u = np.zeros((n, 1))
    return x, u, stepper.step(x, u, jacobians=False).x_next


def test_a_loss_over_no_data_is_refused(box_stepper):
    from drake_abs.learning.scene_losses import ModelLoss, explicit_loss

    empty = np.zeros((0, 4)), np.zeros((0, 1)), np.zeros((0, 4))
    for kind, eps in (("explicit", None), ("violation_implicit", 0.1)):
        with pytest.raises(ValueError, match=r"x must hold at least one transition"):
            ModelLoss(box_stepper, *empty, ["ground_height"], kind, eps=eps)
    with pytest.raises(ValueError, match=r"x must hold at least one transition"):
        explicit_loss(box_stepper, *empty)


@pytest.mark.parametrize(
    "names, message",
    [
        (["mass[box]", "mass[box]"], r"'mass\[box\]' and 'mass\[box\]' both set 'mass\[box\]' "
                                     r"\(the same name given twice\)"),
        (["unit_inertia[box].*", "unit_inertia[box].xx"],
         r"'unit_inertia\[box\].xx' and 'unit_inertia\[box\].\*' both set"),
        (["ground_height", "mass[*]", "mass[box]"], r"'mass\[box\]' and 'mass\[\*\]' both set"),
    ],
)  # fmt: skip
def test_a_parameter_named_twice_is_refused_by_name(box_stepper, names, message):
    """Two names for one column: the column would take the last value, and the gradient of
    the first would be reported for a parameter that moves nothing."""
    from drake_abs.learning.scene_losses import ModelLoss, learned_values, stepper_at

    data = _box_data(box_stepper)
    with pytest.raises(ValueError, match=message):
        ModelLoss(box_stepper, *data, names, "explicit")
    with pytest.raises(ValueError, match=r"names must name each parameter once"):
        learned_values(box_stepper, names)
    with pytest.raises(ValueError, match=r"names must name each parameter once"):
        stepper_at(box_stepper, names, np.ones(len(names)))


def test_complex_or_text_data_is_refused_by_name(box_stepper):
    from drake_abs.learning.scene_losses import ModelLoss

    x, u, x_next = _box_data(box_stepper)
    with pytest.raises(ValueError, match=r"x_next must be an array of real numbers; got dtype "
                                         r"complex128"):  # fmt: skip
        ModelLoss(box_stepper, x, u, x_next + 0j, ["ground_height"])
    with pytest.raises(ValueError, match=r"u must be an array of real numbers"):
        ModelLoss(box_stepper, x, u.astype(str), x_next, ["ground_height"])


# ============================================================================== Ray runner


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"workers": 0}, r"workers must be a whole number >= 1 or None; got 0"),
        ({"workers": 2.5}, r"workers must be a whole number >= 1 or None; got 2.5"),
        ({"workers": True}, r"workers must be a whole number >= 1 or None; got True"),
        ({"chunk_size": 0}, r"chunk_size must be a whole number >= 1 or None"),
        ({"max_retries": -1}, r"max_retries must be a whole number >= 0"),
        ({"address": ""}, r"address must be None \(a local cluster\), 'auto'"),
        ({"address": "  "}, r"address must be None \(a local cluster\), 'auto'"),
    ],
)
def test_bad_runner_arguments_are_refused_before_any_cluster_starts(kwargs, message):
    ray = pytest.importorskip("ray")
    from drake_abs.parallel import RayRunner

    before = ray.is_initialized()
    with pytest.raises(ValueError, match=message):
        RayRunner(**kwargs)
    assert ray.is_initialized() == before  # no cluster was started for a refused argument


def test_more_workers_than_the_cluster_has_cpus_is_refused_not_a_hang():
    """Each actor holds one CPU: on a 1-CPU cluster a second actor never starts and the tasks
    sent to it wait for ever."""
    ray = pytest.importorskip("ray")
    from drake_abs.parallel import RayRunner, connect, shutdown

    if ray.is_initialized():
        pytest.skip("needs its own 1-CPU cluster")
    connect(num_cpus=1)
    try:
        with pytest.raises(ValueError, match=r"workers must be at most the cluster's CPUs \(1\)"
                                             r", one CPU per worker; got 2"):  # fmt: skip
            RayRunner(workers=2)
        with RayRunner() as runner:
            assert runner.workers == 1
    finally:
        shutdown()


# ========================================================= quiet conversions: tasks and env


@pytest.fixture(scope="module")
def hopper():
    from drake_abs.tasks.locomotion import locomotion_task

    return locomotion_task("hopper")


@pytest.fixture(scope="module")
def hopper_env(hopper):
    pytest.importorskip("gymnasium")
    from drake_abs.tasks.gym_env import DrakeAbsEnv

    return DrakeAbsEnv(hopper)


@pytest.mark.parametrize("bad", [1.7, "5", True, np.nan, np.inf, 0, -3, None, 2 + 0j])
def test_a_horizon_is_a_whole_number_of_steps_from_one(hopper, bad):
    """1.7 used to run one step, "5" five and True one; NaN and inf ended in int()'s error."""
    inner = LinearPolicy(hopper.n_obs, hopper.nu)
    with pytest.raises(ValueError, match=r"horizon must be an integer >= 1; got "):
        hopper.objective(inner, horizon=bad)
    with pytest.raises(ValueError, match=r"horizon must be an integer >= 1; got "):
        point_mass_objective(horizon=bad)


def test_an_integral_horizon_is_kept_as_an_int(hopper):
    obj = hopper.objective(LinearPolicy(hopper.n_obs, hopper.nu), horizon=np.int64(5))
    assert obj.horizon == 5 and type(obj.horizon) is int
    assert point_mass_objective(horizon=5.0).horizon == 5


@pytest.mark.parametrize("bad", ["0.1", None, np.nan, -0.1, True, 0.1j])
def test_sigma_is_a_finite_real_number(hopper, bad):
    with pytest.raises(ValueError, match=r"sigma must be a finite real number"):
        hopper.objective(LinearPolicy(hopper.n_obs, hopper.nu), horizon=3, sigma=bad)


def test_complex_theta_x0_and_actions_are_refused_not_cast():
    """numpy drops the imaginary part with only a ComplexWarning: refused by name instead."""
    obj = point_mass_objective()
    P = obj.policy.n_params
    with pytest.raises(ValueError, match=r"theta must be a real numeric array; got complex"):
        first_order(obj, np.zeros(P) + 1j, np.random.default_rng(0), 2)
    with pytest.raises(ValueError, match=r"theta must be a real numeric array; got complex"):
        obj.policy.act(np.zeros(P, complex), np.zeros((1, NX)))
    with pytest.raises(ValueError, match=r"x0 must be a real numeric array; got complex"):
        PolicyObjective(obj.stepper, obj.policy, obj.reward, obj.x0 + 0j, 3)


def test_the_env_refuses_a_complex_or_non_finite_action(hopper_env):
    hopper_env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action must be a real numeric array; got complex"):
        hopper_env.step(np.array([0.1, 0.0, 0.0]) + 0.5j)
    with pytest.raises(ValueError, match=r"action contains NaN or inf"):
        hopper_env.step(np.array([0.0, np.nan, 0.0]))
    with pytest.raises(ValueError, match=r"q must be a real numeric array; got complex"):
        hopper_env.set_state(hopper_env.state[:6] + 0j, hopper_env.state[6:])


@pytest.mark.parametrize(
    "options, message",
    [
        ({"bogus": 1}, r"unknown option\(s\) \['bogus'\] of locomotion_task\('hopper'\)"),
        ({"max_iteration": 20}, r"unknown option\(s\) \['max_iteration'\]"),
        ({"max_iterations": 2.5}, r"max_iterations must be an integer >= 1"),
        ({"tol": "small"}, r"tol must be a finite real number"),
        ({"control_period": True}, r"control_period must be a finite number > 0"),
    ],
)
def test_unknown_or_bad_task_options_are_refused_when_the_env_is_built(options, message):
    """DrakeAbsEnv("hopper", bogus=1) used to build and fail at its first step."""
    pytest.importorskip("gymnasium")
    from drake_abs.tasks.gym_env import DrakeAbsEnv

    with pytest.raises(ValueError, match=message):
        DrakeAbsEnv("hopper", **options)


def test_a_stepper_refuses_unknown_solver_options_when_built():
    from drake_abs.multibody import Scene, build_scene_model

    model = build_scene_model(Scene.from_dict(FALLING_BOX))
    with pytest.raises(ValueError, match=r"unknown stepper option\(s\) \['bogus'\]"):
        model.stepper(bogus=1)
    with pytest.raises(ValueError, match=r"strict must be True or False"):
        model.stepper(strict="yes")
    assert model.stepper(max_iterations=50, strict=True).solver_options["max_iterations"] == 50


# ================================================ policy files, saved policies, command line


def _usage_error(argv: list[str], capsys) -> str:
    """Run the command line, expect a usage error (exit 2, no traceback); return its text."""
    from drake_abs.experiments.cli import main

    with pytest.raises(SystemExit) as exit_:
        main(argv)
    err = capsys.readouterr().err
    assert exit_.value.code == 2, err
    assert "Traceback" not in err and "error: " in err, err
    return err


def _damaged(source: Path, folder: Path) -> dict[str, Path]:
    """Copies of the npz ``source``: cut in half, empty, one byte flipped in the middle (its
    checksum then fails), the zip header's first bytes flipped."""
    data = source.read_bytes()
    middle = bytearray(data)
    middle[len(data) // 2] ^= 0x55
    header = bytearray(data)
    header[:4] = bytes(b ^ 0xFF for b in header[:4])
    out = {}
    for name, content in (("truncated", data[: len(data) // 2]), ("empty", b""),
                          ("flipped", bytes(middle)), ("header", bytes(header))):  # fmt: skip
        folder.mkdir(parents=True, exist_ok=True)
        out[name] = folder / f"{name}.npz"
        out[name].write_bytes(content)
    return out


@pytest.fixture
def policy_file(tmp_path) -> Path:
    from drake_abs.policy.policy_files import PolicyFile

    file = PolicyFile.linear(np.ones((3, 11)), np.zeros(3), env_id="Hopper-v5")
    return file.save(tmp_path / "good.npz")


@pytest.mark.parametrize("kind", ["truncated", "empty", "flipped", "header"])
def test_a_damaged_policy_file_is_a_value_error_naming_it(policy_file, tmp_path, kind):
    from drake_abs.policy.policy_files import is_policy_file, load_policy_file

    path = _damaged(policy_file, tmp_path / "bad")[kind]
    # it reads the archive's list of names only: a damaged member is found by the loader
    assert is_policy_file(path) is (kind == "flipped")
    with pytest.raises(ValueError, match=rf"'{path}' is not a policy file"):
        load_policy_file(path)


@pytest.mark.parametrize("kind", ["truncated", "empty", "flipped"])
def test_replay_of_a_damaged_policy_file_is_a_usage_error(policy_file, tmp_path, kind, capsys):
    path = _damaged(policy_file, tmp_path / "bad")[kind]
    err = _usage_error(["replay", str(path)], capsys)
    assert "argument POLICY" in err and str(path) in err


@pytest.fixture
def saved(tmp_path) -> dict[str, Path]:
    from drake_abs.policy.saving import save_policy

    policy = LinearPolicy(3, 2)
    return save_policy(tmp_path / "saved" / "p", policy, np.arange(policy.n_params, dtype=float))


@pytest.mark.parametrize("kind", ["truncated", "empty", "flipped", "header"])
def test_a_saved_policy_with_damaged_arrays_is_a_value_error_naming_the_file(saved, kind):
    from drake_abs.policy.saving import load_policy

    good = saved["npz"].read_bytes()
    bad = _damaged(saved["npz"], saved["npz"].parent / "copies")[kind]
    saved["npz"].write_bytes(bad.read_bytes())
    with pytest.raises(ValueError, match=rf"'{saved['npz']}' is not a saved policy's "
                                         r"arrays file"):  # fmt: skip
        load_policy(saved["json"])
    saved["npz"].write_bytes(good)
    assert load_policy(saved["json"]).theta.shape == (8,)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"n_params": 99}, r"n_params must be the LinearPolicy's number of parameters, 8; the "
                           r"file says 99"),
        ({"n_params": "8"}, r"n_params must be the LinearPolicy's number of parameters"),
        ({"n_params": True}, r"n_params must be the LinearPolicy's number of parameters"),
        ({"arrays": "../p.npz"}, r"'arrays' must be the name of the .npz file beside it"),
        ({"arrays": "/etc/hostname"}, r"'arrays' must be the name of the .npz file beside it"),
        ({"arrays": "sub/p.npz"}, r"'arrays' must be the name of the .npz file beside it"),
        ({"arrays": "p.json"}, r"'arrays' must be the name of the .npz file beside it"),
        ({"arrays": 5}, r"'arrays' must be the name of the .npz file beside it"),
    ],
)  # fmt: skip
def test_a_saved_policys_record_is_checked(saved, change, message):
    """n_params used to be ignored, and 'arrays' could name any file on the machine."""
    import json

    from drake_abs.policy.saving import load_policy

    record = json.loads(saved["json"].read_text())
    saved["json"].write_text(json.dumps(record | change))
    with pytest.raises(ValueError, match=message):
        load_policy(saved["json"])


def test_output_paths_under_a_file_and_an_empty_address_are_usage_errors(
    tmp_path, capsys, monkeypatch
):
    """They used to end in tracebacks (the folder cannot be made; Ray refused the address)."""
    from drake_abs.experiments import cli

    monkeypatch.setattr("drake_abs.parallel.sweep.run_sweep", lambda *a, **k: pytest.fail("ran"))
    monkeypatch.setattr(cli, "_run_standard", lambda *a, **k: pytest.fail("ran"))
    monkeypatch.setattr(cli, "_run_demo", lambda *a, **k: pytest.fail("ran"))
    monkeypatch.setattr(cli, "_record", lambda *a, **k: pytest.fail("ran"))
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder\n")
    under = str(blocker / "sub")
    for argv, option in [
        (["sweep", "gradient-variance", "--test-size", "--out", under], "--out"),
        (["experiment", "gradient-variance", "--test-size", "--out", under], "--out"),
        (["demo", "--out", under], "--out"),
        (["record", "ball-throw", "--out", under + "/x.html"], "--out"),
        (["evaluate", "p.npz", "--json", under + "/x.json"], "--json"),
        (["experiment", "gradient-variance", "--address", ""], "--address"),
        (["sweep", "gradient-variance", "--address", " "], "--address"),
    ]:
        err = _usage_error(argv, capsys)
        assert f"argument {option}: " in err, (argv, err)


# ============================================================================ inside the ground


def test_a_state_inside_the_ground_is_refused_by_the_env(hopper_env):
    """The Hopper 0.7 m below the ground used to be pushed up 1.21 m in one step, converged,
    with the survive reward paid."""
    hopper_env.reset(seed=0)
    start = hopper_env.state
    q, v = start[:6].copy(), start[6:].copy()
    q[1] -= 0.74  # the foot's underside starts 4 cm above the ground
    with pytest.raises(ValueError, match=r"the state \(q, v\) is 0.70\d* m inside the ground, "
                                         r"deeper than the 0.01 m a step models"):  # fmt: skip
        hopper_env.set_state(q, v)
    np.testing.assert_array_equal(hopper_env.state, start)  # unchanged
    q[1] = start[1] - 0.045  # 5 mm into the ground: within the tolerance, and reported
    hopper_env.set_state(q, v)
    *_, info = hopper_env.step(np.zeros(3))
    assert "penetration" in info and 0.0 <= info["penetration"] <= 0.01


def test_an_objective_refuses_an_initial_state_inside_the_ground(hopper, box_stepper):
    x0 = hopper.x0.copy()
    x0[1] -= 0.5
    with pytest.raises(ValueError, match=r"x0 is 0.4\d* m inside the ground"):
        PolicyObjective(hopper.stepper, hopper.policy(LinearPolicy(hopper.n_obs, hopper.nu)),
                        hopper.reward, x0, 3)  # fmt: skip
    reward = QuadraticReward(np.eye(4), np.eye(1), np.zeros(4))
    with pytest.raises(ValueError, match=r"x0 is 0.05 m inside the ground"):
        PolicyObjective(box_stepper, LinearPolicy(4, 1), reward, [0.0, 0.05, 0.0, 0.0], 3)


def test_penetration_is_the_deepest_candidates_depth_on_any_scene(box_stepper):
    """The falling box's contact point is 0.1 m below its centre."""
    x = np.array([[0.0, 0.3, 0, 0], [0.0, 0.1, 0, 0], [0.0, 0.02, 0, 0]])
    np.testing.assert_allclose(box_stepper.penetration(x), [0.0, 0.0, 0.08], atol=1e-12)
    assert box_stepper.penetration(x[2]) == pytest.approx(0.08)
    with pytest.raises(ValueError, match=r"x must have shape \(B, nq \+ nv\) = \(B, 4\)"):
        box_stepper.penetration(np.zeros(3))


def test_a_soft_contact_plant_accepts_its_resting_depth_and_refuses_deeper():
    """MuJoCo-like soft contact rests inside the ground by design (MuJoCo's HalfCheetah 13 to
    17 mm deep): 2 cm is refused with hard contact, kept with soft; 8 cm is refused by both."""
    from drake_abs.engine.steppers import refuse_inside_ground
    from drake_abs.multibody.builder import build_scene_model
    from drake_abs.multibody.scene import Scene
    from drake_abs.multibody.stepper import PENETRATION_TOL, SOFT_PENETRATION_TOL

    pytest.importorskip("gymnasium")
    hard_scene = Scene.load("gym_half_cheetah")
    soft_scene = Scene.from_dict(
        {**hard_scene.to_dict(), "compliance": {"kind": "mujoco", "from_model": True}}
    )
    hard, soft = build_scene_model(hard_scene), build_scene_model(soft_scene)
    assert hard.stepper().penetration_tolerance == PENETRATION_TOL == 0.01
    assert soft.stepper().penetration_tolerance == SOFT_PENETRATION_TOL == 0.05
    x = hard.x0.copy()
    lowest = hard.contact_model.distances(x[None, : hard.plant.num_positions()]).min()
    for depth, soft_ok in ((0.02, True), (0.08, False)):
        x[1] = hard.x0[1] - lowest - depth  # the lowest candidate `depth` m deep
        with pytest.raises(ValueError, match="inside the ground, deeper than the 0.01 m"):
            refuse_inside_ground(hard.stepper(), x)
        if soft_ok:
            refuse_inside_ground(soft.stepper(), x)
        else:
            with pytest.raises(ValueError, match="deeper than the 0.05 m"):
                refuse_inside_ground(soft.stepper(), x)


# ================================================================================== sweeps


@pytest.mark.parametrize(
    "settings, message",
    [
        (["seeds=0,-1"], r"'seeds=0,-1': seeds: expected a whole number >= 0"),
        (["seeds=0,2"], r"the point \{'seeds': 0\} is not a valid configuration: seeds must be "
                        r"an integer >= 1; got 0"),
        (["sizes=[10,0]"], r"sizes\[1\] must be an integer >= 1; got 0"),
        (["test_points=-5"], r"test_points: expected a whole number >= 0"),
    ],
)  # fmt: skip
def test_impossible_counts_are_refused_before_a_sweep_starts(settings, message, capsys,
                                                             monkeypatch):  # fmt: skip
    """seeds=0,-1 used to mark both points done with a NaN metric and exit 0."""
    from drake_abs.experiments.sweep import GridError, build_grid

    with pytest.raises(GridError, match=message):
        build_grid("implicit-learning", settings=settings, test_size=True)
    monkeypatch.setattr("drake_abs.parallel.sweep.run_sweep", lambda *a, **k: pytest.fail("ran"))
    argv = ["sweep", "implicit-learning", "--test-size", "--no-progress"]
    for setting in settings:
        argv += ["--set", setting]
    assert "argument --set: " in _usage_error(argv, capsys)


def test_an_experiment_config_refuses_a_zero_count():
    from drake_abs.experiments.implicit_learning import Config

    with pytest.raises(ValueError, match=r"seeds must be an integer >= 1; got 0"):
        Config(seeds=0)
    with pytest.raises(ValueError, match=r"sizes must hold at least one whole number"):
        Config(sizes=())


def _records_folder(values: dict, folder: Path) -> dict:
    """A point function: writes a file, notes its temporary folder, and for x == 1 is
    interrupted as Ctrl-C interrupts it."""
    (folder / "note.txt").write_text(f"{values['x']}\n")
    (Path(values["log"]) / f"{values['x']}.folder").write_text(str(folder))
    if values["x"] == 1:
        raise KeyboardInterrupt
    return {"square": values["x"] ** 2}


def test_an_interrupted_point_leaves_no_temporary_folder(tmp_path):
    from drake_abs.parallel.sweep_points import execute_point

    with pytest.raises(KeyboardInterrupt):
        execute_point(_records_folder, {"x": 1, "log": str(tmp_path)})
    folder = Path((tmp_path / "1.folder").read_text())
    assert folder.name.startswith("drake-abs-point-") and not folder.exists()
    done = execute_point(_records_folder, {"x": 2, "log": str(tmp_path)})
    assert done["status"] == "done" and not Path((tmp_path / "2.folder").read_text()).exists()


def test_folders_left_by_killed_points_are_removed_at_the_next_start(tmp_path):
    import os
    import subprocess
    import sys

    from drake_abs.parallel.sweep_points import TEMP_PREFIX, remove_stale_folders

    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)  # fmt: skip
    dead = tmp_path / f"{TEMP_PREFIX}{int(gone.stdout)}-abc"
    running = tmp_path / f"{TEMP_PREFIX}{os.getpid()}-def"
    other = tmp_path / "someone-else"
    for folder in (dead, running, other):
        (folder / "sub").mkdir(parents=True)
    assert remove_stale_folders(tmp_path) == [dead]
    assert not dead.exists() and running.exists() and other.exists()


def test_a_points_record_has_the_mode_of_its_other_files(tmp_path):
    """point.json was written 0600 (through mkstemp) while the point's files were 0644."""
    from drake_abs.parallel.sweep import run_sweep

    result = run_sweep(_records_folder, [{"x": 2, "log": str(tmp_path)}], tmp_path / "out",
                       progress=False)  # fmt: skip
    (point,) = result.points
    modes = {p.name: p.stat().st_mode & 0o777 for p in point.folder.iterdir()}
    assert modes["point.json"] == modes["note.txt"] == 0o666 & ~_umask(), modes
    gathered = {p.name: p.stat().st_mode & 0o777 for p in (tmp_path / "out").iterdir()}
    assert gathered["sweep.json"] == modes["note.txt"], gathered


def _umask() -> int:
    import os

    mask = os.umask(0o022)
    os.umask(mask)
    return mask
