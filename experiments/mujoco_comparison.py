"""Side by side with MuJoCo: gymnasium's Hopper and HalfCheetah, the same MJCF
files loaded unedited by both, stepped with the same time step from the same state with the same
joint torques, and Drake's SAP on the scene's twin beside them.

Three scenarios per scene: a passive drop from the file's initial pose, a fixed seeded open-loop
torque sequence (piecewise constant, redrawn every ``hold`` steps) and a joint-limit hit (a
constant torque driving the last actuated joint into its upper limit during the drop). Reported:
RMS differences of the configuration trajectories (ours against MuJoCo and against SAP), the
torso's final height, the deepest penetration of a contact into the ground, the total normal
contact impulse and the total joint-limit impulse; and the Jacobians of our step on these scenes
against central finite differences of the same step.

The models are the same but the contact laws are not; see :data:`WHY_THEY_DIFFER`.

MuJoCo's side: ``opt.timestep`` is set to the scene's time step and ``opt.integrator`` to Euler
(semi-implicit; the Hopper file asks for RK4, which ``mjd_transitionFD`` refuses and which a
stiff soft contact at 10 ms does not need); the joints' springs are zeroed (``jnt_stiffness``),
as the HalfCheetah scene drops them (the Hopper's are 0 already). States map one to one: the
scenes' q, v are MuJoCo's qpos, qvel (same joints, same order, same references), and our input,
the joint torque, is MuJoCo's ctrl times the motor's gear.
"""

from __future__ import annotations

import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from drake_abs.experiments._common import file_list, progress, results_dir

NAME = "mujoco-comparison"
SCENES = ("gym_hopper", "gym_half_cheetah")

#: scene -> (gymnasium asset, gymnasium's frame_skip in the v5 environments)
GYM_FILES = {"gym_hopper": ("hopper.xml", 4), "gym_half_cheetah": ("half_cheetah.xml", 5)}

#: Why the two simulators' trajectories differ (written into the report).
WHY_THEY_DIFFER = (
    "Contact law: ours is hard (complementarity): the normal impulse stops penetration within the "
    "step, so the contact points rest on the ground (gap ~ 0). MuJoCo's is soft (solref = 0.02 s "
    "time constant, solimp impedance 0.8..0.8 (Hopper) / 0..0.8 (HalfCheetah)): a contact behaves "
    "like a damped spring and the bodies sink into the ground until the spring carries their "
    "weight, millimetres to a centimetre here; its joint limits are soft the same way, so a limit "
    "is overshot briefly. Cone: ours is a linearised (pyramid, 2 directions in the plane) Coulomb "
    "cone with exact complementarity; MuJoCo's default pyramidal cone is regularised, so it "
    "allows slow creep under static load. Geometry: ours touches at listed capsule-end spheres, "
    "MuJoCo collides the whole capsules (and, for the Hopper, the links with each other), so a "
    "capsule landing on its side touches at its middle in MuJoCo only. SAP is soft too (convex, "
    "compliant point contact), between the two. Once the torques make the models walk or fall "
    "over, small differences grow: the open-loop RMS is a measure of that divergence, not of an "
    "error of either side."
)


@dataclass
class Config:
    scenes: tuple[str, ...] = SCENES
    drop_steps: int = 150
    torque_steps: int = 100
    limit_steps: int = 60
    hold: int = 5  # open-loop: steps each random ctrl is held
    ctrl_scale: float = 0.5  # open-loop ctrl drawn uniformly in +-ctrl_scale
    limit_ctrl: float = 0.5  # joint-limit hit: ctrl on the last motor
    gradient_states: int = 3  # states of the open-loop rollout where Jacobians are checked
    seed: int = 0
    sap: bool = True

    @classmethod
    def test_size(cls) -> Config:
        return cls(drop_steps=80, torque_steps=30, limit_steps=40, gradient_states=2)


def gym_asset(scene_name: str) -> Path:
    import gymnasium

    return Path(gymnasium.__file__).parent / "envs" / "mujoco" / "assets" / GYM_FILES[scene_name][0]


def mujoco_model(scene_name: str, time_step: float):
    """MuJoCo's model of the scene's file with the scene's time step, Euler, no joint springs.
    Returns (model, gymnasium's control period frame_skip * file timestep)."""
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(gym_asset(scene_name)))
    gym_dt = float(model.opt.timestep) * GYM_FILES[scene_name][1]
    model.opt.timestep = time_step
    model.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    model.jnt_stiffness[:] = 0.0
    return model, gym_dt


