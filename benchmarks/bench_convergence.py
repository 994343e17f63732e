"""How often a contact step's LCP fails to converge, per scene and smoothing, over noisy
closed-loop rollouts of at least 10^4 steps each.

Scenes and controllers (every rollout seeded):

- **solo12_drop**: the quadruped dropped onto its feet under a joint PD controller that holds
  the initial posture (standing) or swings the hips and knees in a trot-like pattern
  (stepping), with Gaussian torque noise;
- **hopper** and **half_cheetah**: planar legged robots under a joint PD holding the initial
  posture, with torque noise;
- **box_push**: the planar box pushed with random forces from random sliding states.

Smoothing: Exact, Fixed(mu) for mu from 1e-8 to 1e-2, ContactAware (the scene's, or
mu_max 1e-3, length 0.02), GaussianMatched(sigma = 2 mm).

Each pair runs three times from the same seed:

- "before": the papers' Stewart-Trinkle friction with the solver's default start alone;
- "ST": Stewart-Trinkle with the solver's second starts (``drake_abs.lcp.ipm.SECOND_START``, the
  default);
- "Anitescu": the monotone friction formulation (``friction_model: anitescu``).

For each it prints the steps that solved an LCP, the fraction unconverged and the iterations
(median, p99), then every failure of the ST and Anitescu runs (scene, smoothing, rollout, step).
Target: at most 1 in 10^4 steps unconverged (checked on the Anitescu runs: the formulation
offered for smoothed frictional contact). A step that fails is not taken forward: that rollout
starts again from a fresh initial state.

Usage: ``python benchmarks/bench_convergence.py [--steps N] [--scenes ...] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
import warnings
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see drake_abs/__init__

import numpy as np

from drake_abs.contact.smoothing import ContactAware, Exact, Fixed, GaussianMatched
from drake_abs.contact.unconverged import UnconvergedStepWarning
from drake_abs.engine import rollout
from drake_abs.lcp import ipm
from drake_abs.lcp.ipm import LCPConvergenceWarning
from drake_abs.multibody import Scene, build_scene_model
from drake_abs.multibody.posture import (
    SOLO12_TROT,
    STANDING_GAINS,
    standing_controller,
    stepping_controller,
)
from drake_abs.multibody.stepper import StepOverflowWarning
from drake_abs.policy.controls import TimeVaryingController

SMOOTHINGS = {
    "exact": Exact(),
    **{f"fixed {mu:g}": Fixed(mu) for mu in (1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2)},
    "contact_aware": None,  # the scene's own, or the default below
    "gaussian": GaussianMatched(0.002),
}
BATCH = 16
TARGET = 1e-4


def _controller(name: str, model, rng: np.random.Generator):
    """u(t, x) (B, nu) for the scene: the shipped posture-holding feed-forward + PD
    (``drake_abs.multibody.posture``), plus for solo12 "stepping" a trot-like swing of the
    reference (diagonal legs together, 0.3 rad at 2 Hz on the hip and knee pitch), with
    Gaussian torque noise of 5 % of the PD's torque scale; box: random pushes."""
    nu = model.contact_model.nu
    if name == "box_push":
        return lambda t, x: rng.uniform(-8.0, 8.0, (len(x), nu))
    base = name.replace("_standing", "").replace("_stepping", "")
    feet, kp, kd = STANDING_GAINS[base]
    _, u_ff = standing_controller(model, feet, kp, kd)
    noise = 0.05 * np.maximum(np.abs(u_ff), np.broadcast_to(np.asarray(kp, float), (nu,)) * 0.1)
    swing, phase, frequency = np.zeros(nu), np.zeros(nu), 0.0
    if name.endswith("stepping"):  # solo12
        swing, phase, frequency = SOLO12_TROT
    drive = stepping_controller(model, feet, kp, kd, swing, phase, frequency)

    def u(t, x):
        return drive(t, x) + noise * rng.standard_normal((len(x), nu))

    return u


def _initial_states(name: str, model, rng: np.random.Generator, B: int) -> np.ndarray:
    x = np.tile(model.x0, (B, 1))
    nq = model.contact_model.nq
    if name == "box_push":  # sliding at random speeds, slightly pitched or lifted
        x[:, nq] = rng.uniform(-2.0, 2.0, B)
        x[:, 1] += rng.uniform(0.0, 0.02, B)
    else:
        x[:, nq:] += 0.1 * rng.standard_normal((B, model.contact_model.nv))
    return x


class _RestartFailed:
    """The benchmark's stepper: the scene's, with a rollout whose step failed started again
    from a fresh initial state (the failed step is not taken forward), counting as it goes."""

    parameter_names = ()

    def __init__(self, stepper, fresh, offset: int = 0):
        self.stepper, self.fresh, self.t = stepper, fresh, offset
        self.solved, self.unconverged, self.iterations, self.failures = 0, 0, [], []

    def step(self, x, u, *, jacobians=False, parameters=False):
        r = self.stepper.step(x, u, jacobians=False)
        lcp = r.iterations > 0
        self.solved += int(lcp.sum())
        bad = np.flatnonzero(~r.converged)
        self.unconverged += bad.size
        self.failures += [{"rollout": int(b), "step": self.t} for b in bad]
        self.iterations += r.iterations[lcp].tolist()
        self.t += 1
        if not bad.size:
            return r
        x_next = r.x_next.copy()
        x_next[bad] = self.fresh(bad.size)
        return replace(r, x_next=x_next)


