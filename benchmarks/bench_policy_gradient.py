"""The first-order policy gradient of one batch: ours against Drake on the same rigid-body model.

Task: the translating box (``drake_abs/models/box_translating.sdf``: 1 kg, prismatic x and z
joints, one contact point at its bottom, friction 0.5, h = 10 ms) pushed to a goal by a linear
policy ``u = K x + k`` with exploration noise (sigma = 1 N); M = 256 rollouts of H = 200 steps,
and the gradient of each rollout's return with respect to the policy's 5 parameters. Every row
is timed in this run, every rollout is run on every side (``--drake-rollouts`` N < M runs N
Drake rollouts and scales their time to M; the output says so).

Rows:

- **ours, batched**: the scene's complementarity stepper on the scene's MultibodyPlant model
  (pinocchio provider) with ABS smoothing, all M rollouts in one engine call and its reverse
  pass. The plant's joints are prismatic, so its quantities are affine in the state and are
  evaluated once (``drake_abs/multibody/affine_dynamics.py``; exact, tested against the
  general path).
- **ours, batched, general provider**: the same with the per-state rigid-body algorithms
  (what a plant with rotations costs per state).
- **ours, one rollout per call**: the per-rollout cost; batching gain = its time / batched.
- **ours, constant-matrix LCS**: the box as the LCS of ``TranslatingBox``, a simpler model of
  the same box (its own labelled row; not the same model as Drake's).
- **Drake SAP / Similar, closed loop**: the same model as a discrete MultibodyPlant + SceneGraph
  (``make_drake_twin``), closed by the policy, noise and reward as Drake systems
  (``build_policy_diagram``; pydrake offers no C++ system that multiplies a parameter matrix by
  the state under AutoDiffXd, so the policy is a Python LeafSystem), converted to AutoDiffXd and
  simulated one rollout at a time (``rollout_return``).
  ``rollout_return`` converts the diagram to AutoDiffXd in every call; that conversion's time
  is measured and printed separately.
- **Drake SAP / Similar, plant with the policy in Python between steps**: the plant + SceneGraph
  as a ``DrakePlantStepper`` in the engine (one discrete update per step, its Jacobians by
  AutoDiffXd), the policy and the reward in Python between steps, the gradient by the engine's
  reverse pass. Gives the trajectories.
- **Drake SAP / Similar, plant only (lower bound)**: the plant + SceneGraph alone in
  AutoDiffXd, its input fixed to a value carrying the same 5 derivatives, advanced over the
  whole horizon in one C++ call: what Drake's plant costs per rollout before any closed loop.

Beside each Drake time, the physics agreement with ours: the RMS position difference over all
rollouts and steps (plant-only rows), the relative difference of the mean return and of the
batch-mean gradient, and the median per-rollout relative gradient difference. The contact
models differ (hard LCP against compliant point contact), so the agreement is not expected to
be exact. Targets: ours batched at least 30 times faster than Drake SAP's closed loop and 10
times faster than its plant-only loop. Timing: ours the best of ``--repeats`` batches; Drake
one pass over all rollouts (each row's total over 256 rollouts).

Usage: ``python benchmarks/bench_policy_gradient.py [--drake-rollouts N] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see drake_abs/__init__

import numpy as np

from drake_abs.contact.smoothing import ContactAware
from drake_abs.diagrams.policy_diagram import build_policy_diagram, rollout_return
from drake_abs.engine import rollout
from drake_abs.lcp.ipm import LCPConvergenceWarning
from drake_abs.multibody import build_scene_model
from drake_abs.multibody.scene import Scene
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.reference.drake_plant import DrakePlantStepper
from drake_abs.reference.drake_twin import make_drake_twin
from drake_abs.tasks.box_lcs import TranslatingBox

M, H = 256, 200
GOAL = 0.5  # m
SIGMA = 1.0  # N, exploration noise on the push
TARGET_CLOSED_LOOP, TARGET_PLANT_ONLY = 30.0, 10.0
SMOOTHING = ContactAware(mu_max=1e-3, length=0.02)


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


# ----------------------------------------------------------------------------------------------
# ours


def _best(repeats: int, fn):
    best, out = np.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best, out


def ours_rows(box, policy, reward, theta, x0, noise, repeats: int) -> dict:
    """Ours: batched (affine quantities), batched with the general provider, one rollout per
    call, and the constant-matrix LCS."""
    model = build_scene_model(box_scene(box))
    assert model.contact_model.affine is not None  # prismatic joints only
    stepper = model.stepper(smoothing=SMOOTHING)
    general_model = build_scene_model(box_scene(box))
    general_model.contact_model.affine = None
    general = general_model.stepper(smoothing=SMOOTHING)
    lcs = box.stepper(SMOOTHING)

    def batch(s):
        return rollout(s, policy, theta, x0, noise, reward, sigma=SIGMA)

    rollout(stepper, policy, theta, x0, noise[:4], reward, sigma=SIGMA)  # compile the kernels
    t_batch, traj = _best(repeats, lambda: batch(stepper))
    t_general, traj_general = _best(repeats, lambda: batch(general))
    t_lcs, traj_lcs = _best(repeats, lambda: batch(lcs))
    start = time.perf_counter()
    singles = [
        rollout(stepper, policy, theta, x0, noise[m : m + 1], reward, sigma=SIGMA)
        for m in range(len(noise))
    ]
    t_single = time.perf_counter() - start
    single_returns = np.concatenate([s.returns for s in singles])
    single_grads = np.concatenate([s.grad for s in singles])
    for name, returns in (
        ("general provider", traj_general.returns),
        ("one per call", single_returns),
    ):
        if not np.allclose(returns, traj.returns, rtol=1e-6):  # the same model, run another way
            raise RuntimeError(f"ours {name}: returns differ from the batched run")
    return {
        "batched": {"seconds": t_batch, "traj": traj},
        "general_provider": {"seconds": t_general, "traj": traj_general},
        "one_per_call": {"seconds": t_single, "grad": single_grads},
        "lcs": {"seconds": t_lcs, "traj": traj_lcs},
        "unconverged_steps": int((~traj.converged).sum()),
        "profile": profile_ours(lambda: batch(stepper)),
    }


def profile_ours(fn) -> dict:
    """Where the batched time goes: seconds in the solver, the quantities, the rest of the
    contact step, the reverse pass, and the total (one profiled run)."""
    prof = cProfile.Profile()
    prof.enable()
    fn()
    prof.disable()
    stats = pstats.Stats(prof).stats
    total = sum(v[2] for v in stats.values())

    def cum(name: str, file_part: str) -> float:
        return sum(v[3] for k, v in stats.items() if k[2] == name and file_part in k[0])

    parts = {
        "lcp_solve": cum("solve_lcp_trusted", "ipm.py"),
        "quantities": cum("quantities", "drake_dynamics.py"),
        "contact_step": cum("contact_step", "contact_lcp.py"),
        "reverse_pass": cum("reverse_pass", "adjoint.py"),
        "total": cum("rollout", "closed_loop.py") or total,
    }
    parts["contact_step_besides_lcp"] = parts.pop("contact_step") - parts["lcp_solve"]
    return parts


# ----------------------------------------------------------------------------------------------
# Drake


def _reward_ad(reward: QuadraticReward, x, u):
    """The stage reward on AutoDiffXd values (object arrays)."""
    e = x - reward.x_goal
    return -(e @ reward.Q @ e) - (u @ reward.R @ u)


def drake_plant_only(scene, approximation, policy, reward, theta, x0, noise) -> dict:
    """The plant + SceneGraph as a :class:`~drake_abs.reference.drake_plant.DrakePlantStepper`
    in the engine: the policy and the reward in Python between Drake's steps, the gradient by
    the engine's reverse pass over Drake's one-step AutoDiffXd Jacobians."""
    stepper = DrakePlantStepper(scene, approximation)
    start = time.perf_counter()
    traj = rollout(stepper, policy, theta, x0, noise, reward, sigma=SIGMA)
    seconds = time.perf_counter() - start
    return {"seconds": seconds, "returns": traj.returns, "grad": traj.grad, "x": traj.x}


def drake_plant_lower_bound(scene, approximation, P: int, x0, n: int, horizon: int, h) -> dict:
    """Seconds for n rollouts of the plant + SceneGraph alone in AutoDiffXd (P derivatives), its
    input fixed, each advanced over the whole horizon in one C++ call."""
    from pydrake.autodiffutils import AutoDiffXd
    from pydrake.systems.analysis import Simulator_

    twin = make_drake_twin(scene, approximation, sampled_outputs=False)
    diagram = twin.diagram.ToAutoDiffXd()
    plant = diagram.GetSubsystemByName(twin.plant.get_name())
    u = [AutoDiffXd(0.0, np.eye(P)[j % P]) for j in range(plant.num_actuators())]
    start = time.perf_counter()
    for _ in range(n):
        simulator = Simulator_[AutoDiffXd](diagram)
        pctx = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
        plant.SetPositionsAndVelocities(pctx, [AutoDiffXd(v, np.ones(P)) for v in x0])
        plant.get_actuation_input_port().FixValue(pctx, u)
        simulator.AdvanceTo(horizon * h)
    return {"seconds": time.perf_counter() - start}


def drake_closed_loop(scene, approximation, policy, reward, theta, x0, noise, h) -> dict:
    """The closed loop as a Drake diagram (plant, SceneGraph, policy, noise and reward systems)
    in AutoDiffXd, one rollout at a time (diagram building not counted)."""
    returns, grads, seconds, conversion = [], [], 0.0, 0.0
    for m in range(len(noise)):
        twin = make_drake_twin(scene, approximation, sampled_outputs=False)
        pd = build_policy_diagram(
            twin.diagram, policy, reward, theta, noise[m], h, sigma=SIGMA,
            state_port="state", input_port="actuation",
        )  # fmt: skip
        start = time.perf_counter()
        r = rollout_return(pd, theta, x0)
        seconds += time.perf_counter() - start
        if m < 4:  # the AutoDiffXd conversion rollout_return does in each call, timed apart
            start = time.perf_counter()
            pd.diagram.ToAutoDiffXd()
            conversion += (time.perf_counter() - start) / min(4, len(noise))
        returns.append(r.value)
        grads.append(r.gradient)
    return {"seconds": seconds, "conversion_seconds_per_rollout": conversion,
            "returns": np.array(returns), "grad": np.array(grads)}  # fmt: skip


def agreement(ours, drake: dict) -> dict:
    """Physics agreement of a Drake row with ours on the same rollouts."""
    n = len(drake["returns"])
    g_o, g_d = ours.grad[:n], drake["grad"]
    per = np.linalg.norm(g_o - g_d, axis=1) / np.linalg.norm(g_d, axis=1)
    mean_o, mean_d = g_o.mean(axis=0), g_d.mean(axis=0)
    out = {
        "mean_return_ours": float(ours.returns[:n].mean()),
        "mean_return_drake": float(drake["returns"].mean()),
        "mean_gradient_relative_difference": float(
            np.linalg.norm(mean_o - mean_d) / np.linalg.norm(mean_d)
        ),
        "mean_gradient_cosine": float(
            mean_o @ mean_d / (np.linalg.norm(mean_o) * np.linalg.norm(mean_d))
        ),
        "median_rollout_gradient_relative_difference": float(np.median(per)),
    }
    if "x" in drake:
        d = ours.x[:n, :, :2] - drake["x"][:, :, :2]
        out["rms_position_difference_m"] = float(np.sqrt(np.mean(np.sum(d**2, axis=-1))))
        out["max_position_difference_m"] = float(np.sqrt(np.sum(d**2, axis=-1)).max())
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--drake-rollouts", type=int, default=M,
        help="Drake rollouts run (fewer than M: their time scaled to M)",
    )  # fmt: skip
    parser.add_argument("--repeats", type=int, default=3, help="timed repeats of ours' batches")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    n = min(max(1, args.drake_rollouts), M)

    warnings.simplefilter("ignore", LCPConvergenceWarning)  # counted below
    box, policy, reward, theta, x0 = task()
    noise = np.random.default_rng(1).standard_normal((M, H, policy.nu))
    ours = ours_rows(box, policy, reward, theta, x0, noise, args.repeats)
    t_ours = ours["batched"]["seconds"]
    traj = ours["batched"]["traj"]

    scene = box_scene(box)
    drake = {}
    for approx in ("sap", "similar"):
        drake[f"{approx}_closed_loop"] = drake_closed_loop(
            scene, approx, policy, reward, theta, x0, noise[:n], box.time_step
        )
        drake[f"{approx}_plant_policy_in_python"] = drake_plant_only(
            scene, approx, policy, reward, theta, x0, noise[:n]
        )
        drake[f"{approx}_plant_only_lower_bound"] = drake_plant_lower_bound(
            scene, approx, theta.size, x0, n, H, box.time_step
        )
    scale = M / n  # 1 unless --drake-rollouts < M
    rows = {
        "ours_batched": t_ours,
        "ours_batched_general_provider": ours["general_provider"]["seconds"],
        "ours_one_rollout_per_call": ours["one_per_call"]["seconds"],
        "ours_constant_matrix_lcs": ours["lcs"]["seconds"],
        **{f"drake_{k}": v["seconds"] * scale for k, v in drake.items()},
    }
    g_cl, g_py = drake["sap_closed_loop"]["grad"], drake["sap_plant_policy_in_python"]["grad"]
    same = np.allclose(g_cl, g_py, rtol=1e-6, atol=1e-9)
    ratio_cl = rows["drake_sap_closed_loop"] / t_ours
    ratio_po = rows["drake_sap_plant_only_lower_bound"] / t_ours
    conversion = drake["sap_closed_loop"]["conversion_seconds_per_rollout"]

    print(f"first-order gradient of one batch, translating box, M = {M}, H = {H} "
          f"(policy u = K x + k, {theta.size} parameters); seconds for all {M} rollouts"
          + ("" if n == M else f" (Drake: {n} rollouts run, scaled to {M})"))  # fmt: skip
    for name, seconds in rows.items():
        print(f"  {name:36s} {seconds:9.3f} s   ({seconds / t_ours:7.1f} x ours batched)")
    gain = rows["ours_one_rollout_per_call"] / t_ours
    print(f"  batching gain (one per call / batched): {gain:.1f}x; "
          f"per rollout: ours {rows['ours_one_rollout_per_call'] / M * 1e3:.2f} ms, Drake SAP "
          f"closed loop {rows['drake_sap_closed_loop'] / M * 1e3:.2f} ms")  # fmt: skip
    verdict = {True: "PASS", False: "FAIL"}
    print(f"  ours batched vs Drake SAP closed loop: {ratio_cl:.1f}x "
          f"({verdict[ratio_cl >= TARGET_CLOSED_LOOP]}, target {TARGET_CLOSED_LOOP:.0f}x); "
          f"vs its plant-only loop (lower bound): {ratio_po:.1f}x "
          f"({verdict[ratio_po >= TARGET_PLANT_ONLY]}, "
          f"target {TARGET_PLANT_ONLY:.0f}x)")  # fmt: skip
    print(f"  of Drake SAP's closed loop, the AutoDiffXd conversion in each rollout_return: "
          f"{conversion * 1e3:.1f} ms per rollout ({conversion * M:.1f} s for {M})")  # fmt: skip
    print(f"  Drake's closed loop and its plant with the policy in Python give the same gradients: "
          f"{same}")  # fmt: skip
    prof = ours["profile"]
    print("  where ours' batched time goes (one profiled run): " + ", ".join(
        f"{k} {v / prof['total']:.0%}" for k, v in prof.items() if k != "total"))  # fmt: skip
    print(f"  ours: {ours['unconverged_steps']} of {M * H} steps unconverged")
    agree = {k: agreement(traj, v) for k, v in drake.items() if "returns" in v}
    for k, a in agree.items():
        print(f"  agreement, {k}: " + ", ".join(f"{name} {value:.4g}" for name, value in a.items()))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({
            "M": M, "H": H, "drake_rollouts_run": n, "seconds": rows,
            "ratio_closed_loop": ratio_cl, "ratio_plant_only": ratio_po,
            "targets": {"closed_loop": TARGET_CLOSED_LOOP, "plant_only": TARGET_PLANT_ONLY},
            "pass": bool(ratio_cl >= TARGET_CLOSED_LOOP and ratio_po >= TARGET_PLANT_ONLY),
            "batching_gain": rows["ours_one_rollout_per_call"] / t_ours,
            "profile_seconds": prof, "agreement": agree,
            "drake_closed_loop_equals_plant_policy_in_python": bool(same),
            "drake_conversion_seconds_per_rollout": conversion,
            "ours_unconverged_steps": ours["unconverged_steps"],
        }, indent=2))  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
