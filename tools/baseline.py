#!/usr/bin/env python3
"""Record, or compare against, the numbers the project produces: every experiment's test-size
``summary.json`` and the benchmarks' JSON outputs.

    python tools/baseline.py record [--dir benchmarks/baselines]
    python tools/baseline.py compare [--dir benchmarks/baselines] [--rtol 1e-12]

``record`` runs each experiment at test size (through the ``drake-abs`` CLI, as a user would) and
each benchmark at its quick size, and stores their JSON outputs. ``compare`` runs them again and
lists every numeric entry that differs by more than ``rtol`` (relative to the larger magnitude,
absolute below 1e-300). Entries that measure time, and strings (paths), are skipped: a move of the
code must leave the numbers unchanged, not the clock.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
EXPERIMENTS = (
    "bouncing-ball",
    "box-convergence",
    "drake-comparison",
    "mpc-quadcopter",
    "gradient-variance",
    "bias-return",
    "ball-throw",
    "smoothing-vs-rs",
    "speed-accuracy",
    "locomotion-variance",
    "locomotion",
    "mujoco-comparison",
    "locomotion-transfer",
    "implicit-learning",
    "model-learning",
    "model-based-fopg",
    "scene-recordings",
)
# benchmark script -> its arguments (quick sizes); each writes the JSON file named by --json
BENCHMARKS = {
    "bench_lcp": ["--quick"],
    "bench_scenes": ["--quick"],
    "bench_variance": ["--quick"],
    "bench_mpc": ["--steps", "40"],
    "bench_policy_gradient": ["--drake-rollouts", "2"],
}
TIMING = re.compile(
    r"(^|_)(s|ms|us|seconds|time|times|wall|per_s|per_second|speed|ratio|rate)"
    r"($|_)|seconds|time|wall|_us$|_ms$|per_sec|speedup|ratio|throughput|_over_",
    re.I,
)


def _is_timing(key: str) -> bool:
    """Entries that measure the clock (skipped by the comparison); a time *step* is a setting."""
    k = key.lower().replace("time_step", "h")
    folders = k.split("/")[:-1]  # e.g. /seconds/<row> or /profile_seconds/<part>: all clock
    return bool(
        TIMING.search(key.rsplit("/", 1)[-1].replace("time_step", "h"))
        or "time" in k
        or any(f in ("seconds", "profile_seconds") for f in folders)
        or k.endswith("batching_gain")
    )


def _bin(name: str) -> str:
    return str(Path(sys.executable).parent / name)


def run_all(work: Path, only: set[str] | None = None) -> dict[str, object]:
    """Run every experiment and benchmark (or those named in ``only``) into ``work``; returns
    name -> parsed JSON."""
    out: dict[str, object] = {}
    for name in EXPERIMENTS:
        if only is not None and name not in only:
            continue
        folder = work / name
        cmd = [_bin("drake-abs"), "experiment", name, "--test-size", "--out", str(folder)]
        print("running", " ".join(cmd[1:]), flush=True)
        subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
        out[f"experiment/{name}"] = {  # summary.json, or whatever JSON the experiment wrote
            f.name: json.loads(f.read_text()) for f in sorted(folder.glob("*.json"))
        }
    for name, args in BENCHMARKS.items():
        if only is not None and name not in only:
            continue
        path = work / f"{name}.json"
        cmd = [sys.executable, str(ROOT / "benchmarks" / f"{name}.py"), *args, "--json", str(path)]
        print("running", name, *args, flush=True)
        subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
        out[f"benchmark/{name}"] = json.loads(path.read_text()) if path.is_file() else None
    return out


def _leaves(obj, prefix=""):
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _leaves(v, f"{prefix}/{k}")
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _leaves(v, f"{prefix}[{i}]")
    elif isinstance(obj, bool) or obj is None:
        yield prefix, obj
    elif isinstance(obj, (int, float)):
        yield prefix, float(obj)


def differences(old, new, rtol: float) -> list[str]:
    a, b = dict(_leaves(old)), dict(_leaves(new))
    bad = []
    for key in sorted(set(a) | set(b)):
        if _is_timing(key):
            continue
        if key not in a:  # a new output: reported by `added`, not a changed number
            continue
        x, y = a.get(key, "missing"), b.get(key, "missing")
        if isinstance(x, float) and isinstance(y, float):
            same = (math.isnan(x) and math.isnan(y)) or x == y
            scale = max(abs(x), abs(y))
            if not same and not (scale < 1e-300 or abs(x - y) <= rtol * scale):
                bad.append(f"{key}: {x!r} -> {y!r} (rel {abs(x - y) / scale:.2e})")
        elif x != y:
            bad.append(f"{key}: {x!r} -> {y!r}")
    return bad


def timing_ratios(old, new) -> list[float]:
    """new / old for every positive timing entry both have (what ``differences`` skips)."""
    a, b = dict(_leaves(old)), dict(_leaves(new))
    out = []
    for key in set(a) & set(b):
        name = key.rsplit("/", 1)[-1]
        if (
            not (TIMING.search(name) or "time" in key.lower())
            or "ratio" in name
            or "_over_" in name
        ):
            continue
        x, y = a[key], b[key]
        if isinstance(x, float) and isinstance(y, float) and x > 0 and y > 0:
            out.append(y / x)
    return sorted(out)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("mode", choices=("record", "compare"))
    parser.add_argument("--dir", type=Path, default=ROOT / "benchmarks" / "baselines")
    parser.add_argument("--rtol", type=float, default=1e-12)
    parser.add_argument(
        "--only", nargs="+", metavar="NAME", help="these experiments and benchmarks only"
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        results = run_all(Path(tmp), set(args.only) if args.only else None)
    if args.mode == "record":
        if args.dir.exists() and not args.only:
            shutil.rmtree(args.dir)
        for key, value in results.items():
            path = args.dir / f"{key}.json"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(value, indent=1, sort_keys=True) + "\n")
        print(f"recorded {len(results)} outputs in {args.dir}")
        return 0
    failures = 0
    for key, value in results.items():
        path = args.dir / f"{key}.json"
        old = json.loads(path.read_text()) if path.is_file() else "missing"
        if isinstance(old, dict) and isinstance(value, dict) and len(old) == len(value) == 1:
            old = {next(iter(value)): next(iter(old.values()))}  # one JSON file, renamed
        bad = differences(old, value, args.rtol)
        ratios = timing_ratios(old, value) if isinstance(old, dict) else []
        clock = (
            f"; {len(ratios)} timings, new/old median {ratios[len(ratios) // 2]:.2f}"
            f" (range {ratios[0]:.2f} to {ratios[-1]:.2f})"
            if ratios
            else ""
        )
        added = sorted(set(dict(_leaves(value))) - set(dict(_leaves(old)))) if ratios else []
        extra = f"; {len(added)} new entries (e.g. {added[0]})" if added else ""
        print(f"{key}: {'same' if not bad else f'{len(bad)} differences'}{clock}{extra}")
        for line in bad[:20]:
            print("   ", line)
        failures += bool(bad)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
