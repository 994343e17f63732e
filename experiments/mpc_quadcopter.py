"""Gray-box tuning of a QP-MPC on the 12-state quadcopter (Zuliani et al. 2025, section 7, Figures
1-2).

1. System identification: 100 closed-loop trajectories near the target under a stabilising MPC
   (built on the exact hover linearisation; the policy itself never uses it), inputs perturbed
   by Gaussian noise and clipped to [0, 630] rad/s; (A, B) by least squares in deviations from
   (x_ref, u_ref) (:mod:`drake_abs.mpc.sysid`).
2. The policy: QP-MPC with the identified model, N = 12, slack penalty 25 (linear and
   quadratic), theta = (p_Q, p_R, p_P) initialised at Q = Qc, R = Rc and P from the Riccati
   equation of the identified model (docs/math.md section 9).
3. Closed loop on the nonlinear quadcopter from x_0 (the paper does not state it; we take the
   origin at hover) to x_ref = (-6, -3.5, 0, 0..) over T = 200 steps; cost C and penalty
   300 dist_1 (:mod:`drake_abs.mpc.graybox`).
4. 200 gray-box iterations (eq. 10) for gamma = 0.25, 0.5, 0.75, eta = 1 (model only) and
   eta = 0 (zeroth order only), all from the same theta_0 and with the same random directions;
   200 iterations with the exact gradient (the nonlinear model's own Jacobians in eq. 8a) and
   the same step sizes; and the reference "optimised with perfect model knowledge": L-BFGS-B
   (scipy, box-constrained) on the exact-gradient closed-loop cost, run towards convergence.

Outputs in ``out``: ``figure1_convergence.png`` (tracking cost and constraint violation against
iterations per method), ``figure2_trajectories.png`` (position and attitude of the trained and of
the exact-model controller), ``summary.json`` and, optionally, ``flights.html`` (Meshcat).
The suboptimality of the trained controller (gamma = 0.5, fixed before running) against the
reference is reported beside the paper's 1111.71 vs 1103.04. Every rollout's MPC statuses are
counted (fallback and inaccurate steps) and reported per method.

Step sizes: see :mod:`drake_abs.mpc.graybox` (the printed formula is checked and reported too).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from drake_abs.engine import rollout
from drake_abs.experiments.outputs import (
    file_list,
    progress,
    pyplot,
    results_dir,
    save_figure,
    write_json,
)
from drake_abs.mpc.graybox import (
    GrayBoxResult,
    Schedule,
    TrackingCost,
    graybox_optimize,
    step_size_as_printed,
)
from drake_abs.mpc.qp_mpc import MpcSpec, QpMpc, riccati_terminal_cost, theta_from_cost
from drake_abs.mpc.sysid import LinearModel, identify_linear_model
from drake_abs.mpc.tuning import ClosedLoopEvaluator, lbfgs_tune
from drake_abs.policy.controls import TimeVaryingController
from drake_abs.tasks import quadcopter as qc

NAME = "mpc-quadcopter"
PAPER_TRAINED_COST = 1111.71
PAPER_EXACT_MODEL_COST = 1103.04
X_REF, STAGE_Q, STAGE_R = qc.TRACKING_TARGET, qc.TRACKING_STAGE_Q, qc.TRACKING_STAGE_R
TERMINAL_P = qc.TRACKING_TERMINAL_P
SYSID_SPREAD = (0.5, 0.5, 0.5, 0.2, 0.2, 0.2, 0.1, 0.1, 0.1, 0.05, 0.05, 0.05)


@dataclass(frozen=True)
class Config:
    """The experiment's settings (paper values unless noted).

    Attributes:
        iterations: gray-box updates per method (200).
        steps: closed-loop horizon T (200).
        horizon: MPC horizon N (12).
        gammas: eta_k = 1 / (k + 1)^gamma schedules (0.25, 0.5, 0.75).
        baselines: also run eta = 1 (model only) and eta = 0 (zeroth order only).
        exact_model: also tune with the exact gradient: the gray-box schedule with eta = 1, and
            the reference "optimised with perfect model knowledge", L-BFGS-B for at most
            ``reference_iterations`` iterations.
        trained_gamma: the hybrid reported as "the trained controller" (chosen before running:
            the middle schedule).
        x0: initial state (not stated in the paper: hover at the origin).
        sysid_trajectories, sysid_length: closed-loop runs (100) and their steps.
        sysid_input_noise: std (rad/s) of the Gaussian input perturbation during identification.
        sysid_spread: half-widths of the uniform initial states around x_ref.
        delta: eq. 9's smoothing radius (1e-4). theta_bound: ``Theta = {|theta_i| <= bound}``.
        penalty_weight: 300. slack_penalty: 25 (linear and quadratic).
        seed: seeds identification noise and the directions v_k.
        meshcat: also write the Meshcat HTML of the two flights.
    """

    iterations: int = 200
    steps: int = 200
    horizon: int = 12
    gammas: tuple[float, ...] = (0.25, 0.5, 0.75)
    baselines: bool = True
    exact_model: bool = True
    reference_iterations: int = 200
    trained_gamma: float = 0.5
    x0: tuple[float, ...] = (0.0,) * 12
    sysid_trajectories: int = 100
    sysid_length: int = 20
    sysid_input_noise: float = 3.0
    sysid_spread: tuple[float, ...] = SYSID_SPREAD
    delta: float = 1e-4
    theta_bound: float = 100.0
    penalty_weight: float = qc.TRACKING_PENALTY
    slack_penalty: float = 25.0
    seed: int = 0
    meshcat: bool = True
    params: qc.QuadcopterParams = field(default_factory=qc.QuadcopterParams)

    @classmethod
    def test_size(cls) -> Config:
        """A few iterations on a short closed loop (seconds; what CI runs)."""
        return cls(
            iterations=2, steps=30, sysid_trajectories=10, sysid_length=10, reference_iterations=1
        )

    def __post_init__(self):
        counts = ("iterations", "steps", "horizon", "sysid_trajectories", "sysid_length",
                  "reference_iterations")  # fmt: skip
        for name in counts:
            value = getattr(self, name)
            if int(value) != value or value < (0 if name == "iterations" else 1):
                raise ValueError(f"Config.{name} must be a positive integer; got {value!r}")
        if self.trained_gamma not in self.gammas:
            raise ValueError(f"Config.trained_gamma {self.trained_gamma} is not in gammas")
        if len(self.x0) != 12 or len(self.sysid_spread) != 12:
            raise ValueError("Config.x0 and Config.sysid_spread need 12 entries")


def identify(config: Config, rng: np.random.Generator) -> tuple[LinearModel, dict]:
    """Step 1: closed-loop data near the target and the least-squares model."""
    prm = config.params
    x_ref, u_ref = np.array(X_REF), prm.hover_input()
    x_min, x_max = qc.QuadcopterConstraints().state_bounds()
    u_min, u_max = qc.QuadcopterConstraints().input_bounds()
    A_h, B_h = qc.hover_linearization(prm)
    P, _ = riccati_terminal_cost(A_h, B_h, np.diag(STAGE_Q), np.diag(STAGE_R))
    spec = MpcSpec(A_h, B_h, config.horizon, x_ref, u_ref, u_min, u_max, x_min, x_max)
    stabilising = QpMpc(spec, theta_from_cost(STAGE_Q, STAGE_R, P))
    # one engine rollout per trajectory (the MPC's warm start runs through them in order): the
    # stabilising MPC plus seeded input noise, clipped to the rotor limits
    fallbacks, runs = [], []
    spread, L = np.asarray(config.sysid_spread), config.sysid_length
    for _ in range(config.sysid_trajectories):
        x0 = x_ref + spread * rng.uniform(-1.0, 1.0, 12)
        noise = rng.normal(0.0, config.sysid_input_noise, (L, 4))

        def control(t, x, noise=noise):
            sol = stabilising.solve(x[0])
            fallbacks.append(sol.fallback)
            return np.clip(sol.u0 + noise[t], u_min, u_max)

        policy = TimeVaryingController(control, 12, 4)
        runs.append(rollout(qc.QuadcopterStepper(prm), policy, np.zeros(0), x0,
                            np.zeros((1, L, 4)), sigma=0.0, gradient=False))  # fmt: skip
    X = np.concatenate([r.x[0, :-1] for r in runs])
    Xn = np.concatenate([r.x[0, 1:] for r in runs])
    U = np.concatenate([r.u[0] for r in runs])
    model = identify_linear_model(X, U, Xn, x_ref, u_ref)
    info = {
        "transitions": model.samples,
        "rank": model.rank,
        "residual_rms_max": float(model.residual_rms.max()),
        "max_abs_A_minus_hover_jacobian": float(np.abs(model.A - A_h).max()),
        "max_abs_B_minus_hover_jacobian": float(np.abs(model.B - B_h).max()),
        "max_abs_B_hover": float(np.abs(B_h).max()),
        "stabilising_mpc_fallback_steps": int(np.sum(fallbacks)),
    }
    return model, info


def build_problem(config: Config, rng: np.random.Generator):
    """Steps 1-2: the MPC spec on the identified model, the cost, theta_0 and the
    identification's summary."""
    model, sysid = identify(config, rng)
    x_ref, u_ref = np.array(X_REF), config.params.hover_input()
    con = qc.QuadcopterConstraints()
    (x_min, x_max), (u_min, u_max) = con.state_bounds(), con.input_bounds()
    slack = {"slack_linear": config.slack_penalty, "slack_quadratic": config.slack_penalty}
    spec = MpcSpec(model.A, model.B, config.horizon, x_ref, u_ref, u_min, u_max, x_min, x_max,
                   **slack)  # fmt: skip
    Q, R = np.diag(STAGE_Q), np.diag(STAGE_R)
    P, _ = riccati_terminal_cost(model.A, model.B, Q, R)
    cost = TrackingCost(Q, R, np.diag(TERMINAL_P), x_ref, u_ref, x_min, x_max,
                        config.penalty_weight)  # fmt: skip
    return spec, cost, theta_from_cost(STAGE_Q, STAGE_R, P), sysid


