"""Per-step cost of the complementarity plant against Drake's own contact models.

Measured in the same run, on each shipped scene (drake_abs/scenes/*.yaml):

1. a double step: ours (``ComplementarityStepper.step(jacobians=False)``, exact contact, at
   each state of its own rollout) against the scene's Drake twin (same models, a collision
   sphere per contact point; :class:`DrakePlantStepper`) with SAP, Similar and Lagged, over its
   own rollout in the engine (``open_loop``); target: ours within 3 times SAP;
2. a step with its Jacobian: ours (``jacobians=True``: dx+/dx and dx+/du) against the SAP
   stepper's step with its AutoDiffXd Jacobians, at the same states; target: ours faster;
3. per-step cost against the number of active contacts (a box edge with n candidate points,
   k of them within the activation distance): cost should follow k, not n.

Usage: ``python benchmarks/bench_scenes.py [--quick] [--json results/bench_scenes.json]``.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see drake_abs/__init__

import numpy as np

from drake_abs import Exact
from drake_abs.engine import open_loop
from drake_abs.multibody.builder import build_scene_model
from drake_abs.multibody.scene import Scene, shipped_scenes
from drake_abs.reference.drake_plant import DrakePlantStepper


def _best_time(fn, repeats: int) -> float:
    """The fastest of ``repeats`` runs (s). The least-disturbed run estimates a step's own cost
    on a shared machine; both sides of every ratio are timed the same way."""
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.min(times))


def bench_scene(scene: Scene, steps: int, repeats: int) -> dict:
    sm = build_scene_model(scene)
    stepper = sm.stepper(smoothing=Exact())
    nu = stepper.sizes[2]
    u, U = np.zeros((1, nu)), np.zeros((steps, nu))
    # the states ours is timed at: its rollout from the scene's initial state, zero actuation
    xs = open_loop(stepper, sm.x0, U, jacobians=False, on_unconverged="flag").x[0]
    ours = _best_time(lambda: [stepper.step(x[None], u, jacobians=False) for x in xs], repeats)
    ours_jac = _best_time(lambda: [stepper.step(x[None], u, jacobians=True) for x in xs], repeats)
    per = len(xs)
    row = {
        "scene": scene.name,
        "contacts": scene.num_contacts,
        "ours_us": 1e6 * ours / per,
        "ours_jacobian_us": 1e6 * ours_jac / per,
    }
    drake = {name: DrakePlantStepper(scene, name) for name in ("sap", "similar", "lagged")}
    for name, plant in drake.items():
        t = _best_time(lambda plant=plant: open_loop(plant, xs[0], U, jacobians=False), repeats)
        row[f"{name}_us"] = 1e6 * t / steps
    row["ratio_ours_over_sap"] = row["ours_us"] / row["sap_us"]
    # the SAP stepper's step with its AutoDiffXd Jacobians (on x and u) at each of our states
    zeros = np.zeros((per, nu))
    try:
        t = _best_time(lambda: drake["sap"].step(xs, zeros), repeats)
        row["drake_autodiff_us"] = 1e6 * t / per
        row["ratio_ours_jacobian_over_drake_autodiff"] = (
            row["ours_jacobian_us"] / row["drake_autodiff_us"]
        )
    except NotImplementedError as err:  # e.g. capsules: no AutoDiffXd penetration query
        row["drake_autodiff_us"] = row["ratio_ours_jacobian_over_drake_autodiff"] = None
        row["drake_autodiff_unavailable"] = str(err).split(". ")[0]
    return row


def edge_scene(folder: Path, candidates: int, active: int) -> tuple[Scene, np.ndarray]:
    """The planar box with ``candidates`` points along its bottom edge, tilted so that exactly
    ``active`` of them are within the activation distance."""
    xs_edge = np.linspace(-0.2, 0.2, candidates)
    points = [[float(x), 0.0, -0.1] for x in xs_edge]
    # tilt about the left corner: point i's height is x_i-offset * sin(theta)
    theta = 0.3
    heights = (xs_edge + 0.2) * np.sin(theta)
    activation = 0.5 * (heights[active - 1] + heights[active]) if active < candidates else 1.0
    q0 = [0.0, 0.1 * np.cos(theta) + 0.2 * np.sin(theta) + 1e-4, -theta]
    scene = Scene.from_dict(
        {
            "name": f"edge_{candidates}_{active}",
            "models": [{"file": "drake_abs:models/box_planar.sdf"}],
            "contacts": [{"body": "box", "points": points, "friction": 0.5}],
            "friction_directions": 2,
            "activation_distance": float(activation),
            "initial_state": {"q": q0, "v": [0.0, 0.0, 0.0]},
        }
    )
    return scene, np.concatenate([q0, [0.0, 0.0, 0.0]])


def bench_active_contacts(repeats: int, quick: bool) -> list[dict]:
    rows = []
    grid = [(32, k) for k in (1, 2, 4, 8, 16, 32)] + [(n, 2) for n in (4, 16, 64)]
    if quick:
        grid = [(16, 1), (16, 4), (16, 16), (4, 2), (64, 2)]
    with tempfile.TemporaryDirectory() as folder:
        for n, k in grid:
            scene, x = edge_scene(Path(folder), n, k)
            sm = build_scene_model(scene)
            st = sm.stepper(smoothing=Exact())
            u = np.zeros((1, 1))
            r = st.step(x[None], u)
            assert int(r.active.sum()) == k, (n, k, int(r.active.sum()))
            t = _best_time(lambda st=st, x=x, u=u: st.step(x[None], u), repeats)
            rows.append({"candidates": n, "active": k, "step_with_jacobian_us": 1e6 * t})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--json", default="results/bench_scenes.json")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    steps, repeats = (20, 3) if args.quick else (100, 5)
    rows = [bench_scene(Scene.load(name), steps, repeats) for name in shipped_scenes()]
    print("[1,2] per step (us), same run; ours: exact contact, double / with dx+/dx, dx+/du")
    header = (
        f"{'scene':14s} {'contacts':>8s} {'ours':>9s} {'SAP':>8s} {'Similar':>8s} "
        f"{'Lagged':>8s} {'ours/SAP':>9s} {'ours+J':>9s} {'DrakeAD':>9s} {'ours+J/AD':>10s}"
    )
    print(header)
    for r in rows:
        ad, ratio = r["drake_autodiff_us"], r["ratio_ours_jacobian_over_drake_autodiff"]
        print(
            f"{r['scene']:14s} {r['contacts']:8d} {r['ours_us']:9.1f} {r['sap_us']:8.1f} "
            f"{r['similar_us']:8.1f} {r['lagged_us']:8.1f} {r['ratio_ours_over_sap']:9.2f} "
            f"{r['ours_jacobian_us']:9.1f} "
            + (f"{ad:9.1f} {ratio:10.2f}" if ad is not None else f"{'n/a':>9s} {'n/a':>10s}")
        )
    for r in rows:
        if r["drake_autodiff_us"] is None:
            print(f"  {r['scene']}: no Drake AutoDiffXd step ({r['drake_autodiff_unavailable']})")
    worst = max(r["ratio_ours_over_sap"] for r in rows)
    print(f"TARGET ours within 3x SAP per double step: worst {worst:.2f}x -> "
          f"{'PASS' if worst <= 3 else 'FAIL'}")  # fmt: skip
    worst_j = max(
        r["ratio_ours_jacobian_over_drake_autodiff"]
        for r in rows
        if r["ratio_ours_jacobian_over_drake_autodiff"] is not None
    )
    print(f"TARGET our Jacobian step faster than Drake's AutoDiffXd step: worst {worst_j:.2f}x -> "
          f"{'PASS' if worst_j < 1 else 'FAIL'}")  # fmt: skip
    active = bench_active_contacts(repeats, args.quick)
    print("\n[3] per step with Jacobian (us) against active contacts k of n candidates")
    for r in active:
        print(
            f"  n = {r['candidates']:3d}  k = {r['active']:3d}  {r['step_with_jacobian_us']:9.1f}"
        )
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"scenes": rows, "active_contacts": active}, indent=2))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