def run_pair(
    scene_name: str, smoothing_name: str, steps: int, seed: int, friction: str = "stewart_trinkle"
) -> dict:
    base = scene_name.replace("_standing", "").replace("_stepping", "")
    scene = Scene.load(base)
    model = build_scene_model(scene)
    smoothing = SMOOTHINGS[smoothing_name]
    if smoothing is None:
        smoothing = scene.make_smoothing()
        if not isinstance(smoothing, ContactAware):
            smoothing = ContactAware(1e-3, 0.02)
    rng = np.random.default_rng(seed)
    u_of = _controller(scene_name, model, rng)
    horizon = int(np.ceil(steps / BATCH))
    log = _RestartFailed(
        model.stepper(smoothing=smoothing, friction=friction),
        lambda n: _initial_states(scene_name, model, rng, n),
    )
    nx, nu = model.x0.size, model.contact_model.nu
    start = time.perf_counter()
    for t0 in range(0, horizon, 200):  # an episode of up to 200 steps from fresh states
        x0 = _initial_states(scene_name, model, rng, BATCH)
        length = min(200, horizon - t0)
        policy = TimeVaryingController(
            lambda t, x, t0=t0: u_of((t0 + t) * scene.time_step, x), nx, nu
        )
        rollout(log, policy, np.zeros(0), x0, np.zeros((BATCH, length, nu)), sigma=0.0,
                gradient=False, on_unconverged="flag")  # fmt: skip
    solved, unconverged, iterations, failures = (
        log.solved,
        log.unconverged,
        log.iterations,
        log.failures,
    )
    it = np.array(iterations) if iterations else np.zeros(1)
    return {
        "scene": scene_name, "smoothing": smoothing_name, "steps": horizon * BATCH,
        "lcp_steps": solved, "unconverged": unconverged,
        "median_iterations": float(np.median(it)), "p99_iterations": float(np.percentile(it, 99)),
        "seconds": time.perf_counter() - start, "failures": failures,
    }  # fmt: skip


SCENES = ("solo12_drop_standing", "solo12_drop_stepping", "hopper", "half_cheetah", "box_push")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=10_000, help="steps per scene and smoothing")
    parser.add_argument("--scenes", nargs="*", default=list(SCENES))
    parser.add_argument("--smoothings", nargs="*", default=list(SMOOTHINGS))
    parser.add_argument("--runs", nargs="*", default=["before", "ST", "Anitescu"],
                        help="which of the runs: before, ST, Anitescu")  # fmt: skip
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore", LCPConvergenceWarning)  # counted below
    warnings.simplefilter("ignore", StepOverflowWarning)
    warnings.simplefilter("ignore", UnconvergedStepWarning)  # counted by the stepper
    runs = [run for run in (("before", False, "stewart_trinkle"), ("ST", True, "stewart_trinkle"),
            ("Anitescu", True, "anitescu")) if run[0] in args.runs]  # fmt: skip
    if not runs:
        parser.error("--runs must name at least one of before, ST, Anitescu")
    rows = []
    print(f"{'scene':22s} {'smoothing':14s} " + " ".join(
        f"| {name + ':':9s} {'unconv.':>8s} {'med':>4s} {'p99':>4s}" for name, _, _ in runs)
        + f"  (fraction of LCP steps; target <= {TARGET:g})")  # fmt: skip
    for i, scene in enumerate(args.scenes):
        for j, smoothing in enumerate(args.smoothings):
            res = {}
            for name, second, friction in runs:
                ipm.SECOND_START = second
                res[name] = run_pair(scene, smoothing, args.steps, 1000 * i + j, friction)
            ipm.SECOND_START = True
            rows.append({"scene": scene, "smoothing": smoothing, **{
                f"{name}_{k}": v for name, r in res.items() for k, v in r.items()
                if k not in ("scene", "smoothing")}})  # fmt: skip
            line = f"{scene:22s} {smoothing:14s} "
            for r in res.values():
                frac = r["unconverged"] / max(r["lcp_steps"], 1)
                line += (f" | {'':9s} {frac:8.1e} {r['median_iterations']:4.0f} "
                         f"{r['p99_iterations']:4.0f}")  # fmt: skip
            a = res.get("Anitescu")
            fail = a is not None and a["unconverged"] / max(a["lcp_steps"], 1) > TARGET
            print(line + ("  FAIL" if fail else ""), flush=True)
    for name in [n for n in ("ST", "Anitescu") if n in args.runs]:
        worst = max(r[f"{name}_unconverged"] / max(r[f"{name}_lcp_steps"], 1) for r in rows)
        verdict = ("PASS" if worst <= TARGET else "FAIL") if name == "Anitescu" else "(reported)"
        print(f"{name}: worst unconverged fraction {worst:.2e} {verdict}")
        for r in rows:  # every Anitescu failure; ST's first 5 per row (all in the JSON)
            shown = r[f"{name}_failures"][: None if name == "Anitescu" else 5]
            for f in shown:
                print(f"  unconverged ({name}): {r['scene']}, {r['smoothing']}, "
                      f"rollout {f['rollout']}, step {f['step']}")  # fmt: skip
            if len(shown) < len(r[f"{name}_failures"]):
                print(f"  ... and {len(r[f'{name}_failures']) - len(shown)} more ({name}, "
                      f"{r['scene']}, {r['smoothing']})")  # fmt: skip
    worst = max((r[f"{n}_unconverged"] / max(r[f"{n}_lcp_steps"], 1) for r in rows
                 for n in args.runs if n == "Anitescu"), default=None)  # fmt: skip
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"rows": rows, "target": TARGET,
                                               "worst": worst}, indent=2))  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