def _evaluator(config, spec, cost, theta0, source="model") -> ClosedLoopEvaluator:
    """A fresh controller (its own OSQP warm start) on the quadcopter, counting MPC statuses."""
    plant = qc.QuadcopterStepper(config.params)
    return ClosedLoopEvaluator(QpMpc(spec, theta0), config.x0, config.steps, plant, cost, source)


def _tune(config, spec, cost, theta0, schedule, source, label) -> tuple[GrayBoxResult, dict]:
    evaluate = _evaluator(config, spec, cost, theta0, source)
    bar = progress(total=config.iterations + 1, desc=method_label(label))

    def on_iterate(rec):
        bar.set_postfix(total=f"{rec.total:.1f}")
        bar.update()

    start = time.perf_counter()
    result = graybox_optimize(
        evaluate, theta0, iterations=config.iterations, schedule=schedule,
        rng=np.random.default_rng(config.seed + 1), delta=config.delta, bound=config.theta_bound,
        progress=on_iterate,
    )  # fmt: skip
    bar.close()
    return result, {"seconds": time.perf_counter() - start, **evaluate.counts()}


def _method_summary(result: GrayBoxResult, stats: dict) -> dict:
    trace = result.trace
    totals = [r.total for r in trace]
    best = int(np.argmin(totals))
    series = ("tracking_cost", "violation", "total", "direction_norm")
    return {
        "initial_total": trace[0].total,
        "final_tracking_cost": trace[-1].tracking_cost,
        "final_violation": trace[-1].violation,
        "final_total": trace[-1].total,
        "best_total": float(totals[best]),
        "best_iteration": trace[best].k,
        **stats,
        **{key: [getattr(r, key) for r in trace] for key in series},
        "theta_final": result.theta.tolist(),
    }


