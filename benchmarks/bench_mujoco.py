"""Per-step cost against MuJoCo and Drake SAP on the same models.

Same run, same machine, one thread, on gymnasium's Hopper and HalfCheetah (the scenes gym_hopper
and gym_half_cheetah, which load the MJCF files unedited), same time step (the scene's):

* ours: ``ComplementarityStepper.step`` (exact contact), single (B = 1) and batched (B = 64,
  1024; cost per environment), without and with the Jacobians dx+/dx, dx+/du;
* MuJoCo: ``mj_step`` (Euler: the Hopper file's RK4 is switched off so that the same model can be
  differentiated) and ``mjd_transitionFD`` (centred differences, eps 1e-6; it returns the
  same dx+/dx, dx+/du; the target's reference, as the accurate one), and the same with forward
  differences (half the evaluations, first-order accurate; printed beside it);
* Drake SAP on the scene's twin (``make_drake_twin``): a double step (one
  ``EvalUniquePeriodicDiscreteUpdate`` of the twin without sampled outputs, from each state)
  and one AutoDiffXd step with derivatives seeded on (x, u), where Drake can.

The states are those of a seeded open-loop rollout (the MuJoCo comparison's torques), so every
side steps through flight, landing and stance. Target: our batched step + Jacobian, per
environment, faster than MuJoCo's finite-difference Jacobian.

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

from drake_abs.experiments.mujoco_comparison import SCENES, Config, _controls, mujoco_model
from drake_abs.multibody import build_scene_model


def _best_time(fn, repeats: int) -> float:
    """The fastest of ``repeats`` runs (s); every side is timed the same way."""
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.min(times))


def rollout(sm, model, steps: int):
    """States (steps, nx) and joint torques (steps, nu) of our seeded open-loop rollout; MuJoCo's
    ctrl for the same torques."""
    ctrl = _controls(Config(), "open_loop", steps, model.nu)
    torques = ctrl * model.actuator_gear[:, 0]
    stepper = sm.stepper()
    xs = [np.asarray(sm.x0, float)]
    for u in torques[:-1]:
        xs.append(stepper.step(xs[-1][None], u[None], jacobians=False).x_next[0])
    return np.array(xs), torques, ctrl


def bench_scene(name: str, steps: int, repeats: int, batches: list[int]) -> dict:
    sm = build_scene_model(name)
    scene = sm.scene
    model, gym_dt = mujoco_model(name, scene.time_step)
    xs, torques, ctrl = rollout(sm, model, steps)
    stepper = sm.stepper()
    row = {"scene": name, "time_step": scene.time_step, "gymnasium_control_period": gym_dt}
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
    # MuJoCo
    data = mujoco.MjData(model)
    nq, nv = model.nq, model.nv

    def mj_steps():
        for x, c in zip(xs, ctrl, strict=True):
            data.qpos[:] = x[:nq]
            data.qvel[:] = x[nq:]
            data.ctrl[:] = c
            mujoco.mj_step(model, data)

    def mj_set_only():
        for x, c in zip(xs, ctrl, strict=True):
            data.qpos[:] = x[:nq]
            data.qvel[:] = x[nq:]
            data.ctrl[:] = c

    overhead = _best_time(mj_set_only, repeats)
    row["mj_step_us"] = 1e6 * (_best_time(mj_steps, repeats) - overhead) / steps
    A = np.zeros((2 * nv + model.na, 2 * nv + model.na))
    Bm = np.zeros((2 * nv + model.na, model.nu))

    def mj_fd(centred: bool):
        for x, c in zip(xs, ctrl, strict=True):
            data.qpos[:] = x[:nq]
            data.qvel[:] = x[nq:]
            data.ctrl[:] = c
            mujoco.mjd_transitionFD(model, data, 1e-6, centred, A, Bm, None, None)

    for key, centred in (("mjd_transitionFD_us", True), ("mjd_transitionFD_forward_us", False)):
        row[key] = 1e6 * (_best_time(lambda c=centred: mj_fd(c), repeats) - overhead) / steps
    row.update(bench_sap(sm, xs, torques, repeats))
    return row


def bench_sap(sm, xs, torques, repeats: int) -> dict:
    from pydrake.autodiffutils import InitializeAutoDiff

    from drake_abs.reference.drake_twin import make_drake_twin

    scene = sm.scene
    steps, nx, nu = len(xs), xs.shape[1], torques.shape[1]
    # one discrete update per rollout state, from that state (like the other sides); without
    # sampled outputs the plant's update is a unique periodic event that can be evaluated alone
    twin = make_drake_twin(scene, "sap", sampled_outputs=False)
    ctx = twin.diagram.CreateDefaultContext()
    pc = twin.plant.GetMyMutableContextFromRoot(ctx)
    port = twin.diagram.get_input_port(0)

    def sap_steps():
        for x, u in zip(xs, torques, strict=True):
            twin.plant.SetPositionsAndVelocities(pc, x)
            port.FixValue(ctx, u)
            twin.diagram.EvalUniquePeriodicDiscreteUpdate(ctx)

    out = {"sap_double_us": 1e6 * _best_time(sap_steps, repeats) / steps}
    try:
        twin = make_drake_twin(scene, "sap", sampled_outputs=False)
        ad = twin.diagram.ToAutoDiffXd()
        plant_ad = ad.GetSubsystemByName(twin.plant.get_name())
        actx = ad.CreateDefaultContext()
        apc = plant_ad.GetMyMutableContextFromRoot(actx)
        aport = ad.get_input_port(0)

        def ad_steps():
            for x, u in zip(xs, torques, strict=True):
                plant_ad.SetPositionsAndVelocities(
                    apc, InitializeAutoDiff(x.reshape(-1, 1), nx + nu, 0).ravel()
                )
                aport.FixValue(actx, InitializeAutoDiff(u.reshape(-1, 1), nx + nu, nx).ravel())
                ad.EvalUniquePeriodicDiscreteUpdate(actx)

        out["sap_autodiff_us"] = 1e6 * _best_time(ad_steps, max(1, repeats // 2)) / steps
    except Exception as err:  # noqa: BLE001 (Drake's refusal is reported, not hidden)
        out["sap_autodiff_us"] = None
        out["sap_autodiff_error"] = str(err).splitlines()[0][:160]
    return out


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
        print(f"  {'':28s} {'us/step':>9s} {'/mj_step':>9s} {'/FD jac':>8s}")
        lines = [
            ("MuJoCo mj_step", r["mj_step_us"]),
            ("MuJoCo mjd_transitionFD", fd),
            ("MuJoCo FD, forward (1st order)", r["mjd_transitionFD_forward_us"]),
        ]
        for B in args.batches:
            lines.append((f"ours B={B} step", r[f"ours_B{B}_us"]))
            lines.append((f"ours B={B} step+Jacobian", r[f"ours_B{B}_jac_us"]))
        lines.append(("Drake SAP double step", r["sap_double_us"]))
        if r["sap_autodiff_us"] is not None:
            lines.append(("Drake SAP AutoDiffXd step", r["sap_autodiff_us"]))
        for label, us in lines:
            print(f"  {label:28s} {us:9.1f} {us / r['mj_step_us']:9.2f} {us / fd:8.2f}")
        if r["sap_autodiff_us"] is None:
            print(f"  Drake SAP AutoDiffXd: not possible ({r['sap_autodiff_error']})")
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
