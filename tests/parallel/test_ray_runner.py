"""The Ray rollout runner (drake_abs.parallel.RayRunner) on a local 2-CPU cluster bound to
127.0.0.1: every estimator returns the single-process estimate (gradient and return to 1e-12)
for the same seed whatever the number of workers and the split; each actor rebuilds a scene's
stepper once and keeps it; an actor killed mid-gradient is restarted, its task re-run, and the
estimate is unchanged; errors raised in the workers reach the caller as themselves; warnings
raised there are raised again here; an objective that cannot be sent says why."""

from __future__ import annotations

import os
import signal
import sys
import threading
import time

import numpy as np
import pytest

ray = pytest.importorskip("ray")

from ray import cloudpickle  # noqa: E402

from drake_abs import Fixed, point_mass_lcs  # noqa: E402
from drake_abs.contact.lcs import LcsStepper  # noqa: E402
from drake_abs.contact.unconverged import UnconvergedStepWarning  # noqa: E402
from drake_abs.multibody.builder import build_scene_model  # noqa: E402
from drake_abs.multibody.stepper import ComplementarityStepper  # noqa: E402
from drake_abs.parallel import RayRunner, connect, shutdown  # noqa: E402
from drake_abs.policy.estimators import (  # noqa: E402
    PolicyObjective,
    alpha_order,
    ars,
    first_order,
    randomized_smoothing,
    zeroth_order,
)
from drake_abs.policy.policies import LinearPolicy, MLPPolicy  # noqa: E402
from drake_abs.policy.rewards import QuadraticReward  # noqa: E402
from drake_abs.policy.rollouts import LocalRunner, use_runner  # noqa: E402

# The test module's classes go to the workers by value (they cannot import tests/).
cloudpickle.register_pickle_by_value(sys.modules[__name__])


@pytest.fixture(scope="module")
def cluster():
    connect(num_cpus=2)
    yield
    shutdown()


def hopper_objective(horizon: int = 40, policy=None) -> PolicyObjective:
    """The planar hopper (a scene: its stepper pickles as the scene description), a posture
    reward, exploration noise 0.3."""
    model = build_scene_model("hopper")
    stepper = model.stepper(smoothing=Fixed(1e-3))
    nx, nu = model.x0.size, stepper.sizes[2]
    reward = QuadraticReward(Q=0.1 * np.eye(nx), R=0.01 * np.eye(nu), x_goal=model.x0)
    policy = LinearPolicy(nx, nu) if policy is None else policy
    return PolicyObjective(stepper, policy, reward, model.x0, horizon, 0.3)


def ball_objective(stepper=None, on_unconverged="drop") -> PolicyObjective:
    """A 2-D ball bouncing (an LCS)."""
    lcs = point_mass_lcs(2, time_step=0.02)
    stepper = LcsStepper(lcs, Fixed(1e-3), "total") if stepper is None else stepper
    reward = QuadraticReward(
        Q=np.diag([0.0, 1.0, 0.0, 0.01]), R=0.01 * np.eye(2), x_goal=np.array([1, 0.2, 0, 0.0])
    )
    x0 = np.array([0.0, 0.3, 1.0, -1.0])
    return PolicyObjective(stepper, LinearPolicy(4, 2), reward, x0, 30, 0.3, on_unconverged)


ESTIMATORS = {
    "first_order": lambda obj, th, rng, **kw: first_order(obj, th, rng, 12, **kw),
    "zeroth_order": lambda obj, th, rng, **kw: zeroth_order(obj, th, rng, 12, **kw),
    "alpha_order": lambda obj, th, rng, **kw: alpha_order(obj, th, rng, 12, 0.3, **kw),
    "randomized_smoothing": lambda obj, th, rng, **kw: randomized_smoothing(
        obj, th, rng, 7, 0.05, **kw
    ),
    "ars": lambda obj, th, rng, **kw: ars(obj, th, rng, 3, 0.05, 2, 4, **kw),
}


