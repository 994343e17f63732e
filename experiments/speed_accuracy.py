"""The speed/accuracy trade: what each setting costs per simulated second, and how far from the
truth it lands, for our complementarity plant and Drake's contact models on the same scenes:
**box** and **ball** of :mod:`drake_abs.reference.comparison_scenes` (the box pushed off at
1 m/s slides to rest; the 5 cm ball dropped from 0.3 m and thrown at 1 m/s lands, slides and
rolls) and shipped articulated scenes (unactuated: they drop and collapse). Every setting starts
from the same state and runs in the engine (:func:`drake_abs.engine.open_loop`).

Settings, each at every time step h of ``time_steps``: ours exact (the solver's tolerance 1e-12
and looser ``tolerances``), BS (``Fixed`` mu, stated at h = 10 ms and scaled with h so that the
barrier acts at the same distance), ABS (``ContactAware``) and Gaussian-matched ABS; Drake's
discrete plant (:class:`DrakePlantStepper`) with SAP, Similar and Lagged (compliant point
contact, Drake's documented defaults). MuJoCo is left out: neither scene is an MJCF file.

The reference (the "truth") is our exact plant at ``reference_time_step`` (much finer than any
h); its own convergence is measured by the same errors at twice its step. Accuracy, against the
reference on a common time grid every ``sample_period``:

- ``trajectory_error_m``: RMS over the grid of the distance between the body's position and the
  reference's (m); ``final_error_m``: the same at the last time;
- ``penetration_m``: the deepest penetration of any contact point over the run (m);
- ``energy_error_J``: the largest ``|E(t) - E_ref(t)|`` over the grid, E kinetic plus potential (J);
- ``gradient_error``: ||G - G_ref|| / ||G_ref|| (Frobenius), G the derivatives of the final
  position with respect to two inputs (box: initial speed and push; ball: initial speed and
  height), by the engine's reverse pass over each model's one-step Jacobians (ours implicit,
  Drake's from AutoDiffXd). G_ref is the reference's least-squares slope of its final position
  over ``fd_points`` perturbations spread over +-``fd_half_width``, the slope at the scale of the
  motion: the exact discrete model lands at a whole step, so its final position is piecewise
  constant in the drop height (derivative 0; the rigid-body answer is 2/7 v_0 / (g t_land)). The
  analytic rigid-body slopes are reported beside G_ref.

Cost: wall-clock seconds per simulated second of one rollout, in double (``cost_s_per_s``) and
with the gradient (``gradient_cost_s_per_s``), the best of ``repeats`` timings. Outputs in
``out``: ``summary.json``, ``speed_accuracy.png`` (accuracy against cost) and
``speed_accuracy.md`` (for each accuracy, the cheapest setting that reaches it; every row).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from drake_abs.contact.smoothing import GaussianMatched, TimeStepScaled
from drake_abs.contact.unconverged import UnconvergedStepError
from drake_abs.engine import open_loop
from drake_abs.experiments import outputs
from drake_abs.multibody import Scene, build_scene_model
from drake_abs.multibody.energy import mechanical_energy
from drake_abs.policy.methods import SMOOTHINGS, make_smoothing
from drake_abs.reference.comparison_scenes import SCENES, ComparisonScenes
from drake_abs.reference.drake_plant import DrakePlantStepper
from drake_abs.reference.drake_twin import APPROXIMATION_LABELS

NAME = "speed-accuracy"
OURS = (*SMOOTHINGS, "gaussian")  # our settings' families; the others are Drake's
GAUSSIAN = "adaptive barrier smoothing (ABS, Gaussian-matched mu)"

_SPECIAL = {  # the inputs G differentiates with respect to, and the analytic slopes' entries
    "box": {"x0_columns": (3,), "push": True, "names": ("vx_0", "push"),
            "analytic": (("dx_T/dvx_0", 0, 0), ("dx_T/du", 0, 1))},
    "ball": {"x0_columns": (7, 2), "push": False, "names": ("vy_0", "z_0"),
             "analytic": (("dy_T/dvy_0", 1, 0), ("dy_T/dz_0", 1, 1))},
}  # fmt: skip
_TIERS = (1e-2, 1e-3, 1e-4)  # trajectory errors (m) the table asks for


@dataclass(frozen=True)
class Config:
    """Settings (SI units). A larger mu or sigma is more smoothing.

    Attributes:
        scenes: ``"box"``, ``"ball"`` (:class:`ComparisonScenes`) and shipped articulated
            scenes (unactuated: they drop and collapse).
        time_steps: the steps h every setting runs at (s); each must divide ``sample_period``.
        reference_time_step: the reference's step (s).
        sample_period: the common time grid of the errors (s).
        bs_mu: BS's mu values at h = 10 ms (N s m), scaled with h.
        gaussian_sigma: GaussianMatched's width (m, in the normal rows' units).
        tolerances: looser solver tolerances run with exact contact (1e-12 always runs).
        drake: Drake's discrete contact approximations to run.
        fd_half_width: per scene (box, ball), the half widths of the reference gradient's
            perturbations of each input (box: m/s, N; ball: m/s, m).
        fd_points: perturbations per input (the least-squares slope through them).
        repeats: timed repeats of each rollout (the best is kept).
        articulated_duration: simulated seconds of the articulated scenes.
        articulated_half_width: the reference gradient's perturbation of their base speeds
            (m/s).
        scene_config: the box's and ball's parameters (masses, friction, speeds, durations,
            ABS, Drake's material).
    """

    scenes: tuple[str, ...] = ("box", "ball", "hopper", "half_cheetah", "solo12_drop")
    time_steps: tuple[float, ...] = (0.02, 0.01, 0.005, 0.0025)
    reference_time_step: float = 0.0005
    sample_period: float = 0.02
    bs_mu: tuple[float, ...] = (1e-7, 1e-6, 1e-5, 1e-4)
    gaussian_sigma: float = 0.002
    tolerances: tuple[float, ...] = (1e-8, 1e-4)
    drake: tuple[str, ...] = ("sap", "similar", "lagged")
    fd_half_width: tuple[tuple[float, float], tuple[float, float]] = ((0.05, 0.05), (0.05, 0.02))
    fd_points: int = 9
    repeats: int = 2
    articulated_duration: float = 0.5
    articulated_half_width: float = 0.05
    scene_config: ComparisonScenes = field(
        default_factory=lambda: ComparisonScenes(ball_duration=1.0)
    )

    @classmethod
    def test_size(cls) -> Config:
        """The reduced size CI runs: two steps, a coarser reference, one setting of each kind."""
        return cls(
            time_steps=(0.02, 0.01),
            reference_time_step=0.002,
            bs_mu=(1e-5,),
            tolerances=(1e-4,),
            drake=("sap",),
            fd_points=5,
            scenes=("box", "ball", "hopper"),
            articulated_duration=0.2,
            scene_config=ComparisonScenes(ball_duration=0.5, box_duration=0.3),
        )


@dataclass(frozen=True)
class Setting:
    """One row: who simulates, how, at which step."""

    family: str  # "exact", "bs", "abs", "gaussian", or Drake's "sap", "similar", "lagged"
    time_step: float
    value: float | None = None  # mu (BS), tol (exact), sigma (Gaussian)

    @property
    def ours(self) -> bool:
        return self.family in OURS

    @property
    def name(self) -> str:
        """The family's display name (ours by the smoothing registry, Drake's by its
        approximation)."""
        if self.family in SMOOTHINGS:
            return f"ours, {SMOOTHINGS[self.family]}"
        return f"ours, {GAUSSIAN}" if self.ours else f"Drake {APPROXIMATION_LABELS[self.family]}"

    @property
    def label(self) -> str:
        value = {"exact": "tol", "bs": "mu"}.get(self.family) if self.value is not None else None
        name = self.name + (f", {value}={self.value:g}" if value else "")
        return f"{name}, h={1e3 * self.time_step:g} ms"


def settings(config: Config) -> list[Setting]:
    out = []
    for h in config.time_steps:
        out.append(Setting("exact", h))
        out += [Setting("exact", h, tol) for tol in config.tolerances]
        out += [Setting("bs", h, mu) for mu in config.bs_mu]
        out += [Setting("abs", h), Setting("gaussian", h, config.gaussian_sigma)]
        out += [Setting(name, h) for name in config.drake]
    return out


def scene_inputs(scene: str) -> dict:
    """What G is for a scene: ``rows``, the final position's coordinates (the plant's prismatic
    joints: the translation of the base); ``x0_columns`` and ``push``, the inputs (box and ball
    as above; an articulated scene: the base's initial horizontal and vertical speeds, the
    first and last prismatic joints' velocities); their ``names``; the ``analytic`` entries."""
    plant = build_scene_model(_scene_spec(scene, Config())).plant
    prismatic = [plant.get_joint(j) for j in plant.GetJointIndices()
                 if plant.get_joint(j).type_name() == "prismatic"]  # fmt: skip
    rows = tuple(j.position_start() for j in prismatic)
    if scene in _SPECIAL:
        return {"rows": rows, **_SPECIAL[scene]}
    nq, first, last = plant.num_positions(), prismatic[0], prismatic[-1]
    return {"rows": rows, "x0_columns": (nq + first.velocity_start(), nq + last.velocity_start()),
            "push": False, "names": (f"v_{first.name()}_0", f"v_{last.name()}_0"),
            "analytic": ()}  # fmt: skip


def _scene_spec(scene: str, config: Config, time_step: float | None = None):
    """The scene (box and ball from ``config.scene_config``; otherwise the shipped scene of that
    name), at ``time_step`` if given."""
    if scene in SCENES:
        return config.scene_config.scene(scene, time_step)
    spec = Scene.load(scene)
    return replace(spec, time_step=time_step) if time_step else spec


# ----------------------------------------------------------------------------------------------
# one rollout of a setting


def _stepper(scene: str, s: Setting, config: Config):
    """The setting's stepper: ours under its smoothing (mu stated at the scene config's step,
    scaled to h) and tolerance, or Drake's plant (the box's and ball's material from the scene
    config; an articulated scene with Drake's default material)."""
    spec, cfg = _scene_spec(scene, config, s.time_step), config.scene_config
    if not s.ours:
        material = cfg.drake_material() if scene in SCENES else None
        return DrakePlantStepper(spec, s.family, time_step=s.time_step, material=material)
    i = 1 if scene == "ball" else 0  # ABS as for the box, but for the ball
    if s.family == "gaussian":
        smoothing = GaussianMatched(s.value)
    else:
        smoothing = TimeStepScaled.between(make_smoothing(
            s.family, mu=s.value or 0.0, contact_aware=(cfg.abs_mu_max[i], cfg.abs_length[i])
        ), s.time_step, cfg.time_step)  # fmt: skip
    options = {"tol": s.value} if s.family == "exact" and s.value is not None else {}
    return build_scene_model(spec).stepper(smoothing=smoothing, gradient="total", **options)


def _inputs(scene: str, config: Config) -> tuple[np.ndarray, np.ndarray, float]:
    """(x0, the constant input, simulated seconds): box and ball from the scene config; an
    articulated scene from its initial state, unactuated."""
    if scene in SCENES:
        return config.scene_config.start(scene)
    model = build_scene_model(_scene_spec(scene, config))
    return model.x0, np.zeros(model.contact_model.nu), config.articulated_duration


def _selected(spec: dict, dx_dx0: np.ndarray, dx_du: np.ndarray) -> np.ndarray:
    """G: the final position's derivatives with respect to the scene's two inputs."""
    cols = [dx_dx0[:, c] for c in spec["x0_columns"]] + ([dx_du[:, 0]] if spec["push"] else [])
    return np.stack(cols, axis=1)[list(spec["rows"])]


def _best_of(repeats: int, fn):
    """(the shortest of ``repeats`` wall-clock timings of ``fn()``, its first result)."""
    best, first = np.inf, None
    for _ in range(max(1, repeats)):
        start = time.perf_counter()
        value = fn()
        best = min(best, time.perf_counter() - start)
        first = value if first is None else first
    return best, first


def run_setting(scene: str, s: Setting, config: Config, x0, u, duration, spec: dict) -> dict:
    """States, cost and G of one setting (one rollout in double, one with the gradient)."""
    stepper = _stepper(scene, s, config)
    U = np.tile(u, (int(round(duration / s.time_step)), 1))
    forward, traj = _best_of(config.repeats, lambda: open_loop(
        stepper, x0, U, jacobians=False, on_unconverged="flag"))  # fmt: skip
    with_gradient, grad = _best_of(config.repeats, lambda: open_loop(
        stepper, x0, U, on_unconverged="flag"))  # fmt: skip
    return {
        "xs": traj.x[0],
        "G": _selected(spec, grad.dxH_dx0[0], grad.dxH_du[0].sum(axis=0)),
        "cost_s_per_s": forward / duration,
        "gradient_cost_s_per_s": with_gradient / duration,
        "unconverged_steps": int((~traj.converged).sum()),
    }


# ----------------------------------------------------------------------------------------------
# accuracy


class Measures:
    """The reference of one scene and the errors of any rollout against it."""

    def __init__(self, scene: str, config: Config, xs_ref: np.ndarray, G_ref: np.ndarray,
                 spec: dict):  # fmt: skip
        self.scene, self.config, self.spec = scene, config, spec
        self.model = build_scene_model(_scene_spec(scene, config, config.reference_time_step))
        self.plant, self.nq = self.model.plant, self.model.plant.num_positions()
        self.xs_ref = self._grid(xs_ref, config.reference_time_step)
        self.E_ref = mechanical_energy(self.plant, self.xs_ref)
        self.G_ref = G_ref

    def _grid(self, xs: np.ndarray, h: float) -> np.ndarray:
        period = self.config.sample_period
        if abs((stride := int(round(period / h))) * h - period) > 1e-12:
            raise ValueError(f"time step {h} must divide sample_period = {period}")
        return xs[::stride]

    def errors(self, xs: np.ndarray, h: float, G: np.ndarray) -> dict:
        grid = self._grid(xs, h)
        rows = list(self.spec["rows"])
        dist = np.linalg.norm(grid[:, rows] - self.xs_ref[:, rows], axis=1)
        phi = self.model.contact_model.distances(xs[:, : self.nq])
        energy = mechanical_energy(self.plant, grid)
        return {
            "trajectory_error_m": float(np.sqrt(np.mean(dist**2))),
            "final_error_m": float(dist[-1]),
            "penetration_m": float(max(0.0, -phi.min())),
            "energy_error_J": float(np.max(np.abs(energy - self.E_ref))),
            "gradient_error": float(np.linalg.norm(G - self.G_ref) / np.linalg.norm(self.G_ref)),
        }


def reference(scene: str, config: Config, spec: dict) -> tuple[np.ndarray, np.ndarray, dict]:
    """The reference states at ``reference_time_step``, G_ref by the least-squares slope of its
    final position, and the reference's own errors at twice its step."""
    x0, u, duration = _inputs(scene, config)

    def states(h: float, x, push) -> np.ndarray:
        stepper = _stepper(scene, Setting("exact", h), config)
        U = np.tile(push, (int(round(duration / h)), 1))
        return open_loop(stepper, x, U, jacobians=False, on_unconverged="raise").x[0]

    h = config.reference_time_step
    xs = states(h, x0, u)
    widths = (config.fd_half_width[SCENES.index(scene)] if scene in SCENES
              else (config.articulated_half_width,) * 2)  # fmt: skip
    cols, n_x0 = [], len(spec["x0_columns"])
    for j, width in enumerate(widths):  # input j: column j of x0 or, past them, the push
        deltas, finals = np.linspace(-width, width, config.fd_points), []
        for d in deltas:
            x, push = x0.copy(), (u + d if j >= n_x0 else u)
            if j < n_x0:
                x[spec["x0_columns"][j]] += d
            finals.append(states(h, x, push)[-1])
        cols.append(np.polyfit(deltas, np.array(finals), 1)[0])  # the least-squares slope
    G_ref = np.stack(cols, axis=1)[list(spec["rows"])]
    self_error = Measures(scene, config, xs, G_ref, spec).errors(states(2 * h, x0, u), 2 * h, G_ref)
    self_error.pop("gradient_error")
    return xs, G_ref, self_error


# ----------------------------------------------------------------------------------------------
# the experiment


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Run every setting on every scene; write summary.json, speed_accuracy.png and
    speed_accuracy.md to ``out`` (default results/speed-accuracy); return the summary."""
    config = config or Config()
    out = outputs.results_dir(NAME, out)
    summary = {"config": asdict(config), "scenes": {}}
    bar = outputs.progress(total=len(config.scenes) * (1 + len(settings(config))), desc=NAME)
    for scene in config.scenes:
        bar.set_postfix_str(f"{scene}: reference")
        spec = scene_inputs(scene)
        try:
            xs_ref, G_ref, self_error = reference(scene, config, spec)
        except UnconvergedStepError as err:  # no truth to measure against: said, not hidden
            summary["scenes"][scene] = {"no_converged_reference": str(err)}
            bar.update(1 + len(settings(config)))
            continue
        bar.update()
        analytic = config.scene_config.rigid_slopes(scene) if scene in SCENES else {}
        measures = Measures(scene, config, xs_ref, G_ref, spec)
        x0, u, duration = _inputs(scene, config)
        rows = []
        for s in settings(config):
            bar.set_postfix_str(f"{scene}: {s.label}")
            r = run_setting(scene, s, config, x0, u, duration, spec)
            bar.update()
            rows.append({
                "label": s.label, "family": s.family, "time_step": s.time_step, "value": s.value,
                **{k: r[k] for k in ("cost_s_per_s", "gradient_cost_s_per_s",
                                     "unconverged_steps")},
                **measures.errors(r["xs"], s.time_step, r["G"]),
                "G": r["G"].tolist(),
            })  # fmt: skip
        summary["scenes"][scene] = {
            "duration_s": duration, "gradient_inputs": list(spec["names"]),
            "position_rows": list(spec["rows"]),
            "reference": {
                "time_step": config.reference_time_step, "G": G_ref.tolist(),
                "G_entries_vs_analytic": {
                    name: {"reference": float(G_ref[i, j]), "analytic_rigid": analytic[name]}
                    for name, i, j in spec["analytic"]},
                "self_error_at_twice_the_step": self_error,
            },
            "rows": rows, "cheapest": cheapest(rows),
        }  # fmt: skip
    bar.close()
    summary["folder"] = str(out)
    summary["files"] = outputs.file_list({
        "summary": out / "summary.json", "markdown": out / "speed_accuracy.md",
        "plot": out / "speed_accuracy.png",
    })  # fmt: skip
    outputs.write_json(out / "summary.json", summary)
    (out / "speed_accuracy.md").write_text(report(summary))
    plot(summary, out / "speed_accuracy.png")
    return summary


def cheapest(rows: list[dict]) -> dict:
    """For each trajectory-error tier, the cheapest of ours and of Drake's that reach it."""
    out = {}
    for tier in _TIERS:
        for who, ours in (("ours", True), ("drake", False)):
            ok = [r for r in rows if (r["family"] in OURS) == ours
                  and r["trajectory_error_m"] <= tier and r["unconverged_steps"] == 0]  # fmt: skip
            best = min(ok, key=lambda r: r["cost_s_per_s"]) if ok else None
            out[f"{who}@{tier:g}"] = None if best is None else {
                k: best[k] for k in ("label", "cost_s_per_s", "trajectory_error_m",
                                     "gradient_error", "gradient_cost_s_per_s")
            }  # fmt: skip
    return out


def _fmt(x: float | None, spec: str = "{:.2g}") -> str:
    return "-" if x is None else spec.format(x)


def report(summary: dict) -> str:
    lines = ["# Speed and accuracy", ""]
    keys = ("cost_s_per_s", "gradient_cost_s_per_s", "trajectory_error_m", "final_error_m",
            "penetration_m", "energy_error_J", "gradient_error")  # fmt: skip
    for scene, s in summary["scenes"].items():
        if "no_converged_reference" in s:
            lines += [f"## {scene}", "", "No converged reference (the exact plant at the "
                      f"reference step took an unconverged step): {s['no_converged_reference']}",
                      ""]  # fmt: skip
            continue
        ref, tiers = s["reference"], []
        for tier in _TIERS:
            best = [s["cheapest"][f"{who}@{tier:g}"] for who in ("ours", "drake")]
            tiers.append([f"{tier:g} m", *(cell for b in best for cell in (
                b["label"] if b else "none", _fmt(b and b["cost_s_per_s"]),
                _fmt(b and b["gradient_error"])))])  # fmt: skip
        lines += [
            f"## {scene} ({s['duration_s']:g} s simulated; reference: ours, exact, at "
            f"h = {1e3 * ref['time_step']:g} ms, its own trajectory error at twice the step "
            f"{_fmt(ref['self_error_at_twice_the_step']['trajectory_error_m'])} m)", "",
            *outputs.markdown_table(
                ["trajectory error at most", "ours: cheapest setting", "s per simulated s",
                 "gradient error", "Drake: cheapest setting", "s per simulated s",
                 "gradient error"], tiers), "",
            *outputs.markdown_table(
                ["setting", "s per sim. s", "with gradient", "trajectory error (m)",
                 "final error (m)", "penetration (m)", "energy error (J)", "gradient error",
                 "unconverged steps"],
                [[r["label"], *(_fmt(r[k]) for k in keys), r["unconverged_steps"]]
                 for r in s["rows"]]), "",
        ]  # fmt: skip
    return "\n".join(lines)


_STYLE = {"exact": ("C0", "o"), "bs": ("C1", "s"), "abs": ("C2", "^"), "gaussian": ("C4", "v"),
          "sap": ("C3", "D"), "similar": ("C5", "P"), "lagged": ("C7", "X")}  # fmt: skip


def plot(summary: dict, path: Path) -> None:
    from matplotlib.ticker import NullFormatter

    scenes = [k for k, v in summary["scenes"].items() if "rows" in v]
    measures = (
        ("trajectory_error_m", "cost_s_per_s", "trajectory error (m)", "of the rollout"),
        ("gradient_error", "gradient_cost_s_per_s", "gradient error (relative)",
         "with the gradient"),
    )  # fmt: skip
    fig, axes = outputs.pyplot().subplots(
        len(scenes), 2, figsize=(11, 4.2 * len(scenes)), squeeze=False
    )
    for i, scene in enumerate(scenes):
        for j, (err, cost, ylabel, what) in enumerate(measures):
            ax = axes[i, j]
            for family, (color, marker) in _STYLE.items():
                rows = [r for r in summary["scenes"][scene]["rows"] if r["family"] == family]
                if rows:
                    h = np.array([r["time_step"] for r in rows])
                    ax.scatter([r[cost] for r in rows], [max(r[err], 1e-12) for r in rows],
                               s=20 + 1.2e4 * h, c=color, marker=marker, alpha=0.75,
                               label=Setting(family, 0.01).name)  # fmt: skip
            ax.set(xscale="log", yscale="log", xlabel=f"cost {what} (s per simulated s)",
                   ylabel=ylabel, title=f"{scene}: {ylabel} against cost")  # fmt: skip
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.grid(True, which="both", alpha=0.3)
        axes[i, 0].legend(fontsize=7, title="marker size: time step", title_fontsize=7)
    outputs.save_figure(fig, path)
