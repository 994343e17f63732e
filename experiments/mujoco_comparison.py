"""Side by side with MuJoCo: gymnasium's Hopper and HalfCheetah, the same MJCF
files loaded unedited by both, stepped with the same time step from the same state with the same
joint torques, and Drake's SAP on the scene's twin beside them.

Three scenarios per scene: a passive drop from the file's initial pose, a fixed seeded open-loop
torque sequence (piecewise constant, redrawn every ``hold`` steps) and a joint-limit hit (a
constant torque driving one joint into a limit during the drop: the Hopper's foot into its upper
limit, the HalfCheetah's back foot into its lower one, the one its spring lets a full-range motor
reach, :data:`LIMIT_HIT`). Our step
runs twice: with hard contact (the scene as shipped, side ``ours``) and with the contact
compliance option that reproduces MuJoCo's soft contact from the file's own solref, solimp and
margins (``compliance: {kind: mujoco, from_model: true}``, side ``ours_soft``;
:mod:`drake_abs.contact.compliance`). Reported: RMS differences of the configuration trajectories
(ours against MuJoCo and against SAP; each of our two sides against MuJoCo, side by side), the
torso's final height, the deepest penetration of a contact into the ground, the total normal
contact impulse and the total joint-limit impulse; and the Jacobians of our step on these scenes
against central finite differences of the same step.

The models are the same but the contact laws are not; see :data:`WHY_THEY_DIFFER`.

MuJoCo's side: ``opt.timestep`` is set to the scene's time step and ``opt.integrator`` to Euler
(semi-implicit; the Hopper file asks for RK4, which ``mjd_transitionFD`` refuses and which a
stiff soft contact at 10 ms does not need); the joints' springs are MuJoCo's own, as the
scenes take them too (the HalfCheetah's, stiffness towards 0; the Hopper has none). States map
one to one: the scenes' q, v are MuJoCo's qpos, qvel (same joints, same order, same
references), and our input, the joint torque, is MuJoCo's ctrl times the motor's gear.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from drake_abs.engine import open_loop
from drake_abs.engine.step_log import StepLog
from drake_abs.experiments.outputs import file_list, progress, results_dir
from drake_abs.multibody import build_scene_model
from drake_abs.policy.controls import held_random_inputs
from drake_abs.reference.drake_plant import DrakePlantStepper
from drake_abs.reference.mujoco_plant import MujocoStepper

NAME = "mujoco-comparison"
SCENES = ("gym_hopper", "gym_half_cheetah")

#: scene -> (gymnasium asset, gymnasium's frame_skip in the v5 environments)
GYM_FILES = {"gym_hopper": ("hopper.xml", 4), "gym_half_cheetah": ("half_cheetah.xml", 5)}

#: scene -> (the motor driven into a joint limit in the limit-hit scenario, by index; the
#: multiple of Config.limit_ctrl its ctrl takes: its sign picks the limit). The HalfCheetah's
#: springs (stiffness 60 ... 240 N m/rad) hold every joint off its limits at half its motor's
#: range; its back foot (gear 60, spring 120 N m/rad) reaches its lower limit, -0.4 rad, at full
#: range.
LIMIT_HIT = {"gym_hopper": (-1, 1.0), "gym_half_cheetah": (2, -2.0)}

#: Why the two simulators' trajectories differ (written into the report).
WHY_THEY_DIFFER = (
    "Contact law: ours is hard (complementarity): the normal impulse stops penetration within the "
    "step, so the contact points rest on the ground (gap ~ 0). MuJoCo's is soft (solref = 0.02 s "
    "time constant, solimp impedance 0.8..0.8 (Hopper) / 0..0.8 (HalfCheetah)): a contact behaves "
    "like a damped spring and the bodies sink into the ground until the spring carries their "
    "weight, millimetres to a centimetre here; its joint limits are soft the same way, so a limit "
    "is overshot briefly. Cone: ours is a linearised (pyramid, 2 directions in the plane) Coulomb "
    "cone with exact complementarity; MuJoCo's default pyramidal cone is regularised, so it "
    "allows slow creep under static load. Geometry: ours touches at the capsules' end spheres, "
    "which against the flat ground is the whole capsule (its nearest point is an end); MuJoCo "
    "also collides the Hopper's links with each other. Springs: the HalfCheetah's joint springs "
    "are explicit on both sides (its scene's joint_springs: explicit, MuJoCo's Euler step: in "
    "the air the two agree to rounding; implicit springs would separate them by about 0.09 rad "
    "at this 10 ms step). SAP is soft too (convex, "
    "compliant point contact), between the two. Once the torques make the models walk or fall "
    "over, small differences grow: the open-loop RMS is a measure of that divergence, not of an "
    "error of either side. ours_soft is our step with MuJoCo's contact law (the file's solref, "
    "solimp and margins as a regularised LCP): it sinks and springs back as MuJoCo does; what "
    "remains is the cone (its friction rows stay hard; a planar scene "
    "has 2 of MuJoCo's 4 pyramid edges) and the joint limits, which stay hard."
)


@dataclass
class Config:
    scenes: tuple[str, ...] = SCENES
    drop_steps: int = 150
    torque_steps: int = 100
    limit_steps: int = 60
    hold: int = 5  # open-loop: steps each random ctrl is held
    ctrl_scale: float = 0.5  # open-loop ctrl drawn uniformly in +-ctrl_scale
    limit_ctrl: float = 0.5  # joint-limit hit: ctrl on the motor of LIMIT_HIT (times its factor)
    gradient_states: int = 3  # states of the open-loop rollout where Jacobians are checked
    seed: int = 0
    sap: bool = True
    compliance: bool = True  # also run our step with MuJoCo's soft contact (side ours_soft)

    @classmethod
    def test_size(cls) -> Config:
        return cls(drop_steps=80, torque_steps=30, limit_steps=40, gradient_states=2)


def gym_asset(scene_name: str) -> Path:
    import gymnasium

    return Path(gymnasium.__file__).parent / "envs" / "mujoco" / "assets" / GYM_FILES[scene_name][0]


def _ctrl(config: Config, scenario: str, steps: int, nu: int, scene: str) -> np.ndarray:
    """MuJoCo ctrl (steps, nu), in [-1, 1]: zero (drop), held random (open loop), or the
    constant ``limit_ctrl`` times the scene's factor on its :data:`LIMIT_HIT` motor (limit
    hit)."""
    if scenario == "open_loop":
        return held_random_inputs(
            steps, nu, scale=config.ctrl_scale, hold=config.hold, seed=config.seed
        )
    ctrl = np.zeros((steps, nu))
    motor, factor = LIMIT_HIT[scene]
    ctrl[:, motor] = factor * config.limit_ctrl if scenario == "limit_hit" else 0.0
    return ctrl


def _floor_penetration(model, states: np.ndarray) -> float:
    """MuJoCo's deepest geom penetration (m) into the floor at these states (qpos first)."""
    import mujoco

    data = mujoco.MjData(model)
    floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    deepest = 0.0
    for x in states:
        data.qpos[:] = x[: model.nq]
        mujoco.mj_fwdPosition(model, data)  # the contacts mj_step finds at this state
        c = data.contact
        on_floor = (c.geom1 == floor) | (c.geom2 == floor)
        deepest = max(deepest, float((-c.dist[on_floor]).max(initial=0.0)))
    return deepest