def _same(a, b):
    """Gradient and return to 1e-12 (relative to the gradient's size), counts exactly."""
    scale = max(1.0, float(np.abs(a.grad).max()))
    np.testing.assert_allclose(b.grad, a.grad, rtol=0, atol=1e-12 * scale)
    assert b.value == pytest.approx(a.value, rel=1e-12, abs=1e-12)
    assert (b.rollouts, b.steps, b.unconverged, b.dropped) == (
        a.rollouts, a.steps, a.unconverged, a.dropped,
    )  # fmt: skip


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_every_estimator_matches_the_single_process_estimate_for_any_split(cluster, name):
    estimator = ESTIMATORS[name]
    obj = hopper_objective()
    theta = 0.02 * np.random.default_rng(0).standard_normal(obj.policy.n_params)
    local = estimator(obj, theta, np.random.default_rng(7))
    assert np.abs(local.grad).max() > 0
    # every split for the plain first-order estimator; for the others, the two that differ most
    # (one chunk per worker, and one rollout per chunk), which keeps the test's Ray start-ups few
    splits = (
        ((1, None), (2, None), (2, 1), (2, 5)) if name == "first_order" else ((2, None), (2, 1))
    )
    for workers, chunk in splits:
        with RayRunner(workers, chunk_size=chunk) as runner:
            _same(local, estimator(obj, theta, np.random.default_rng(7), runner=runner))
    # another seed gives another estimate (the comparison above can fail)
    other = estimator(obj, theta, np.random.default_rng(8))
    assert not np.allclose(other.grad, local.grad)


def test_the_default_runner_sends_an_unchanged_experiment_to_ray(cluster):
    obj = ball_objective()
    theta = np.full(obj.policy.n_params, 0.05)
    local = first_order(obj, theta, np.random.default_rng(3), 16)
    with RayRunner(2) as runner, use_runner(runner):
        distributed = first_order(obj, theta, np.random.default_rng(3), 16)
        assert runner.tasks_sent == 2
    _same(local, distributed)
    again = first_order(obj, theta, np.random.default_rng(3), 16, runner=LocalRunner())
    np.testing.assert_array_equal(again.grad, local.grad)  # the default is the local runner


def test_each_actor_rebuilds_the_stepper_once_and_keeps_it(cluster):
    obj = hopper_objective(horizon=5)
    theta = np.zeros(obj.policy.n_params)
    with RayRunner(2) as runner:
        for seed in range(3):
            first_order(obj, theta, np.random.default_rng(seed), 4, runner=runner)
        assert runner.objectives_built() == [1, 1]
        # an equal objective built anew is recognised by its content: not sent again
        first_order(hopper_objective(horizon=5), theta, np.random.default_rng(0), 4, runner=runner)
        assert runner.objectives_built() == [1, 1]
        # another policy is another objective
        mlp = hopper_objective(horizon=5, policy=MLPPolicy(obj.policy.nx, obj.policy.nu, (4,)))
        th = mlp.policy.init(np.random.default_rng(0), 0.1)
        first_order(mlp, th, np.random.default_rng(0), 4, runner=runner)
        assert runner.objectives_built() == [2, 2]


def _cpu_seconds(pid: int) -> float:
    import psutil

    t = psutil.Process(pid).cpu_times()
    return t.user + t.system


def test_an_actor_killed_mid_gradient_is_restarted_and_the_estimate_is_unchanged(cluster):
    obj = hopper_objective(horizon=400)  # about 2 s of work per actor here
    theta = 0.02 * np.random.default_rng(1).standard_normal(obj.policy.n_params)
    M = 384
    local = first_order(obj, theta, np.random.default_rng(11), M)
    with RayRunner(2) as runner:
        first_order(obj, theta, np.random.default_rng(0), 2, runner=runner)  # objective sent
        before = runner.pids()
        victim = before[1]
        idle = _cpu_seconds(victim)
        result, failure = {}, []

        def estimate():
            try:
                result["est"] = first_order(obj, theta, np.random.default_rng(11), M,
                                            runner=runner)  # fmt: skip
            except Exception as err:  # pragma: no cover - reported below
                failure.append(err)

        worker = threading.Thread(target=estimate)
        worker.start()
        deadline = time.monotonic() + 60
        while _cpu_seconds(victim) < idle + 0.2:  # the actor is computing its chunk
            assert worker.is_alive(), "the task finished before the actor could be killed"
            assert time.monotonic() < deadline
            time.sleep(0.02)
        os.kill(victim, signal.SIGKILL)
        worker.join(timeout=300)
        assert not failure, failure
        after = runner.pids()
    assert after[0] == before[0] and after[1] != before[1]  # restarted, a new process
    _same(local, result["est"])


