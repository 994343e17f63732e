"""What the Drake system costs on top of the step it calls: one simulated step of a scene's
ComplementarityPlant in Drake's Simulator (double, and AutoDiffXd with the state seeded), against
the same core step called directly on one state (the reference, measured in the same run; the
engine's open loop, with its reverse pass when it has the Jacobians), and beside Drake's own
discrete MultibodyPlant with SAP on the same scene (:class:`DrakePlantStepper`, its double step
in the same open loop).

Usage: ``python benchmarks/bench_drake_systems.py [--steps N] [--scenes box_push hopper]``.
Prints microseconds per step (best of 3) and the ratio to the direct core step.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.systems.analysis import Simulator, Simulator_

from drake_abs.engine import open_loop
from drake_abs.multibody import build_scene_model
from drake_abs.reference.drake_plant import DrakePlantStepper
from drake_abs.systems import ComplementarityPlant


def _best(fn, repeats: int = 3) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def bench_scene(name: str, steps: int) -> dict[str, float]:
    model = build_scene_model(name)
    stepper = model.stepper()
    nu = stepper.sizes[2]
    h = stepper.model.h
    u, U = np.zeros(nu), np.zeros((steps, nu))

    def core(jacobians: bool):
        open_loop(stepper, model.x0, U, jacobians=jacobians, on_unconverged="flag")

    plant = ComplementarityPlant(stepper, initial_state=model.x0)

    def system():
        context = plant.CreateDefaultContext()
        plant.actuation_port.FixValue(context, u)
        Simulator(plant, context).AdvanceTo(steps * h)

    ad = plant.ToAutoDiffXd()

    def system_ad():
        context = ad.CreateDefaultContext()
        context.SetDiscreteState(InitializeAutoDiff(model.x0.reshape(-1, 1)).ravel())
        ad.actuation_port.FixValue(
            context, InitializeAutoDiff(u.reshape(-1, 1), np.zeros((nu, model.x0.size))).ravel()
        )
        Simulator_[AutoDiffXd](ad, context).AdvanceTo(steps * h)

    sap_stepper = DrakePlantStepper(model.scene, "sap")

    def sap():
        open_loop(sap_stepper, model.x0, U, jacobians=False)

    rows = {
        "core step, one state, no Jacobian (reference)": _best(lambda: core(False)),
        "ComplementarityPlant in Simulator, double": _best(system),
        "core step, one state, with Jacobian": _best(lambda: core(True)),
        "ComplementarityPlant in Simulator_[AutoDiffXd]": _best(system_ad),
        "Drake MultibodyPlant SAP, double": _best(sap),
    }
    return {k: 1e6 * v / steps for k, v in rows.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--scenes", nargs="+", default=["box_push", "hopper"])
    args = parser.parse_args()
    if args.steps < 1:
        parser.error("--steps must be a positive integer")
    for name in args.scenes:
        rows = bench_scene(name, args.steps)
        ref = next(iter(rows.values()))
        print(f"\n{name}: {args.steps} steps, microseconds per step (best of 3)")
        print(f"{'':50s} {'us/step':>10s} {'/ref':>7s}")
        for label, us in rows.items():
            print(f"{label:50s} {us:10.1f} {us / ref:7.2f}")


if __name__ == "__main__":
    main()
