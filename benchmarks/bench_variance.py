"""Gradient-estimate variance per second of compute: FOPG-ABS against randomised smoothing (RS)
(Zhang et al. 2023, section 5, "Discussion on BS and RS").

The task is the hopping ball of :mod:`drake_abs.tasks.hopping_ball` (2-D point mass,
h = 0.01 s, inelastic ground, action noise sigma = 1 N, the spring policy), at one horizon.
Measured in the same run, at the same theta, with the same number of rollouts per estimate:

- ``FOPG-ABS``: :func:`drake_abs.policy.estimators.first_order` through the contact-aware ABS model
  (``ContactAware(1e-2, 0.05)``, frozen gradient), M rollouts batched in one call;
- ``FOPG-exact``: the same through hard contact (the baseline both try to improve on);
- ``RS``: :func:`drake_abs.policy.estimators.randomized_smoothing` on the exact model: the mean
  first-order gradient at N parameters ``theta + w_i``, ``w_i ~ N(0, std^2 I)``, one rollout each.
  As implemented in ``estimators`` it simulates its N rollouts one by one (each has its own theta),
  so it does not get the batching FOPG gets; that is part of its cost here.

For each: the trace variance ``v`` of one estimate (K independent estimates,
:func:`drake_abs.policy.gradient_stats.measure_variance`), the mean wall time ``t`` per estimate,
and ``v * t``, the variance per second of compute (the variance of the average of the estimates one
second buys; lower is better). Printed: the table and the ratio RS / FOPG-ABS of ``v * t``. All
random numbers come from ``--seed``. Note: the estimators have different means (ABS and RS are
biased towards different smoothed objectives); variance alone says nothing about bias.

Usage::

    python benchmarks/bench_variance.py            # H = 200, M = N = 64, K = 20
    python benchmarks/bench_variance.py --quick    # smaller (a few seconds)
    python benchmarks/bench_variance.py --json results/bench_variance.json
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see drake_abs/__init__

import numpy as np  # noqa: E402

from drake_abs.contact.smoothing import ContactAware, Exact  # noqa: E402
from drake_abs.policy.estimators import first_order, randomized_smoothing  # noqa: E402
from drake_abs.policy.gradient_stats import measure_variance  # noqa: E402
from drake_abs.tasks.hopping_ball import hopping_ball, spring_theta  # noqa: E402


def bench(horizon: int, samples: int, batches: int, rs_std: float, seed: int) -> dict:
    theta = spring_theta()
    abs_obj = hopping_ball(ContactAware(1e-2, 0.05), "frozen", horizon)
    exact_obj = hopping_ball(Exact(), "frozen", horizon)
    estimators = {
        "FOPG-ABS": lambda th, rng: first_order(abs_obj, th, rng, samples),
        "FOPG-exact": lambda th, rng: first_order(exact_obj, th, rng, samples),
        "RS": lambda th, rng: randomized_smoothing(exact_obj, th, rng, samples, rs_std),
    }
    rows = {}
    for name, est in estimators.items():
        est(theta, np.random.default_rng(seed + 1))  # warm-up (imports, JIT)
        s = measure_variance(est, theta, batches=batches, seed=seed)
        rows[name] = {
            "trace_variance": s.trace_variance,
            "trace_variance_se": s.trace_variance_se,
            "seconds_per_estimate": s.seconds_per_estimate,
            "variance_seconds": s.variance_seconds,
            "mean_grad_norm": float(np.linalg.norm(s.mean_grad)),
        }
    return {
        "config": {
            "horizon": horizon,
            "samples": samples,
            "batches": batches,
            "rs_std": rs_std,
            "seed": seed,
        },  # fmt: skip
        "rows": rows,
        "ratio_variance_seconds_rs_over_abs": rows["RS"]["variance_seconds"]
        / rows["FOPG-ABS"]["variance_seconds"],
        "ratio_variance_rs_over_abs": rows["RS"]["trace_variance"]
        / rows["FOPG-ABS"]["trace_variance"],
    }


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="H = 100, M = N = 16, K = 6")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rs-std", type=float, default=1.0, help="RS parameter noise std")
    parser.add_argument("--json", default="results/bench_variance.json")
    args = parser.parse_args(argv)
    H, M, K = (100, 16, 6) if args.quick else (200, 64, 20)
    result = bench(H, M, K, args.rs_std, args.seed)
    print(f"hopping ball, H = {H}, {M} rollouts per estimate, {K} estimates each")
    print(f"{'estimator':12s} {'variance v':>12s} {'+- se':>10s} {'s/estimate':>11s} {'v*s':>11s}")
    for name, r in result["rows"].items():
        print(
            f"{name:12s} {r['trace_variance']:12.4g} {r['trace_variance_se']:10.2g} "
            f"{r['seconds_per_estimate']:11.4g} {r['variance_seconds']:11.4g}"
        )
    print(
        f"RS / FOPG-ABS: variance x{result['ratio_variance_rs_over_abs']:.3g}, "
        f"variance per second of compute x{result['ratio_variance_seconds_rs_over_abs']:.3g} "
        "(> 1: FOPG-ABS is better)"
    )
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