def _rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)))


def gradient_check(stepper, states: np.ndarray, torques: np.ndarray, eps: float = 1e-6) -> dict:
    """Largest relative error of our dx+/dx, dx+/du at (states (S, nx), torques (S, nu)) against
    central differences of the same step (every perturbation in one batch)."""
    (S, nx), n = states.shape, states.shape[1] + torques.shape[1]
    z = np.concatenate([states, torques], axis=1)[None, :, None, :]
    z = z + np.array([1.0, -1.0])[:, None, None, None] * eps * np.eye(n)  # (2, S, n, n)
    r = stepper.step(states, torques, jacobians=True)
    f = stepper.step(z[..., :nx].reshape(-1, nx), z[..., nx:].reshape(-1, n - nx), jacobians=False)
    f = f.x_next.reshape(2, S, n, nx)
    fd = ((f[0] - f[1]) / (2 * eps)).transpose(0, 2, 1)  # (S, nx, nx + nu)
    scale = np.maximum(1.0, np.abs(fd).max(axis=(1, 2)))
    return {
        key: float((np.abs(J - fd[..., cols]).max(axis=(1, 2)) / scale).max())
        for key, J, cols in (("dx_dx_rel_err", r.dx_dx, slice(None, nx)),
                             ("dx_du_rel_err", r.dx_du, slice(nx, None)))
    }  # fmt: skip