def test_errors_in_the_workers_reach_the_caller_as_themselves(cluster):
    from drake_abs.contact.unconverged import UnconvergedStepError

    obj = ball_objective(_Corrupting(ball_objective().stepper), on_unconverged="raise")
    with RayRunner(2) as runner:
        with pytest.raises(UnconvergedStepError, match="on_unconverged='raise'"):
            first_order(obj, np.zeros(10), np.random.default_rng(0), 8, runner=runner)
        # the runner is still usable
        good = first_order(ball_objective(), np.zeros(10), np.random.default_rng(0), 4,
                           runner=runner)  # fmt: skip
    assert np.isfinite(good.grad).all()


class _Corrupting:
    """Marks unconverged every step that starts beyond x = 0.58 m (a test stepper: which rollouts
    get there depends on their noise)."""

    def __init__(self, inner):
        self.inner = inner
        self.parameter_names = inner.parameter_names

    def step(self, x, u, *, jacobians=True, parameters=False):
        from dataclasses import replace

        s = self.inner.step(x, u, jacobians=jacobians, parameters=parameters)
        return replace(s, converged=s.converged & ~(np.asarray(x)[:, 0] > 0.58))


def test_warnings_raised_in_the_workers_are_raised_again_here(cluster):
    obj = ball_objective(_Corrupting(ball_objective().stepper))
    theta = np.zeros(obj.policy.n_params)
    with pytest.warns(UnconvergedStepWarning, match="dropped"):
        local = first_order(obj, theta, np.random.default_rng(0), 8)
    assert 0 < local.dropped < 8
    with RayRunner(2) as runner, pytest.warns(UnconvergedStepWarning, match="dropped"):
        distributed = first_order(obj, theta, np.random.default_rng(0), 8, runner=runner)
    _same(local, distributed)


def test_an_objective_that_cannot_be_sent_says_why(cluster):
    model = build_scene_model("box_push")
    direct = ComplementarityStepper(model.contact_model)  # no scene description
    obj = PolicyObjective(
        direct, LinearPolicy(model.x0.size, direct.sizes[2]),
        QuadraticReward(Q=np.eye(model.x0.size), R=np.eye(direct.sizes[2]), x_goal=model.x0),
        model.x0, 3, 0.1,
    )  # fmt: skip
    with RayRunner(1) as runner, pytest.raises(TypeError, match="make_stepper"):
        first_order(obj, np.zeros(obj.policy.n_params), np.random.default_rng(0), 2,
                    runner=runner)  # fmt: skip


def test_bad_runner_arguments_are_refused_by_name(cluster):
    with pytest.raises(ValueError, match="workers"):
        RayRunner(0)
    with pytest.raises(ValueError, match="chunk_size"):
        RayRunner(1, chunk_size=2.5)
    with pytest.raises(ValueError, match="max_retries"):
        RayRunner(1, max_retries=-1)
    with pytest.raises(ValueError, match="runner"):
        first_order(ball_objective(), np.zeros(10), np.random.default_rng(0), 2, runner=object())
    runner = RayRunner(1)
    runner.close()
    with pytest.raises(RuntimeError, match="closed"):
        runner.pids()


def _loopback(ip: str) -> bool:
    """127.0.0.0/8, ::1, or an IPv4-mapped IPv6 loopback address (::ffff:127.0.0.1)."""
    import ipaddress

    address = ipaddress.ip_address(ip.split("%")[0])
    mapped = getattr(address, "ipv4_mapped", None)
    return address.is_loopback or (mapped is not None and mapped.is_loopback)


def test_every_ray_listener_is_on_the_loopback_interface(cluster):
    import psutil

    ray_pids = {p.pid for p in psutil.Process().children(recursive=True)}
    with RayRunner(2) as runner:
        ray_pids |= set(runner.pids())
        listening = [
            c for c in psutil.net_connections(kind="inet")
            if c.status == psutil.CONN_LISTEN and c.pid in ray_pids | {os.getpid()}
        ]  # fmt: skip
    assert listening, "no Ray listener found (the check would pass vacuously)"
    outside = [(c.pid, c.laddr) for c in listening if not _loopback(c.laddr.ip)]
    assert not outside, outside
