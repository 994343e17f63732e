"""Convergence of the frictional contact solver on the box.

The linearised-cone LCP is not monotone (copositive, not P). This sweep measures how the
interior point fares on the planar box over friction coefficients 0 to 2, mass ratios 1e-3 to
1e3 and time steps 1e-4 to 5e-2 s, under exact contact and ABS. Two mass ratios are varied:
the box's absolute mass (kg; the LCP is scaled, so this should not matter) and the ratio of
translational to rotational mobility ``m L^2 / I_yy`` (L = 0.2 m, the half length), which sets
the conditioning of ``J W J^T``. Each case drops the box tilted and sliding onto the ground,
pushed, for a fixed number of steps, and records every step's convergence and iterations.

Failures are reported (every failing case is listed), never hidden.
"""

from __future__ import annotations

import itertools
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drake_abs.engine import open_loop
from drake_abs.engine.step_log import StepLog
from drake_abs.experiments.outputs import file_list, progress, results_dir, write_json
from drake_abs.lcp.ipm import LCPConvergenceWarning
from drake_abs.multibody import build_scene_model
from drake_abs.multibody.scene import Scene

NAME = "box-convergence"

_BOX_SDF = """<?xml version="1.0"?>
<sdf version="1.9">
  <model name="box">
    <link name="slider_x">{massless}</link>
    <link name="slider_z">{massless}</link>
    <link name="box">
      <inertial><mass>{mass}</mass>
        <inertia><ixx>{ixx}</ixx><iyy>{iyy}</iyy><izz>{izz}</izz>
          <ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia>
      </inertial>
    </link>
    <joint name="x" type="prismatic"><parent>world</parent><child>slider_x</child>
      <axis><xyz>1 0 0</xyz><limit><effort>1e9</effort></limit></axis></joint>
    <joint name="z" type="prismatic"><parent>slider_x</parent><child>slider_z</child>
      <axis><xyz>0 0 1</xyz><limit><effort>0</effort></limit></axis></joint>
    <joint name="pitch" type="revolute"><parent>slider_z</parent><child>box</child>
      <axis><xyz>0 1 0</xyz><limit><effort>0</effort></limit></axis></joint>
  </model>
</sdf>
"""
_MASSLESS = (
    "<inertial><mass>0</mass><inertia><ixx>0</ixx><iyy>0</iyy><izz>0</izz>"
    "<ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia></inertial>"
)


@dataclass(frozen=True)
class Config:
    """The grid. ``mobility_ratios`` are m L^2 / I_yy; ``masses`` in kg; ``time_steps`` in s."""

    frictions: tuple[float, ...] = (0.0, 0.1, 0.5, 1.0, 2.0)
    masses: tuple[float, ...] = (1e-3, 1.0, 1e3)
    mobility_ratios: tuple[float, ...] = (1e-3, 1e-1, 2.4, 1e1, 1e3)
    time_steps: tuple[float, ...] = (1e-4, 1e-3, 1e-2, 5e-2)
    steps: int = 40
    policies: tuple[str, ...] = ("exact", "abs")

    @classmethod
    def test_size(cls) -> Config:
        return cls(
            frictions=(0.0, 0.5, 2.0),
            masses=(1e-3, 1e3),
            mobility_ratios=(1e-3, 1e3),
            time_steps=(1e-4, 5e-2),
            steps=12,
        )