def compare_scene(name: str, config: Config) -> dict:
    import mujoco

    sm = build_scene_model(name)
    soft_scene = replace(sm.scene, compliance={"kind": "mujoco", "from_model": True})
    scene, plant, nq = sm.scene, sm.plant, sm.contact_model.nq
    file_model = mujoco.MjModel.from_xml_path(str(gym_asset(name)))
    gym_dt = float(file_model.opt.timestep) * GYM_FILES[name][1]
    options = {"timestep": scene.time_step, "integrator": "Euler"}
    floor = mujoco.mj_name2id(file_model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    actuators = plant.GetJointActuatorIndices()
    last = plant.get_joint_actuator(actuators[-1]).joint()
    motor, factor = LIMIT_HIT[name]
    hit = plant.get_joint_actuator(actuators[motor]).joint()
    k_hit = float(sm.stepper().springs.stiffness[hit.velocity_start()])  # N m / rad, 0: none
    context, torso = plant.CreateDefaultContext(), plant.GetBodyByName("torso")
    x0 = np.asarray(sm.x0, float)
    head = max(2, int(round(0.2 / scene.time_step)))
    row = {
        "scene": name,
        "time_step": scene.time_step,
        "gymnasium_control_period": gym_dt,
        "mujoco_file_timestep": gym_dt / GYM_FILES[name][1],
        "scenarios": {},
    }
    steps = {"drop": config.drop_steps, "open_loop": config.torque_steps}
    steps["limit_hit"] = config.limit_steps
    for scenario, n in steps.items():
        ctrl = _ctrl(config, scenario, n, file_model.nu, name)
        torques = ctrl * file_model.actuator_gear[:, 0]
        sides = {"ours": (sm.stepper(), torques),
                 "mujoco": (MujocoStepper(file_model, options=options), ctrl)}  # fmt: skip
        if config.compliance:
            sides["ours_soft"] = (build_scene_model(soft_scene).stepper(), torques)
        if config.sap:
            sides["sap"] = (DrakePlantStepper(scene, "sap"), torques)
        res = row["scenarios"][scenario] = {}
        for side, (stepper, u) in sides.items():
            log = StepLog(stepper)
            traj = open_loop(log, x0, u, jacobians=False, on_unconverged="flag")
            qs = traj.x[0, :, :nq]
            plant.SetPositions(context, qs[-1])
            impulse = traj.impulse[0, :, [floor]] if side == "mujoco" else traj.impulse
            e = {
                "final_torso_height": plant.EvalBodyPoseInWorld(context, torso).translation()[2],
                "final_root_x": qs[-1, 0],
                "max_point_penetration": max(0.0, -sm.contact_model.distances(qs).min()),
                "normal_impulse_total": impulse.sum(),
            }
            if side == "mujoco":
                e["max_geom_penetration"] = _floor_penetration(stepper.model, traj.x[0, :-1])
            if side != "sap":
                e["limit_impulse_total"] = np.abs(log.stacked("limit_impulse")).sum()
            if side in ("ours", "ours_soft"):
                e["converged"] = bool(traj.converged.all())
            if side == "ours":
                x_ours = traj.x[0]
            if side == "mujoco":
                x_mujoco = traj.x[0]
            if side == "ours_soft":
                x_soft = traj.x[0]
            upper = last.position_upper_limits()[0]
            e["last_joint_max_over_upper"] = (qs[:, last.position_start()] - upper).max()
            # past the limit LIMIT_HIT drives into (rad; negative: short of it)
            if factor > 0:
                past = qs[:, hit.position_start()] - hit.position_upper_limits()[0]
            else:
                past = hit.position_lower_limits()[0] - qs[:, hit.position_start()]
            e["limit_joint_max_past_limit"] = past.max()
            # the load the joint's spring takes beyond the limit (N m s): where a soft limit lets
            # the joint overshoot, its spring pushes back harder than at the limit, and the
            # limit itself stops that much less (springs at the step's start, as MuJoCo's Euler)
            e["limit_spring_excess_impulse"] = (
                scene.time_step * k_hit * np.maximum(0.0, past[:-1]).sum()
            )
            if side != "ours":
                e["rms_q_vs_ours"] = _rms(qs, x_ours[:, :nq])
                e["rms_q_vs_ours_first_0.2s"] = _rms(qs[:head], x_ours[:head, :nq])
            if side == "ours_soft":  # the gap to MuJoCo, beside the hard side's (below)
                e["rms_q_vs_mujoco"] = _rms(qs, x_mujoco[:, :nq])
                e["rms_q_vs_mujoco_first_0.2s"] = _rms(qs[:head], x_mujoco[:head, :nq])
            res[side] = {k: v if isinstance(v, bool) else float(v) for k, v in e.items()}
        if config.compliance:  # hard and soft side by side: each one's gap to MuJoCo
            res["gap_to_mujoco"] = {
                contact: {"rms_q": res[side]["rms_q_vs_mujoco"] if side == "ours_soft"
                          else res["mujoco"]["rms_q_vs_ours"],
                          "rms_q_first_0.2s": res[side]["rms_q_vs_mujoco_first_0.2s"]
                          if side == "ours_soft" else res["mujoco"]["rms_q_vs_ours_first_0.2s"]}
                for contact, side in (("hard", "ours"), ("soft", "ours_soft"))
            }  # fmt: skip
        if scenario == "open_loop" and config.gradient_states:
            idx = np.linspace(1, n - 1, config.gradient_states).astype(int)
            row["gradient"] = gradient_check(sm.stepper(), x_ours[idx], torques[idx])
            if config.compliance:  # at the soft side's own states (contacts within margins)
                row["gradient_soft"] = gradient_check(
                    sides["ours_soft"][0], x_soft[idx], torques[idx]
                )
    return row


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Compare every scene of ``config``; write mujoco_comparison.json to ``out`` (default
    results/mujoco-comparison); ``summary["files"]`` lists it (absolute path)."""
    config = config or Config()
    out = results_dir(NAME, out)
    import mujoco

    summary = {
        "config": asdict(config),
        "mujoco_version": mujoco.__version__,
        "scenes": [
            compare_scene(name, config) for name in progress(config.scenes, desc=f"{NAME}: scenes")
        ],
        "why_they_differ": WHY_THEY_DIFFER,
        "folder": str(out),
        "files": file_list({"summary": out / "mujoco_comparison.json"}),
    }
    (out / "mujoco_comparison.json").write_text(json.dumps(summary, indent=2))
    return summary


def report(summary: dict) -> str:
    lines = [f"Ours (hard; ours_soft: MuJoCo's soft contact) vs MuJoCo "
             f"{summary['mujoco_version']} (soft contact) vs Drake SAP"]  # fmt: skip
    for row in summary["scenes"]:
        lines.append(
            f"\n{row['scene']}: time step {row['time_step']} s for all (gymnasium: file timestep "
            f"{row['mujoco_file_timestep']} s x frame_skip = {row['gymnasium_control_period']} s)"
        )
        lines.append(
            f"  {'scenario':10s} {'side':7s} {'torso z':>8s} {'pen (mm)':>9s} {'imp (Ns)':>9s} "
            f"{'lim (Nms)':>9s} {'over lim':>9s} {'RMS q':>8s} {'RMS 0.2s':>8s}"
        )
        for scenario, res in row["scenarios"].items():
            for side, e in res.items():
                if side == "gap_to_mujoco":
                    continue
                lines.append(
                    f"  {scenario:10s} {side:7s} {e['final_torso_height']:8.4f} "
                    f"{1e3 * e['max_point_penetration']:9.3f} {e['normal_impulse_total']:9.2f} "
                    f"{e.get('limit_impulse_total', float('nan')):9.2f} "
                    f"{e['last_joint_max_over_upper']:9.4f} "
                    f"{e.get('rms_q_vs_ours', 0.0):8.4f} "
                    f"{e.get('rms_q_vs_ours_first_0.2s', 0.0):8.4f}"
                )
        if "gradient" in row:
            g = row["gradient"]
            lines.append(
                f"  our Jacobians vs central differences (open loop): dx/dx rel err "
                f"{g['dx_dx_rel_err']:.2e}, dx/du {g['dx_du_rel_err']:.2e}"
            )
        if "gradient_soft" in row:
            g = row["gradient_soft"]
            lines.append(
                f"  with soft contact: dx/dx rel err {g['dx_dx_rel_err']:.2e}, dx/du "
                f"{g['dx_du_rel_err']:.2e}"
            )
        gaps = [
            (s, r["gap_to_mujoco"]) for s, r in row["scenarios"].items() if "gap_to_mujoco" in r
        ]
        if gaps:
            lines.append("  gap to MuJoCo, RMS of q (whole run / first 0.2 s): hard | soft contact")
            for scenario, gap in gaps:
                hard, soft = gap["hard"], gap["soft"]
                lines.append(
                    f"    {scenario:10s} {hard['rms_q']:8.4f} / {hard['rms_q_first_0.2s']:8.4f} | "
                    f"{soft['rms_q']:8.4f} / {soft['rms_q_first_0.2s']:8.4f}"
                )
    lines.append("\nWhy they differ: " + summary["why_they_differ"])
    return "\n".join(lines)


if __name__ == "__main__":
    print(report(run(Config())))