class _Geometry:
    """Our contact points' signed gaps to the ground and the torso's height, for any q."""

    def __init__(self, sm):
        self.plant = sm.plant
        self.ctx = self.plant.CreateDefaultContext()
        self.nq = self.plant.num_positions()
        self.scene = sm.scene
        self.bodies = [self.plant.GetBodyByName(c.body) for c in sm.scene.contacts]
        self.torso = self.plant.GetBodyByName("torso")

    def gaps(self, q: np.ndarray) -> np.ndarray:
        self.plant.SetPositions(self.ctx, q[: self.nq])
        out = []
        for body, c in zip(self.bodies, self.scene.contacts, strict=True):
            X = self.plant.EvalBodyPoseInWorld(self.ctx, body)
            for p in c.points:
                z = (X @ np.asarray(p, float))[2]
                out.append(z - (c.radius or 0.0) - self.scene.ground_height)
        return np.asarray(out)

    def torso_height(self, q: np.ndarray) -> float:
        self.plant.SetPositions(self.ctx, q[: self.nq])
        return float(self.plant.EvalBodyPoseInWorld(self.ctx, self.torso).translation()[2])


def _controls(config: Config, scenario: str, steps: int, nu: int) -> np.ndarray:
    """MuJoCo ctrl (steps, nu), in [-1, 1]."""
    ctrl = np.zeros((steps, nu))
    if scenario == "open_loop":
        rng = np.random.default_rng(config.seed)
        blocks = rng.uniform(-config.ctrl_scale, config.ctrl_scale, (-(-steps // config.hold), nu))
        ctrl = np.repeat(blocks, config.hold, axis=0)[:steps]
    elif scenario == "limit_hit":
        ctrl[:, -1] = config.limit_ctrl
    return ctrl


def run_ours(sm, x0, torques):
    stepper = sm.stepper()
    xs, imp, limp, conv = [x0], 0.0, 0.0, True
    for u in torques:
        r = stepper.step(xs[-1][None], u[None], jacobians=False)
        xs.append(r.x_next[0])
        imp += float(r.impulse.sum())
        limp += float(np.abs(r.limit_impulse).sum()) if r.limit_impulse is not None else 0.0
        conv &= bool(r.converged.all())
    return {"x": np.array(xs), "impulse": imp, "limit_impulse": limp, "converged": conv}


def run_mujoco(model, x0, ctrls):
    import mujoco

    data = mujoco.MjData(model)
    nq = model.nq
    data.qpos[:] = x0[:nq]
    data.qvel[:] = x0[nq:]
    mujoco.mj_forward(model, data)
    floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    xs, imp, limp, pen = [x0.copy()], 0.0, 0.0, 0.0
    f6 = np.zeros(6)
    dt = model.opt.timestep
    for c in ctrls:
        data.ctrl[:] = c
        mujoco.mj_step(model, data)
        xs.append(np.concatenate([data.qpos, data.qvel]))
        # forces of the step just taken (mj_step leaves them from its own forward pass)
        for i in range(data.ncon):
            con = data.contact[i]
            if floor not in (con.geom1, con.geom2):
                continue
            pen = max(pen, -float(con.dist))
            mujoco.mj_contactForce(model, data, i, f6)
            imp += f6[0] * dt
        limits = data.efc_type == mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT
        limp += float(np.abs(data.efc_force[limits]).sum()) * dt
    return {"x": np.array(xs), "impulse": imp, "limit_impulse": limp, "penetration": pen}


def run_sap(scene, x0, torques):
    from pydrake.systems.analysis import Simulator

    from drake_abs.reference.drake_twin import make_drake_twin

    twin = make_drake_twin(scene, "sap")
    sim = Simulator(twin.diagram)
    ctx = sim.get_mutable_context()
    pc = twin.plant.GetMyMutableContextFromRoot(ctx)
    nq = twin.plant.num_positions()
    twin.plant.SetPositions(pc, x0[:nq])
    twin.plant.SetVelocities(pc, x0[nq:])
    port = twin.diagram.get_input_port(0)
    port.FixValue(ctx, torques[0])
    sim.Initialize()
    xs, imp = [x0.copy()], 0.0
    for k, u in enumerate(torques):
        port.FixValue(ctx, u)
        sim.AdvanceTo((k + 1) * scene.time_step)
        xs.append(twin.plant.GetPositionsAndVelocities(pc).copy())
        results = twin.plant.get_contact_results_output_port().Eval(pc)
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            imp += abs(float(info.contact_force() @ info.point_pair().nhat_BA_W)) * scene.time_step
    return {"x": np.array(xs), "impulse": imp}


def _rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)))


