"""Meshcat recordings of the robot and manipulation scenes under their controllers: one
self-contained HTML page per recording, and what each rollout did.

Recordings (each stepped by the scene's own stepper, exact contact unless the scene says
otherwise; every step's ``converged`` flag counted):

- ``gym_hopper``, ``gym_half_cheetah``: gymnasium's models as published, dropped and driven by
  the seeded open-loop torque sequence of the MuJoCo comparison (held 5 steps each,
  ctrl uniform in +-0.5 of the gear);
- ``solo12_standing``: Solo12 dropped onto its feet under the posture-holding feed-forward +
  PD (:func:`drake_abs.multibody.posture.standing_controller`);
- ``solo12_stepping``: the same with its reference swung in a trot-like pattern
  (:data:`~drake_abs.multibody.posture.SOLO12_TROT`);
- ``go1_standing``: the Unitree Go1 (example-robot-data) dropped onto its feet, standing;
- ``pusher_box``: the sphere pusher driven at 0.1 m/s along +x (a velocity servo) into the
  free box, 5 cm off its centre (``push_offset``): the box slides and turns away from the
  push (body-body contact).

The summary per recording: steps, unconverged steps, the deepest penetration of any contact
candidate over the run (m, from the recorded states), the floating base's height at the start
and end (robots) or the box's displacement and yaw (pusher), and the HTML's size.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drake_abs.diagrams.scene_visualization import record_rollout_html
from drake_abs.experiments._common import file_list, progress, results_dir
from drake_abs.experiments.mujoco_comparison import Config as MujocoConfig
from drake_abs.experiments.mujoco_comparison import _controls
from drake_abs.multibody import build_scene_model
from drake_abs.multibody.posture import (
    SOLO12_TROT,
    STANDING_GAINS,
    stepping_controller,
)

NAME = "scene-recordings"

#: recording name -> scene
RECORDINGS: dict[str, str] = {
    "gym_hopper": "gym_hopper",
    "gym_half_cheetah": "gym_half_cheetah",
    "solo12_standing": "solo12_drop",
    "solo12_stepping": "solo12_drop",
    "go1_standing": "go1_drop",
    "pusher_box": "pusher_box",
}
PUSH_SPEED, PUSH_GAIN, PUSH_OFFSET = 0.1, 250.0, 0.05  # m/s, N s/m, m (pusher's y)


@dataclass(frozen=True)
class Config:
    """``duration`` (s) of every recording; ``recordings``: which (names of RECORDINGS)."""

    duration: float = 2.0
    recordings: tuple[str, ...] = tuple(RECORDINGS)
    push_offset: float = PUSH_OFFSET  # m: the pusher's y against the box's centre line

    @classmethod
    def test_size(cls) -> Config:
        return cls(duration=0.3)


def _inputs(name: str, sm, push_offset: float = PUSH_OFFSET):
    """``(x0, u(k, x))`` of a recording: the initial state and the input at step k."""
    nu = sm.contact_model.nu
    h = sm.scene.time_step
    x0 = np.asarray(sm.x0, float).copy()
    if name.startswith("gym_"):
        steps = 10_000
        gear = _gear(sm)
        torques = _controls(MujocoConfig(), "open_loop", steps, nu) * gear
        return x0, lambda k, x: torques[k]
    if name == "pusher_box":
        x0[1] = push_offset  # the pusher's y against the box's centre line (y = 0)

        def push(k, x):
            nq = sm.contact_model.nq
            return PUSH_GAIN * (np.array([PUSH_SPEED, 0.0]) - x[nq : nq + 2])

        return x0, push
    feet, kp, kd = STANDING_GAINS[sm.scene.name]
    swing, phase, frequency = SOLO12_TROT if name == "solo12_stepping" else (0.0, 0.0, 0.0)
    drive = stepping_controller(sm, feet, kp, kd, swing, phase, frequency)
    return x0, lambda k, x: drive(k * h, x)


def _gear(sm) -> np.ndarray:
    """The actuators' effort limits (N m): gymnasium's ctrl in [-1, 1] times the gear."""
    plant = sm.plant
    return np.array(
        [plant.get_joint_actuator(a).effort_limit() for a in plant.GetJointActuatorIndices()]
    )


def rollout(
    name: str, duration: float, push_offset: float = PUSH_OFFSET
) -> tuple[object, np.ndarray, int]:
    """The recording's scene model, its states (T + 1, nx) and the number of unconverged
    steps."""
    sm = build_scene_model(RECORDINGS[name])
    stepper = sm.stepper()
    x, u_of = _inputs(name, sm, push_offset)
    steps = int(round(duration / sm.scene.time_step))
    xs, unconverged = [x], 0
    for k in range(steps):
        r = stepper.step(xs[-1][None], np.asarray(u_of(k, xs[-1]), float)[None], jacobians=False)
        unconverged += int((~r.converged).sum())
        xs.append(r.x_next[0])
    return sm, np.array(xs), unconverged


def _facts(name: str, sm, xs: np.ndarray) -> dict:
    """What the rollout did, from its states."""
    model = sm.contact_model
    nq = model.nq
    depth = float(max(0.0, -model.distances(xs[:, :nq]).min()))
    out = {"deepest_penetration_m": depth}
    if name == "pusher_box":  # box x, y, z, yaw after the pusher's x, y
        out.update(
            box_displacement_m=[float(d) for d in xs[-1, 2:4] - xs[0, 2:4]],
            box_yaw_rad=float(xs[-1, 5] - xs[0, 5]),
        )
    else:
        z = _base_height(sm, xs)
        out.update(base_height_start_m=float(z[0]), base_height_end_m=float(z[-1]))
    return out


def _base_height(sm, xs: np.ndarray) -> np.ndarray:
    """The height (m) of the model's first body with mass (its base) over the rollout."""
    plant = sm.plant
    context = plant.CreateDefaultContext()
    body = plant.get_body(sm.contact_model._massive[0][1])
    nq = plant.num_positions()
    heights = []
    for x in xs:
        plant.SetPositions(context, x[:nq])
        heights.append(plant.EvalBodyPoseInWorld(context, body).translation()[2])
    return np.array(heights)


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Roll every recording out and write its HTML page (drawn in a new Meshcat bound to
    localhost) and summary.json to ``out`` (default results/scene-recordings);
    ``summary["files"]`` lists them (absolute paths)."""
    config = config or Config()
    if not (np.isfinite(config.duration) and config.duration > 0):
        raise ValueError(
            f"duration must be a finite number of seconds > 0; got {config.duration!r}"
        )
    if not np.isfinite(config.push_offset):
        raise ValueError(f"push_offset must be a finite distance in m; got {config.push_offset!r}")
    unknown = set(config.recordings) - set(RECORDINGS)
    if unknown:
        raise ValueError(f"recordings must be among {sorted(RECORDINGS)}; got {sorted(unknown)}")
    folder = results_dir(NAME, out)
    rows, files = [], {}
    for name in progress(config.recordings, desc=f"{NAME}: recordings"):
        sm, xs, unconverged = rollout(name, config.duration, config.push_offset)
        row = {"recording": name, "scene": sm.scene.name, "time_step": sm.scene.time_step,
               "steps": len(xs) - 1, "unconverged_steps": unconverged,
               **_facts(name, sm, xs)}  # fmt: skip
        page = record_rollout_html(sm.scene, xs, folder / f"{name}.html")
        row.update(html=page.name, html_bytes=page.stat().st_size)
        files[name] = page
        rows.append(row)
    files["summary"] = folder / "summary.json"
    summary = {
        "duration_s": config.duration,
        "rows": rows,
        "folder": str(folder),
        "files": file_list(files),
    }
    (folder / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary


def report(summary: dict) -> str:
    lines = [f"scene recordings, {summary['duration_s']:g} s each:"]
    for r in summary["rows"]:
        what = (
            f"box moved {r['box_displacement_m'][0]:+.3f}, {r['box_displacement_m'][1]:+.3f} m, "
            f"yaw {r['box_yaw_rad']:+.3f} rad"
            if "box_yaw_rad" in r
            else f"base {r['base_height_start_m']:.3f} -> {r['base_height_end_m']:.3f} m"
        )
        lines.append(
            f"  {r['recording']:17s} {r['steps']:4d} steps, {r['unconverged_steps']} unconverged, "
            f"deepest penetration {1e3 * r['deepest_penetration_m']:.2f} mm; {what}"
        )
    for path in summary.get("files", {}).values():
        lines.append(f"  {path}")
    return "\n".join(lines)


if __name__ == "__main__":
    print(report(run(Config.test_size())))
