"""Per-step cost against MuJoCo and Drake SAP on the same models.

Same run, same machine, one thread, on gymnasium's Hopper and HalfCheetah (the scenes gym_hopper
and gym_half_cheetah, which load the MJCF files unedited), same time step (the scene's), every
side timed from the same states:

* ours: ``ComplementarityStepper.step`` (exact contact), single (B = 1, one call per state) and
  batched (B = 64, 1024; cost per environment), without and with the Jacobians dx+/dx, dx+/du;
* MuJoCo itself (Euler: the Hopper file's RK4 is switched off so that the same model can be
  differentiated; springs off): ``mj_step`` from every state in one ``mujoco.rollout`` call, and
  ``mjd_transitionFD`` (centred differences, eps 1e-6; the target's reference, as the accurate
  one) state by state, and the same with forward differences (half the evaluations,
  first-order accurate; printed beside it);
* MuJoCo as the engine runs it: ``MujocoStepper.step`` without and with its Jacobians (the same
  ``mjd_transitionFD``), which adds its Python (state, constraint impulses) to MuJoCo's cost;
* Drake SAP: ``DrakePlantStepper(scene, "sap")`` on the scene's twin: its double step (one
  discrete update from each state) and its step with AutoDiffXd Jacobians, where Drake can.

The states are those of a seeded open-loop rollout of ours (``engine.open_loop``; the MuJoCo
comparison's ctrl, ``held_random_inputs``, times the gears), so every side steps through flight,
landing and stance. Target: our batched step + Jacobian, per environment, faster than MuJoCo's
finite-difference Jacobian (``mjd_transitionFD``, centred).

Usage: ``python benchmarks/bench_mujoco.py [--quick] [--batches 1 64 1024] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see drake_abs/__init__

import mujoco
import numpy as np
from mujoco import rollout

from drake_abs.engine import open_loop
from drake_abs.multibody import build_scene_model
from drake_abs.policy.controls import held_random_inputs
from drake_abs.reference.drake_plant import DrakePlantStepper
from drake_abs.reference.mujoco_plant import MujocoStepper

#: scene -> the gymnasium environment whose model it loads
SCENES = {"gym_hopper": "Hopper-v5", "gym_half_cheetah": "HalfCheetah-v5"}


def _best_time(fn, repeats: int) -> float:
    """The fastest of ``repeats`` runs (s); every side is timed the same way."""
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.min(times))


def _bench_mujoco_itself(model, xs: np.ndarray, ctrl: np.ndarray, repeats: int) -> dict:
    """MuJoCo's own cost per state, without the stepper's Python: ``mj_step`` from every state
    in one ``mujoco.rollout`` call (C++), and ``mjd_transitionFD`` (centred and forward) timed
    state by state, less the cost of setting the states."""
    data, spec = mujoco.MjData(model), mujoco.mjtState.mjSTATE_FULLPHYSICS
    states = np.empty((len(xs), mujoco.mj_stateSize(model, spec)))

    def set_state(k):
        data.qpos[:], data.qvel[:], data.ctrl[:] = xs[k, : model.nq], xs[k, model.nq :], ctrl[k]

    for k in range(len(xs)):
        set_state(k)
        mujoco.mj_getState(model, data, states[k], spec)
    out = {"mj_step_us": _best_time(
        lambda: rollout.rollout(model, data, states, ctrl[:, None], nstep=1), repeats)}  # fmt: skip
    nx = 2 * model.nv + model.na
    A, B = np.empty((nx, nx)), np.empty((nx, model.nu))

    def fd(centred: bool | None):  # None: only set the states (the overhead)
        for k in range(len(xs)):
            set_state(k)
            if centred is not None:
                mujoco.mjd_transitionFD(model, data, 1e-6, centred, A, B, None, None)

    overhead = _best_time(lambda: fd(None), repeats)
    for key, centred in (("mjd_transitionFD_us", True), ("mjd_transitionFD_forward_us", False)):
        out[key] = _best_time(lambda c=centred: fd(c), repeats) - overhead
    return {key: 1e6 * t / len(xs) for key, t in out.items()}


def bench_scene(name: str, steps: int, repeats: int, batches: list[int]) -> dict:
    sm = build_scene_model(name)
    scene = sm.scene
    gym = MujocoStepper.from_gymnasium(SCENES[name])  # frame skip and time step of the env
    options = {"timestep": scene.time_step, "integrator": "Euler", "springs": False}
    mj = MujocoStepper(gym.model, options=options)  # Jacobians by centred differences
    sap = DrakePlantStepper(scene, "sap")
    ctrl = held_random_inputs(steps, gym.nu)
    torques = ctrl * gym.model.actuator_gear[:, 0]
    stepper = sm.stepper()
    xs = open_loop(stepper, sm.x0, torques[:-1], jacobians=False, on_unconverged="flag").x[0]
    row = {"scene": name, "time_step": scene.time_step, "gymnasium_control_period": gym.time_step}
    for B in batches:
        idx = np.arange(B) % steps
        X, U = xs[idx], torques[idx]
        for jac in (False, True):
            key = f"ours_B{B}{'_jac' if jac else ''}_us"
            if B == 1:
                t = _best_time(
                    lambda jac=jac: [
                        stepper.step(x[None], u[None], jacobians=jac)
                        for x, u in zip(xs, torques, strict=True)
                    ],
                    repeats,
                )
                row[key] = 1e6 * t / steps
            else:
                stepper.step(X, U, jacobians=jac)  # warm-up (allocation, numba)
                t = _best_time(lambda X=X, U=U, jac=jac: stepper.step(X, U, jacobians=jac), repeats)
                row[key] = 1e6 * t / B
    row.update(_bench_mujoco_itself(mj.model, xs, ctrl, repeats))
    timed = {  # key -> (stepper, inputs, jacobians); one call steps from every state
        "mujoco_stepper_us": (mj, ctrl, False),
        "mujoco_stepper_jac_us": (mj, ctrl, True),
        "sap_step_us": (sap, torques, False),
        "sap_step_jac_us": (sap, torques, True),
    }
    for key, (side, u, jac) in timed.items():
        try:
            side.step(xs[:1], u[:1], jacobians=jac)  # warm-up (Drake's AutoDiffXd diagram)
        except NotImplementedError as err:  # Drake's refusal is reported, not hidden
            row[key], row["sap_jac_error"] = None, str(err).splitlines()[0][:160]
            continue
        t = _best_time(lambda s=side, u=u, j=jac: s.step(xs, u, jacobians=j), repeats)
        row[key] = 1e6 * t / steps
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 64, 1024])
    parser.add_argument("--json", default="results/bench_mujoco.json")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    logging.getLogger("drake").setLevel(logging.ERROR)
    steps, repeats = (20, 3) if args.quick else (100, 5)
    rows = [bench_scene(name, steps, repeats, args.batches) for name in SCENES]
    print(f"per step (us), one thread, same run; MuJoCo {mujoco.__version__} (Euler), "
          f"{steps} states of a seeded open-loop rollout, best of {repeats}")  # fmt: skip
    verdicts = []
    for r in rows:
        gym = r["gymnasium_control_period"]
        print(f"\n{r['scene']} (dt {r['time_step']} s; gymnasium steps {gym} s)")
        fd = r["mjd_transitionFD_us"]
        print(f"  {'':32s} {'us/step':>9s} {'/mj_step':>9s} {'/FD jac':>8s}")
        lines = [
            ("MuJoCo mj_step", r["mj_step_us"]),
            ("MuJoCo mjd_transitionFD", fd),
            ("MuJoCo FD, forward (1st order)", r["mjd_transitionFD_forward_us"]),
            ("MujocoStepper step", r["mujoco_stepper_us"]),
            ("MujocoStepper step+Jacobian", r["mujoco_stepper_jac_us"]),
        ]
        for B in args.batches:
            lines.append((f"ours B={B} step", r[f"ours_B{B}_us"]))
            lines.append((f"ours B={B} step+Jacobian", r[f"ours_B{B}_jac_us"]))
        lines.append(("Drake SAP step", r["sap_step_us"]))
        lines.append(("Drake SAP step+AutoDiff Jacobian", r["sap_step_jac_us"]))
        for label, us in lines:
            if us is None:
                print(f"  {label:32s} not possible ({r['sap_jac_error']})")
            else:
                print(f"  {label:32s} {us:9.1f} {us / r['mj_step_us']:9.2f} {us / fd:8.2f}")
        best = min(r[f"ours_B{B}_jac_us"] for B in args.batches)
        verdicts.append(best < fd)
        print(f"  TARGET batched step+Jacobian per env faster than mjd_transitionFD: "
              f"{best:.1f} vs {fd:.1f} us -> {'PASS' if best < fd else 'FAIL'}")  # fmt: skip
    print(f"\nTARGET overall: {'PASS' if all(verdicts) else 'FAIL'}")
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"mujoco": mujoco.__version__, "scenes": rows}, indent=2))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