def _exact_reference(config, spec, cost, theta0):
    """Tuning with perfect model knowledge, run towards convergence: box-constrained L-BFGS-B
    on the total cost with the exact closed-loop gradient (eq. 8, true Jacobians)."""
    evaluate = _evaluator(config, spec, cost, theta0, "exact")
    bar = progress(total=config.reference_iterations, desc="exact model, L-BFGS-B")

    def on_iteration(total):
        bar.set_postfix(total=f"{total:.1f}")
        bar.update()

    start = time.perf_counter()
    res, history = lbfgs_tune(
        evaluate, theta0, bound=config.theta_bound, iterations=config.reference_iterations,
        callback=on_iteration,
    )  # fmt: skip
    bar.close()
    final = evaluate(res.x, False)
    info = {
        "method": "L-BFGS-B on the exact-gradient closed-loop cost",
        "iterations": int(res.nit),
        "evaluations": int(res.nfev),
        "message": str(res.message),
        "final_tracking_cost": final.tracking_cost,
        "final_violation": final.violation,
        "final_total": final.total,
        "total": history,
        "seconds": time.perf_counter() - start,
        **evaluate.counts(),
        "theta_final": res.x.tolist(),
    }
    return final, info


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Run the experiment (seeded), write its figures and summary to ``out`` (default
    results/mpc-quadcopter); returns the summary dict (``summary["files"]``: absolute paths)."""
    config = config or Config()
    out = results_dir(NAME, out)
    start = time.perf_counter()
    spec, cost, theta0, sysid = build_problem(config, np.random.default_rng(config.seed))
    methods = [(f"gamma={g:g}", Schedule(gamma=g), "model") for g in config.gammas]
    if config.baselines:
        methods += [("model only (eta=1)", Schedule(eta=1.0), "model"),
                    ("zeroth order only (eta=0)", Schedule(eta=0.0), "model")]  # fmt: skip
    if config.exact_model:
        methods.append(("exact model", Schedule(eta=1.0, name="exact model"), "exact"))
    results: dict[str, GrayBoxResult] = {}
    summary_methods = {}
    for label, schedule, source in progress(methods, desc=f"{NAME}: methods"):
        results[label], stats = _tune(config, spec, cost, theta0, schedule, source, label)
        summary_methods[label] = _method_summary(results[label], stats)
    reference = reference_info = None
    if config.exact_model:
        reference, reference_info = _exact_reference(config, spec, cost, theta0)

    # the printed step-size formula, one model-based step from theta_0 (see drake_abs.mpc.graybox)
    evaluate = _evaluator(config, spec, cost, theta0)
    r0 = evaluate(theta0, True)
    alpha_1 = step_size_as_printed(1)
    theta1 = np.clip(theta0 - alpha_1 * r0.gradient, -config.theta_bound, config.theta_bound)
    printed = {"alpha_1": alpha_1, "total_before": r0.total,
               "total_after_one_step": evaluate(theta1, False).total}  # fmt: skip

    trained_label = f"gamma={config.trained_gamma:g}"
    trained = results[trained_label]
    initial, last = trained.trace[0], trained.trace[-1]
    paper = {"trained": PAPER_TRAINED_COST, "exact_model": PAPER_EXACT_MODEL_COST,
             "suboptimality": PAPER_TRAINED_COST / PAPER_EXACT_MODEL_COST - 1.0}  # fmt: skip
    comparison = {"trained_controller": trained_label, "paper": paper}
    files = file_list({"figure1": out / "figure1_convergence.png", "summary": out / "summary.json"})
    _figure1(summary_methods, reference_info, Path(files["figure1"]))
    if config.exact_model:
        same = results["exact model"].trace[-1].total
        comparison["ours"] = {
            "trained": last.total,
            "exact_model": reference.total,
            "suboptimality": last.total / reference.total - 1.0,
            "exact_model_same_schedule": same,
            "suboptimality_vs_same_schedule": last.total / same - 1.0,
            "trained_tracking_cost": last.tracking_cost,
            "exact_model_tracking_cost": reference.tracking_cost,
            "initial": initial.total,
        }
        files["figure2"] = str(out / "figure2_trajectories.png")
        _figure2(trained.final.x, reference.x, config.params.time_step, Path(files["figure2"]))
        if config.meshcat:
            from drake_abs.diagrams.quadcopter_visualization import record_quadcopter_html

            flights = {"trained": trained.final.x, "exact_model": reference.x}
            files["meshcat_html"] = str(record_quadcopter_html(
                flights, out / "flights.html", time_step=config.params.time_step,
                target=np.array(X_REF[:3])))  # fmt: skip
    summary = {
        "config": asdict(config),
        "assumptions": {
            "x0": "not stated in the paper; hover at the origin",
            "step_size": "alpha_k = 5e-5 (log k + 2) / (k + 1)^0.75 (printed formula diverges)",
            "theta_set": f"box |theta_i| <= {config.theta_bound} (not stated in the paper)",
            "slack_penalty": f"{config.slack_penalty} (s's + 1's)",
            "exact_model_tuning": "reference: L-BFGS-B with the exact gradient (towards "
            "convergence); also the gray-box schedule with eta = 1 and the exact gradient",
        },
        "sysid": sysid,
        "initial": {key: getattr(initial, key) for key in ("tracking_cost", "violation", "total")},
        "methods": summary_methods,
        "exact_model_reference": reference_info,
        "comparison": comparison,
        "printed_step_size_check": printed,
        "seconds": time.perf_counter() - start,
        "folder": str(out),
        "files": file_list(files),
    }
    write_json(files["summary"], summary, finite=True)
    return summary


def method_label(label: str) -> str:
    """The legend entry of a method key (``"gamma=0.5"`` -> ``"gray-box, gamma = 0.5"``)."""
    if label.startswith("gamma="):
        return f"gray-box, gamma = {label.split('=', 1)[1]}"
    return label.replace("(eta=", "(eta = ")


def _figure1(methods: dict, reference: dict | None, path: Path) -> None:
    fig, ax = pyplot().subplots(1, 2, figsize=(12, 4.2))
    for label, m in methods.items():
        k = np.arange(1, len(m["total"]) + 1)
        style = {"color": "k", "ls": "--"} if label == "exact model" else {}
        ax[0].plot(k, m["tracking_cost"], label=method_label(label), **style)
        ax[1].plot(k, m["violation"], label=method_label(label), **style)
    if reference is not None:
        ax[0].axhline(reference["final_tracking_cost"], color="k", ls=":",
                      label="exact model, L-BFGS-B")  # fmt: skip
        ax[1].axhline(reference["final_violation"], color="k", ls=":")
    ax[0].set(xlabel="iteration k", ylabel="tracking cost C(theta_k)", title="tracking cost")
    ax[1].set(xlabel="iteration k", ylabel="dist_1(x, X^{T+1}) (state units)",
              title="constraint violation")  # fmt: skip
    ax[1].set_yscale("symlog", linthresh=1e-3)
    ax[1].set_ylim(bottom=0.0)
    ax[0].legend(fontsize=8)
    fig.suptitle("Zuliani et al. 2025, Figure 1 analogue: quadcopter, gray-box tuning")
    save_figure(fig, path, dpi=130)


def _figure2(trained: np.ndarray, exact: np.ndarray, time_step: float, path: Path) -> None:
    """Position and attitude of the trained and the exact-model flights, states (T + 1, 12)."""
    t = np.arange(trained.shape[0]) * time_step
    fig, ax = pyplot().subplots(1, 2, figsize=(12, 4.2))
    for a, first, names in (
        (ax[0], 0, ("p_x", "p_y", "p_z")),
        (ax[1], 6, ("roll", "pitch", "yaw")),
    ):
        for i, name in enumerate(names):
            a.plot(t, trained[:, first + i], color=f"C{i}", label=f"{name}, trained")
            a.plot(t, exact[:, first + i], color=f"C{i}", ls="-.", label=f"{name}, exact model")
        a.legend(fontsize=7, ncol=2)
    ax[0].set(xlabel="t (s)", ylabel="position (m)", title="position")
    ax[1].set(xlabel="t (s)", ylabel="angle (rad)", title="attitude")
    fig.suptitle("Zuliani et al. 2025, Figure 2 analogue: trained (solid) vs optimised with the "
                 "exact model (dash-dot)")  # fmt: skip
    save_figure(fig, path, dpi=130)


def report(summary: dict) -> str:
    """A text summary: per-method results and the comparison with the paper."""
    lines = ["MPC quadcopter (Zuliani et al. 2025): gray-box tuning of the QP-MPC cost"]
    s = summary["sysid"]
    lines.append(
        f"  system identification: {s['transitions']} transitions, rank {s['rank']}, one-step "
        f"residual rms <= {s['residual_rms_max']:.2e}; |A - A_hover|max "
        f"{s['max_abs_A_minus_hover_jacobian']:.2e}, |B - B_hover|max "
        f"{s['max_abs_B_minus_hover_jacobian']:.2e}"
    )
    ini = summary["initial"]
    lines.append(
        f"  theta_0: tracking cost {ini['tracking_cost']:.2f}, violation {ini['violation']:.4f}, "
        f"total {ini['total']:.2f}"
    )
    lines.append(
        f"  {'method':28s} {'final C':>10s} {'final viol':>11s} {'final total':>12s} "
        f"{'best total (k)':>18s} {'fallback/inacc. steps':>22s} {'time':>7s}"
    )
    for label, m in summary["methods"].items():
        lines.append(
            f"  {label:28s} {m['final_tracking_cost']:10.2f} {m['final_violation']:11.4f} "
            f"{m['final_total']:12.2f} {m['best_total']:11.2f} ({m['best_iteration']:3d}) "
            f"{m['fallback_steps']:12d} / {m['inaccurate_steps']:<7d} {m['seconds']:6.0f}s"
        )
    ref = summary.get("exact_model_reference")
    if ref:
        lines.append(
            f"  {'exact model, L-BFGS-B':28s} {ref['final_tracking_cost']:10.2f} "
            f"{ref['final_violation']:11.4f} {ref['final_total']:12.2f} "
            f"{'(' + str(ref['iterations']) + ' it, ' + str(ref['evaluations']) + ' ev)':>18s} "
            f"{ref['fallback_steps']:12d} / {ref['inaccurate_steps']:<7d} {ref['seconds']:6.0f}s"
            f"  [{ref['message']}]"
        )
    c = summary["comparison"]
    p = c["paper"]
    if "ours" in c:
        o = c["ours"]
        lines.append(
            f"  trained ({c['trained_controller']}) vs optimised with the exact model, final total "
            f"cost: ours {o['trained']:.2f} vs {o['exact_model']:.2f} "
            f"({100 * o['suboptimality']:+.2f} %); paper {p['trained']:.2f} vs "
            f"{p['exact_model']:.2f} ({100 * p['suboptimality']:+.2f} %)"
        )
        lines.append(
            f"  (against exact-gradient tuning on the same schedule: {o['trained']:.2f} vs "
            f"{o['exact_model_same_schedule']:.2f}, "
            f"{100 * o['suboptimality_vs_same_schedule']:+.2f} %)"
        )
    pr = summary["printed_step_size_check"]
    lines.append(
        f"  step size as printed (alpha_1 = {pr['alpha_1']:.3f}): one model step takes the total "
        f"from {pr['total_before']:.1f} to {pr['total_after_one_step']:.3g}"
    )
    lines.append(f"  {summary['seconds']:.0f} s in all")
    return "\n".join(lines)
