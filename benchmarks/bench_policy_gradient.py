"""The first-order policy gradient of one batch on the box scene: ours against Drake (issue 4, 6).

One batch: M = 256 noisy closed-loop rollouts of H = 200 steps of a box pushed to a goal by a
linear policy, and the gradient of the mean return with respect to the policy's parameters.

- Ours: the box as a constant-matrix LCS (:class:`drake_abs.tasks.box_lcs.TranslatingBox`, ABS
  contact-aware smoothing), all M rollouts batched, the gradient by the adjoint pass
  (:func:`drake_abs.policy.estimators.first_order`). The box never leaves the ground, so every
  contact is active and ABS asks for mu = mu_min = 0: each of the M H steps is an exact
  frictional LCP (4 rows), solved to the solver's default accuracy.
- Drake: the same box (1 kg, 0.4 x 0.2 x 0.2 m, prismatic x and z joints, friction 0.5, one
  contact point at the bottom, h = 0.01 s) as a discrete MultibodyPlant with SAP
  (:func:`drake_abs.diagrams.drake_twin.make_drake_twin`), closed with the same policy, noise
  and reward (:func:`drake_abs.diagrams.policy_diagram.build_policy_diagram`) and differentiated
  by simulating the diagram in AutoDiffXd
  (:func:`~drake_abs.diagrams.policy_diagram.rollout_return`), one rollout at a time.

Timing Drake for all 256 rollouts takes minutes, so ``--drake-rollouts`` (default 6) of them
are timed and the time is scaled linearly to M (stated in the output). Both sides take the
best of ``--repeats`` timings (ours: of the whole batch; Drake: of each timed rollout), which
removes most of the noise of a shared machine without favouring either. Target: ours at least
100 times faster. The two contact models differ (hard LCP vs SAP's compliant convex
approximation), so their gradients need not be equal; on the timed rollouts the benchmark
prints the relative difference and whether the components agree in sign.

Usage: ``python benchmarks/bench_policy_gradient.py [--drake-rollouts N] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see drake_abs/__init__

import numpy as np

from drake_abs.contact.smoothing import ContactAware
from drake_abs.diagrams.drake_twin import make_drake_twin
from drake_abs.diagrams.policy_diagram import build_policy_diagram, rollout_return
from drake_abs.engine import rollout
from drake_abs.lcp.ipm import LCPConvergenceWarning
from drake_abs.multibody.scene import Scene
from drake_abs.policy.estimators import PolicyObjective, first_order
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.tasks.box_lcs import TranslatingBox

M, H = 256, 200
GOAL = 0.5  # m
SIGMA = 1.0  # N, exploration noise on the push
TARGET = 100.0


def box_scene(box: TranslatingBox) -> Scene:
    """The translating box as a scene (drake_abs/models/box_translating.sdf: 1 kg, 0.2 m tall)."""
    return Scene.from_dict(
        {
            "name": "box_translating",
            "time_step": box.time_step,
            "models": [{"file": "drake_abs:models/box_translating.sdf"}],
            "contacts": [
                {"body": "box", "points": [[0.0, 0.0, -box.half_height]], "friction": box.friction}
            ],
            "friction_directions": 2,
        }
    )


def task():
    box = TranslatingBox(mass=1.0, half_height=0.1, friction=0.5, time_step=0.01)
    policy = LinearPolicy(4, 1)
    reward = QuadraticReward(
        Q=np.diag([1.0, 0.0, 0.1, 0.0]), R=0.01 * np.eye(1),
        x_goal=np.array([GOAL, box.half_height, 0.0, 0.0]),
    )  # fmt: skip
    # u = -20 (p_x - goal) - 5 v_x: starts at 10 N (above the 4.9 N threshold), sticks near goal
    theta = np.array([-20.0, 0.0, -5.0, 0.0, 20.0 * GOAL])
    return box, policy, reward, theta, box.resting_state()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--drake-rollouts", type=int, default=6)
    parser.add_argument(
        "--repeats", type=int, default=3, help="timed repeats of ours and of each Drake rollout"
    )
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)

    box, policy, reward, theta, x0 = task()
    smoothing = ContactAware(mu_max=1e-3, length=0.02)
    obj = PolicyObjective(box.stepper(smoothing, "frozen"), policy, reward, x0, H, SIGMA)

    warnings.simplefilter("ignore", LCPConvergenceWarning)  # counted below
    first_order(obj, theta, np.random.default_rng(0), 8)  # compile the solver kernels
    times = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        est = first_order(obj, theta, np.random.default_rng(1), M)
        times.append(time.perf_counter() - start)
    ours = float(np.min(times))

    # Drake SAP, AutoDiffXd, one rollout at a time, with the same noise as ours' first rollouts
    noise = obj.noise(np.random.default_rng(1), M)
    scene = box_scene(box)
    n = args.drake_rollouts
    drake_grads, drake_returns, drake_times, build_times = [], [], [], []
    for m in range(n):
        start = time.perf_counter()
        twin = make_drake_twin(scene, "sap", sampled_outputs=False)  # a diagram owns its plant
        pd = build_policy_diagram(
            twin.diagram, policy, reward, theta, noise[m], box.time_step, sigma=SIGMA,
            state_port="state", input_port="actuation",
        )  # fmt: skip
        build_times.append(time.perf_counter() - start)
        best = np.inf
        for _ in range(args.repeats):  # the same rollout, best of the repeats (as for ours)
            start = time.perf_counter()
            r = rollout_return(pd, theta, x0)
            J, grad = r.value, r.gradient
            best = min(best, time.perf_counter() - start)
        drake_times.append(best)
        drake_grads.append(grad)
        drake_returns.append(J)
    per_rollout = float(np.mean(drake_times))
    drake = per_rollout * M
    ratio = drake / ours

    ours_check = rollout(obj.stepper, policy, theta, x0, noise[:n], reward, sigma=SIGMA)
    g_ours, g_drake = ours_check.grad, np.array(drake_grads)
    rel = np.linalg.norm(g_ours - g_drake, axis=1) / np.linalg.norm(g_drake, axis=1)
    sign = np.mean(np.sign(g_ours) == np.sign(g_drake), axis=1)
    cos = np.sum(g_ours * g_drake, axis=1) / (
        np.linalg.norm(g_ours, axis=1) * np.linalg.norm(g_drake, axis=1)
    )

    print(f"first-order gradient of one batch, box scene, M = {M}, H = {H} "
          f"(policy u = K x + k, {theta.size} parameters)")  # fmt: skip
    print(f"  ours  (box LCS, ABS, batched adjoint): {ours:8.3f} s  (best of {args.repeats}; "
          f"{est.unconverged} of {est.steps} steps unconverged)")  # fmt: skip
    print(f"  Drake (MultibodyPlant SAP, AutoDiffXd): {drake:8.1f} s  = {per_rollout:.3f} s per "
          f"rollout (best of {args.repeats}) on {n} rollouts x {M} (linear scaling); diagram "
          f"building "
          f"{np.mean(build_times):.3f} s per rollout not included")  # fmt: skip
    print(
        f"  ratio {ratio:.0f}x: {'PASS' if ratio >= TARGET else 'FAIL'} (target >= {TARGET:.0f}x)"
    )
    print("  gradient check on the timed rollouts (different contact models: not expected equal)")
    for m in range(n):
        print(f"    rollout {m}: return ours {ours_check.returns[m]:9.3f}, Drake "
              f"{drake_returns[m]:9.3f}; |g_ours - g_drake| / |g_drake| = {rel[m]:.3f}, "
              f"cosine {cos[m]:+.3f}, components with equal sign {100 * sign[m]:.0f}%")  # fmt: skip
    print(f"    mean over the batch: ours g = {np.array2string(est.grad, precision=3)}")
    print(f"    Drake g (mean of {n}) = {np.array2string(g_drake.mean(axis=0), precision=3)}, "
          f"ours (same {n}) = {np.array2string(g_ours.mean(axis=0), precision=3)}")  # fmt: skip
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({
            "M": M, "H": H, "ours_seconds": ours, "drake_seconds_scaled": drake,
            "drake_seconds_per_rollout": per_rollout, "drake_rollouts_timed": n,
            "ratio": ratio, "target": TARGET, "pass": bool(ratio >= TARGET),
            "relative_difference": rel.tolist(), "cosine": cos.tolist(),
            "sign_agreement": sign.tolist(), "ours_unconverged_steps": est.unconverged,
        }, indent=2))  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
