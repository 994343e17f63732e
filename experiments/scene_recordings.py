"""Meshcat recordings of the robot and manipulation scenes under their controllers: one
self-contained HTML page per recording, and what each rollout did.

Recordings (each the scene's own stepper under its controller, a time-varying policy, in
:func:`drake_abs.engine.rollout`; exact contact unless the scene says otherwise; every step's
``converged`` flag counted):

- ``gym_hopper``, ``gym_half_cheetah``: gymnasium's models as published, dropped and driven by
  the seeded open-loop torque sequence of the MuJoCo comparison
  (:func:`~drake_abs.policy.controls.held_random_inputs`: held 5 steps each, ctrl uniform in
  +-0.5 of the gear);
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

from drake_abs import engine
from drake_abs.diagrams.scene_visualization import record_rollout_html
from drake_abs.experiments.outputs import file_list, progress, results_dir
from drake_abs.multibody import build_scene_model
from drake_abs.multibody.posture import SOLO12_TROT, STANDING_GAINS, stepping_controller
from drake_abs.policy.controls import TimeVaryingController, held_random_inputs

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


def _controller(name: str, sm, steps: int, push_offset: float) -> tuple[np.ndarray, object]:
    """``(x0, policy)`` of a recording: the initial state and its controller of (t, x)."""
    plant, nq, h = sm.plant, sm.contact_model.nq, sm.scene.time_step
    x0 = np.asarray(sm.x0, float).copy()
    nx, nu = x0.size, plant.num_actuators()
    if name.startswith("gym_"):  # ctrl in [-1, 1] times the gear (the actuators' effort limits)
        gear = [plant.get_joint_actuator(a).effort_limit() for a in plant.GetJointActuatorIndices()]
        torques = held_random_inputs(steps, nu) * np.array(gear)
        return x0, TimeVaryingController(lambda t, x: torques[t], nx, nu)
    if name == "pusher_box":  # a velocity servo on the pusher's x, y
        x0[1] = push_offset  # the pusher's y against the box's centre line (y = 0)
        target = np.array([PUSH_SPEED, 0.0])
        return x0, TimeVaryingController(
            lambda t, x: PUSH_GAIN * (target - x[:, nq : nq + 2]), nx, nu
        )
    feet, kp, kd = STANDING_GAINS[sm.scene.name]
    swing, phase, frequency = SOLO12_TROT if name == "solo12_stepping" else (0.0, 0.0, 0.0)
    drive = stepping_controller(sm, feet, kp, kd, swing, phase, frequency)
    return x0, TimeVaryingController(lambda t, x: drive(t * h, x), nx, nu)


def rollout(
    name: str, duration: float, push_offset: float = PUSH_OFFSET
) -> tuple[object, np.ndarray, int]:
    """The recording's scene model, its states (T + 1, nx) and the number of unconverged
    steps."""
    sm = build_scene_model(RECORDINGS[name])
    steps = int(round(duration / sm.scene.time_step))
    x0, policy = _controller(name, sm, steps, push_offset)
    noise = np.zeros((1, steps, policy.nu))
    traj = engine.rollout(sm.stepper(), policy, np.zeros(0), x0, noise, sigma=0.0,
                          gradient=False, on_unconverged="flag")  # fmt: skip
    return sm, traj.x[0], int((~traj.converged).sum())


def _facts(name: str, sm, xs: np.ndarray) -> dict:
    """What the rollout did, from its states."""
    depth = float(max(0.0, -sm.contact_model.distances(xs[:, : sm.contact_model.nq]).min()))
    if name == "pusher_box":  # box x, y, z, yaw after the pusher's x, y
        return {"deepest_penetration_m": depth,
                "box_displacement_m": [float(d) for d in xs[-1, 2:4] - xs[0, 2:4]],
                "box_yaw_rad": float(xs[-1, 5] - xs[0, 5])}  # fmt: skip
    plant = sm.plant  # the height of the model's first body with mass (its base)
    context = plant.CreateDefaultContext()
    base = plant.GetBodyByName(sm.contact_model.massive_bodies[0])
    z = []
    for x in (xs[0], xs[-1]):
        plant.SetPositions(context, x[: plant.num_positions()])
        z.append(float(plant.EvalBodyPoseInWorld(context, base).translation()[2]))
    return {"deepest_penetration_m": depth, "base_height_start_m": z[0], "base_height_end_m": z[1]}


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
