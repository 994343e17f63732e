"""Gradient time against the number of Ray workers, the per-task overhead, and the chunk size.

One first-order policy gradient (M rollouts of H steps of a scene, a linear policy) computed:
- in this process (the reference, :class:`~drake_abs.policy.rollouts.LocalRunner`);
- by a :class:`~drake_abs.parallel.RayRunner` with 1, 2, ... workers (one task per worker);
- with 2 workers (or the largest count) at several chunk sizes (rollouts per task).

Printed per worker count: seconds per gradient (median of ``--repeats``), the speed-up over the
1-worker runner and over the local run, and the parallel efficiency ``T_1 / (w T_w)``. The
per-task overhead is measured twice: the round trip of an empty actor call, and the time of a
gradient of one one-step rollout per task minus its local compute. The chunk-size table is
what the default (``ceil(M / workers)``: one task per worker) was chosen from. Every Ray
gradient is checked against the local one (printed: the largest difference).

Usage: ``python benchmarks/bench_ray.py [--scene hopper] [--rollouts 256] [--horizon 100]
[--workers 1 2] [--repeats 3] [--address ADDR] [--json FILE]``. Without ``--address`` it starts a
local cluster (127.0.0.1) with as many CPUs as the largest worker count.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from pathlib import Path

import numpy as np

from drake_abs.contact.smoothing import Fixed
from drake_abs.multibody.builder import build_scene_model
from drake_abs.parallel import RayRunner, connect, shutdown
from drake_abs.policy.estimators import PolicyObjective, first_order
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.rewards import QuadraticReward


def objective(scene: str, horizon: int) -> PolicyObjective:
    model = build_scene_model(scene)
    stepper = model.stepper(smoothing=Fixed(1e-3))
    nx, nu = model.x0.size, stepper.sizes[2]
    reward = QuadraticReward(Q=0.1 * np.eye(nx), R=0.01 * np.eye(nu), x_goal=model.x0)
    return PolicyObjective(stepper, LinearPolicy(nx, nu), reward, model.x0, horizon, 0.3)


def timed(fn, repeats: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), out


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="hopper")
    parser.add_argument("--rollouts", type=int, default=256)
    parser.add_argument("--horizon", type=int, default=100)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--address", default=None)
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    M, H = args.rollouts, args.horizon
    obj = objective(args.scene, H)
    theta = 0.02 * np.random.default_rng(0).standard_normal(obj.policy.n_params)

    def grad(runner=None, m=M, o=obj):
        return first_order(o, theta, np.random.default_rng(1), m, runner=runner)

    grad(m=2)  # compiled kernels warm
    t_local, ref = timed(grad, args.repeats)
    connect(args.address, num_cpus=None if args.address else max(args.workers))
    out = {"scene": args.scene, "rollouts": M, "horizon": H, "local_s": t_local, "workers": {}}
    print(f"{args.scene}: first-order gradient, M = {M} rollouts x H = {H} steps, linear policy")
    print(f"  local (this process)       {t_local:8.3f} s   (reference)")
    t_one = None
    for w in args.workers:
        with RayRunner(w) as runner:
            grad(runner, m=w)  # the objective sent, the actors' steppers built
            t_w, est = timed(lambda r=runner: grad(r), args.repeats)
            overhead = runner.task_overhead()
        t_one = t_w if t_one is None and w == 1 else t_one
        diff = float(np.abs(est.grad - ref.grad).max())
        eff = None if t_one is None else t_one / (w * t_w)
        out["workers"][w] = {"seconds": t_w, "efficiency": eff, "max_grad_difference": diff,
                             "empty_task_s": overhead}  # fmt: skip
        line = f"  Ray, {w} worker(s)           {t_w:8.3f} s   x{t_local / t_w:5.2f} vs local"
        if t_one is not None:
            line += f", x{t_one / t_w:5.2f} vs 1 worker, efficiency {eff:5.2f}"
        print(line + f"  (|grad - local| <= {diff:.1e})")
    w = max(args.workers)
    with RayRunner(w) as runner:
        tiny = objective(args.scene, 1)
        grad(runner, m=w, o=tiny)
        t_tiny_ray, _ = timed(lambda: grad(runner, m=w, o=tiny), 5 * args.repeats)
        t_tiny_local, _ = timed(lambda: grad(None, m=w, o=tiny), 5 * args.repeats)
        empty = runner.task_overhead()
        per_task = max(t_tiny_ray - t_tiny_local / w, 0.0)
        print(f"  per-task overhead: empty actor call {1e3 * empty:.2f} ms; a task of one "
              f"one-step rollout {1e3 * per_task:.2f} ms beyond its compute")  # fmt: skip
        per_rollout = t_local / M
        print(
            f"  one rollout here: {1e3 * per_rollout:.2f} ms; a chunk of "
            f"{math.ceil(20 * per_task / per_rollout)} rollouts keeps the overhead under 5 %"
        )
        out["per_task_overhead_s"] = per_task
        out["empty_task_s"] = empty
        out["chunks"] = {}
        print(f"  chunk size with {w} workers (rollouts per task):")
        for chunk in sorted({4, 16, 64, math.ceil(M / w)}):
            if chunk > M:
                continue
            runner.chunk_size = chunk
            t_c, est = timed(lambda: grad(runner), args.repeats)
            tasks = math.ceil(M / chunk)
            note = "  (default: one task per worker)" if chunk == math.ceil(M / w) else ""
            print(f"    {chunk:5d} ({tasks:4d} tasks)  {t_c:8.3f} s{note}")
            out["chunks"][chunk] = t_c
    shutdown()
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