def box_scene(folder: Path, friction: float, mass: float, ratio: float, h: float, policy: str):
    """The planar box with the given parameters (its SDF written to ``folder``)."""
    iyy = mass * 0.2**2 / ratio
    sdf = _BOX_SDF.format(massless=_MASSLESS, mass=mass, ixx=iyy, iyy=iyy, izz=iyy)
    path = Path(folder) / f"box_m{mass:g}_r{ratio:g}.sdf"
    path.write_text(sdf)
    corners = [[sx * 0.2, 0.0, sz * 0.1] for sx in (-1, 1) for sz in (-1, 1)]
    smoothing = {"kind": "exact"}
    if policy == "abs":
        # mu_max = s* m g h: the same 1 mm of force at a distance at every mass and time step
        # (impulses scale with m h, so a fixed mu would smooth ever more at small h)
        smoothing = {"kind": "contact_aware", "mu_max": 1e-3 * mass * 9.81 * h, "length": 0.01}
    return Scene.from_dict(
        {
            "name": "box_sweep",
            "time_step": h,
            "models": [{"file": str(path)}],
            "contacts": [{"body": "box", "points": corners, "friction": friction or None}],
            "friction_directions": 2,
            # as in the shipped scenes: the upper edges, 0.2 m up, stay out of the LCP (with
            # them in, a smoothed far contact's friction cone nearly collapses; measured on the
            # CI grid: 526 of 576 steps converged with them, 558 without)
            "activation_distance": 0.05,
            "smoothing": smoothing,
            # dropped tilted from 2 cm, sliding at 1 m/s and spinning
            "initial_state": {"q": [0.0, 0.13, 0.15], "v": [1.0, -0.5, 1.0]},
        }
    )


def run_case(scene: Scene, steps: int, push: float) -> dict:
    """Step one scene (the engine's open loop, Jacobians on); per-step convergence and
    iterations."""
    sm = build_scene_model(scene)
    log = StepLog(sm.stepper(), ("iterations", "dx_dx"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LCPConvergenceWarning)
        traj = open_loop(log, sm.x0, np.full((steps, 1), push), on_unconverged="flag")
    if not (np.isfinite(traj.x).all() and np.isfinite(log.stacked("dx_dx")).all()):
        raise AssertionError("non-finite state or Jacobian returned")
    iterations = log.stacked("iterations")[0]
    return {
        "converged_steps": int(traj.converged.sum()),
        "steps": steps,
        "median_iterations": float(np.median(iterations)),
        "max_iterations": int(np.max(iterations)),
        "contact_steps": int(np.sum(iterations > 0)),
    }


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Run the sweep; returns the table and writes it to summary.json in ``out`` (default
    results/box-convergence); ``summary["files"]`` lists it (absolute path)."""
    config = config or Config()
    out = results_dir(NAME, out)
    rows = []
    axes = (config.policies, config.frictions, config.masses, config.mobility_ratios,
            config.time_steps)  # fmt: skip
    grid = progress(itertools.product(*axes), total=int(np.prod([len(a) for a in axes])),
                    desc=f"{NAME}: cases")  # fmt: skip
    with tempfile.TemporaryDirectory() as folder:
        for policy, friction, mass, ratio, h in grid:
            scene = box_scene(Path(folder), friction, mass, ratio, h, policy)
            result = run_case(scene, config.steps, push=2.0 * mass * 9.81 * 0.3)
            rows.append({"policy": policy, "friction": friction, "mass": mass,
                         "mobility_ratio": ratio, "time_step": h, **result})  # fmt: skip
    summary = {
        "cases": len(rows),
        "steps": sum(r["steps"] for r in rows),
        "converged_steps": sum(r["converged_steps"] for r in rows),
        "failed_cases": [r for r in rows if r["converged_steps"] < r["steps"]],
        "median_iterations": float(np.median([r["median_iterations"] for r in rows])),
        "max_iterations": int(max(r["max_iterations"] for r in rows)),
        "rows": rows,
        "folder": str(out),
        "files": file_list({"summary": out / "summary.json"}),
    }
    write_json(out / "summary.json", summary)
    return summary


def report(summary: dict) -> str:
    lines = [
        f"box convergence sweep: {summary['cases']} cases, {summary['converged_steps']} of "
        f"{summary['steps']} steps converged; iterations median {summary['median_iterations']:g}, "
        f"max {summary['max_iterations']}",
    ]
    for r in summary["failed_cases"]:
        lines.append(
            f"  NOT CONVERGED: {r['policy']} friction {r['friction']} mass {r['mass']:g} "
            f"ratio {r['mobility_ratio']:g} h {r['time_step']:g}: "
            f"{r['steps'] - r['converged_steps']} of {r['steps']} steps"
        )
    return "\n".join(lines)