def gradient_check(sm, states: np.ndarray, torques: np.ndarray, eps: float = 1e-6) -> dict:
    """Largest relative error of our dx+/dx, dx+/du against central differences of our step."""
    stepper = sm.stepper()
    nx = states.shape[1]
    worst_x, worst_u = 0.0, 0.0
    for x, u in zip(states, torques, strict=True):
        r = stepper.step(x[None], u[None], jacobians=True)

        def f(z, u=u):
            return stepper.step(z[None, :nx], z[None, nx:], jacobians=False).x_next[0]

        z = np.concatenate([x, u])
        cols = []
        for i in range(z.size):
            e = np.zeros_like(z)
            e[i] = eps
            cols.append((f(z + e) - f(z - e)) / (2 * eps))
        fd = np.stack(cols, axis=1)
        scale = max(1.0, float(np.abs(fd).max()))
        worst_x = max(worst_x, float(np.abs(r.dx_dx[0] - fd[:, :nx]).max()) / scale)
        worst_u = max(worst_u, float(np.abs(r.dx_du[0] - fd[:, nx:]).max()) / scale)
    return {"dx_dx_rel_err": worst_x, "dx_du_rel_err": worst_u}


def compare_scene(name: str, config: Config) -> dict:
    from drake_abs.multibody import build_scene_model

    sm = build_scene_model(name)
    scene = sm.scene
    model, gym_dt = mujoco_model(name, scene.time_step)
    gear = model.actuator_gear[:, 0].copy()
    geom = _Geometry(sm)
    nq = sm.plant.num_positions()
    x0 = np.asarray(sm.x0, float)
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
        ctrl = _controls(config, scenario, n, model.nu)
        torques = ctrl * gear
        ours = run_ours(sm, x0, torques)
        mj = run_mujoco(model, x0, ctrl)
        sides = {"ours": ours, "mujoco": mj}
        if config.sap:
            sides["sap"] = run_sap(scene, x0, torques)
        res = {}
        for side, out in sides.items():
            qs = out["x"][:, :nq]
            gaps = np.array([geom.gaps(q) for q in qs])
            entry = {
                "final_torso_height": geom.torso_height(qs[-1]),
                "final_root_x": float(qs[-1, 0]),
                "max_point_penetration": float(max(0.0, -gaps.min())),
                "normal_impulse_total": out["impulse"],
            }
            if side == "mujoco":
                entry["max_geom_penetration"] = out["penetration"]
            if "limit_impulse" in out:
                entry["limit_impulse_total"] = out["limit_impulse"]
            if "converged" in out:
                entry["converged"] = out["converged"]
            j = sm.plant.GetJointByName(_last_motor_joint(model))
            entry["last_joint_max_over_upper"] = float(
                (qs[:, j.position_start()] - j.position_upper_limits()[0]).max()
            )
            if side != "ours":
                entry["rms_q_vs_ours"] = _rms(qs, ours["x"][:, :nq])
                head = max(2, int(round(0.2 / scene.time_step)))
                entry["rms_q_vs_ours_first_0.2s"] = _rms(qs[:head], ours["x"][:head, :nq])
            res[side] = entry
        row["scenarios"][scenario] = res
        if scenario == "open_loop" and config.gradient_states:
            idx = np.linspace(1, n - 1, config.gradient_states).astype(int)
            row["gradient"] = gradient_check(sm, ours["x"][idx], torques[idx])
    return row


def _last_motor_joint(model) -> str:
    import mujoco

    jid = int(model.actuator_trnid[model.nu - 1, 0])
    return mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, jid)


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Compare every scene of ``config``; write mujoco_comparison.json to ``out`` (default
    results/mujoco-comparison); ``summary["files"]`` lists it (absolute path)."""
    config = config or Config()
    out = results_dir(NAME, out)
    logging.getLogger("drake").setLevel(logging.ERROR)  # the MJCF parser's unsupported tags
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
    lines = [f"Ours vs MuJoCo {summary['mujoco_version']} (soft contact) vs Drake SAP"]
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
    lines.append("\nWhy they differ: " + summary["why_they_differ"])
    return "\n".join(lines)


if __name__ == "__main__":
    print(report(run(Config())))
