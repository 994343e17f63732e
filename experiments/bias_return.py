"""FOPG training under barrier smoothing with mu = 1e-10, mu = 1e-2 and the adaptive
contact-aware design: return and gradient bias along training (Zhang et al. 2023, section 8.4,
Figure 5).

The paper runs this on the Dojo half-cheetah. Here the full-size run is on a cheap contact task
of the point-mass family, and a small version runs on our planar half-cheetah scene
(``drake_abs/scenes/half_cheetah.yaml``, rigid-body ``ComplementarityStepper``), whose step costs
about a millisecond per sample in Python:

- ``hopping_ball``: the hopping ball of :mod:`drake_abs.tasks.hopping_ball` (2-D point
  mass, h = 0.01 s, inelastic ground, Gaussian action noise sigma = 1 N), starting from the
  hopping spring policy; the reward asks for p = (0.5, 0.2) m (and a little effort), so the ball
  must stop hopping, move sideways and hold a height 0.2 m above the ground. Linear policy
  u = K x + k (10 parameters).
- ``half_cheetah``: run forward: track v_x = 1 m/s while keeping the torso's height and pitch,
  linear feedback around the standing posture (114 parameters), zero at the start; action
  noise sigma = 0.3 N m, Adam step 0.005.
- ``gym_half_cheetah``: the paper's task on gymnasium's HalfCheetah-v5 model on our plant
  (:func:`drake_abs.tasks.locomotion.locomotion_task`): v5's reward (forward velocity minus
  control cost, a reward of transitions), a linear policy of v5's observation (17 -> 6, 108
  parameters, zero at the start), actions in [-1, 1] with noise sigma = 0.1.

Each design is trained with Adam on FOPG estimates (Zhang et al. 2023, eq. 4.1) from the same
seeds. The rollouts of training use the design's own (softened) dynamics with the frozen
gradient, as Algorithm 1 does. Measured:

- the **return** of the current policy on the EXACT model (hard contact), with fixed evaluation
  noise (common random numbers across designs and iterations), every ``eval_every`` iterations;
  mean and spread (standard deviation, min, max) over seeds;
- at the ``checkpoints``, the design's FOPG **variance** and **bias** against the exact
  objective's reference gradient at the current theta (:mod:`drake_abs.policy.gradient_stats`:
  a bias below the noise of the measurement is reported as unresolved, not as a number).

A training run whose rollouts leave the finite numbers stops there and is reported
(``diverged_at``, seed: iteration); the return statistics are then over the seeds still running
(``seeds_evaluated``). Unconverged solver steps during training are counted.

Outputs in ``out``: ``figure5_<task>.png`` ((a) return, (b) bias), ``summary.json``.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from drake_abs.contact.smoothing import ContactAware, Exact, Fixed, Smoothing
from drake_abs.contact.unconverged import UnconvergedStepError, UnconvergedStepWarning
from drake_abs.experiments import outputs
from drake_abs.lcp.ipm import LCPConvergenceWarning
from drake_abs.policy.estimators import PolicyObjective, first_order
from drake_abs.policy.gradient_stats import measure_bias, measure_variance, reference_gradient
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.policy.training import Adam, train
from drake_abs.tasks.hopping_ball import hopping_ball, spring_theta

NAME = "bias-return"
TASKS = ("hopping_ball", "half_cheetah", "gym_half_cheetah")

DESIGNS: dict[str, Smoothing] = {
    "BS mu=1e-10": Fixed(1e-10),
    "BS mu=1e-2": Fixed(1e-2),
    "ABS contact-aware": ContactAware(mu_max=1e-2, length=0.05),
}


@dataclass(frozen=True)
class TrainingSize:
    """Sizes of one task's run. ``samples``: rollouts per FOPG estimate; ``checkpoints``:
    iterations where the variance and bias are measured (``bias_batches`` estimates, and a
    reference of ``reference_samples`` rollouts per estimator); ``eval_rollouts``: exact-model
    rollouts of the return, every ``eval_every`` iterations."""

    iterations: int
    seeds: tuple[int, ...]
    samples: int
    horizon: int
    learning_rate: float
    checkpoints: tuple[int, ...]
    bias_batches: int
    reference_samples: int
    reference_batches: int
    eval_rollouts: int
    eval_every: int


@dataclass(frozen=True)
class Config:
    """One :class:`TrainingSize` per task (None skips the task)."""

    hopping_ball: TrainingSize | None = field(default_factory=lambda: TrainingSize(
        iterations=60, seeds=(0, 1, 2, 3), samples=32, horizon=150, learning_rate=1.0,
        checkpoints=(0, 15, 30, 60), bias_batches=16, reference_samples=4096,
        reference_batches=16, eval_rollouts=256, eval_every=3))  # fmt: skip
    half_cheetah: TrainingSize | None = field(default_factory=lambda: TrainingSize(
        iterations=20, seeds=(0, 1), samples=8, horizon=40, learning_rate=0.05,
        checkpoints=(0, 20), bias_batches=6, reference_samples=96, reference_batches=6,
        eval_rollouts=16, eval_every=5))  # fmt: skip
    gym_half_cheetah: TrainingSize | None = field(default_factory=lambda: TrainingSize(
        iterations=30, seeds=(0, 1, 2), samples=16, horizon=60, learning_rate=0.01,
        checkpoints=(0, 15, 30), bias_batches=8, reference_samples=512, reference_batches=8,
        eval_rollouts=32, eval_every=3))  # fmt: skip
    eval_seed: int = 12345

    @classmethod
    def test_size(cls) -> Config:
        return cls(
            hopping_ball=TrainingSize(
                iterations=4, seeds=(0, 1), samples=8, horizon=60, learning_rate=1.0,
                checkpoints=(0, 4), bias_batches=4, reference_samples=128, reference_batches=4,
                eval_rollouts=16, eval_every=2),
            half_cheetah=None,
            gym_half_cheetah=TrainingSize(
                iterations=2, seeds=(0,), samples=4, horizon=6, learning_rate=0.01,
                checkpoints=(0, 2), bias_batches=2, reference_samples=16, reference_batches=2,
                eval_rollouts=4, eval_every=1),
        )  # fmt: skip


class Task:
    """A training task: ``objective(smoothing, horizon)`` (the rollouts of training use the
    design's own dynamics with the frozen gradient, Zhang et al. 2023, Algorithm 1) and the
    initial ``theta0``."""

    def __init__(self, name: str):
        if name not in TASKS:
            raise ValueError(f"task must be one of {TASKS}; got {name!r}")
        self.name = name
        if name == "hopping_ball":
            # stop hopping, move sideways to p = (0.5, 0.2) m, a little effort
            reward = QuadraticReward(Q=np.diag([1.0, 1.0, 0.0, 0.0]), R=1e-4 * np.eye(2),
                                     x_goal=np.array([0.5, 0.2, 0.0, 0.0]))  # fmt: skip
            self.objective = lambda smoothing, horizon: hopping_ball(
                smoothing, "frozen", horizon, 1.0, reward=reward, x0=(0.0, 0.3, 0.0, 0.0)
            )
            self.theta0 = spring_theta()
        elif name == "gym_half_cheetah":
            from drake_abs.tasks.locomotion import locomotion_task

            def objective(smoothing, horizon):
                task = locomotion_task("half_cheetah", smoothing=smoothing, gradient="frozen")
                # sigma in action units (actions in [-1, 1])
                return task.objective(LinearPolicy(task.n_obs, task.nu), horizon, 0.1)

            self.objective = objective
            self.theta0 = np.zeros(objective(None, 1).policy.n_params)
        else:
            self.objective, self.theta0 = _scene_half_cheetah()


def _scene_half_cheetah():
    """Our planar half-cheetah scene: track v_x = 1 m/s keeping the torso's height and pitch,
    linear feedback around the standing posture, zero at the start."""
    from drake_abs.multibody import build_scene_model

    model = build_scene_model("half_cheetah")
    nq, nv = len(model.q0), len(model.v0)
    nu = model.plant.num_actuators()
    x0 = np.concatenate([model.q0, model.v0])
    goal = x0.copy()
    goal[nq] = 1.0  # forward speed, m/s
    weights = np.zeros(nq + nv)
    weights[[1, 2, nq]] = (10.0, 1.0, 1.0)  # height, pitch, forward speed
    policy = LinearPolicy(nq + nv, nu, x_ref=tuple(x0))
    reward = QuadraticReward(Q=np.diag(weights), R=1e-3 * np.eye(nu), x_goal=goal)

    def objective(smoothing, horizon):
        # sigma in N m; with 1 N m (the ball's value) the zero policy's light feet spin at ~80
        # rad/s and the first Adam steps drove the state to inf (measured; reported in the notes)
        stepper = model.stepper(smoothing=smoothing, gradient="frozen")
        return PolicyObjective(stepper, policy, reward, x0, horizon, 0.3)

    return objective, np.zeros(policy.n_params)


def train_design(task: Task, smoothing: Smoothing, size: TrainingSize, seed: int) -> dict:
    """Adam on FOPG from ``task.theta0``; returns the log and theta at every iteration.

    A run whose rollouts leave the finite numbers (the policy drove the state to inf or NaN, the
    estimate was not finite, or no rollout of the batch converged) stops there: ``diverged_at``
    is that iteration (else None) and ``thetas`` ends with the last finite-gradient theta."""
    obj = task.objective(smoothing, size.horizon)
    thetas, rows = [], []

    def estimator(theta, rng):
        thetas.append(theta.copy())
        est = first_order(obj, theta, rng, size.samples)
        rows.append({"unconverged_steps": est.unconverged, "dropped_rollouts": est.dropped})
        return est

    try:
        run = train(estimator, task.theta0, Adam(size.learning_rate), size.iterations, seed=seed,
                    progress=False)  # fmt: skip
    except (ValueError, FloatingPointError, UnconvergedStepError) as err:
        return {"thetas": thetas[:-1], "rows": rows, "diverged_at": len(thetas) - 1,
                "error": str(err)}  # fmt: skip
    thetas.append(run.theta.copy())
    return {"thetas": thetas, "rows": rows, "diverged_at": None, "error": None}


def _checkpoint(obj, exact, theta, size: TrainingSize, seed: int, k: int, references: dict) -> dict:
    """The design's FOPG variance and its bias against the exact reference at theta (iteration
    k of the run from ``seed``). ``references`` caches the exact references by (seed, k,
    theta): every design starts from the same theta, so iteration 0 shares one."""
    estimator = lambda th, rng: first_order(obj, th, rng, size.samples)  # noqa: E731
    stats = measure_variance(estimator, theta, batches=size.bias_batches,
                             seed=np.random.SeedSequence([seed, k]))  # fmt: skip
    key = (seed, k, np.asarray(theta, dtype=float).tobytes())
    if key not in references:
        references[key] = reference_gradient(
            exact, theta, samples=size.reference_samples, batches=size.reference_batches,
            seed=np.random.SeedSequence([seed, k, 1]),
        )  # fmt: skip
    ref = references[key]
    return {
        "seed": seed, "iteration": k, "variance": stats.trace_variance,
        "variance_se": stats.trace_variance_se,
        "largest_batch_share": stats.largest_batch_share,
        "bias": measure_bias(stats, ref).to_dict(), "reference_method": ref.method,
        "reference_agreement": ref.agreement, "reference_std_error": ref.std_error,
    }  # fmt: skip


def run_task(task: Task, size: TrainingSize, eval_seed: int, bar=None) -> dict:
    """Train every design from every seed; evaluate returns and measure bias at checkpoints.
    ``bar`` (a progress bar) is advanced once per design and seed."""
    if any(c < 0 or c > size.iterations for c in size.checkpoints):
        raise ValueError(f"checkpoints must lie in [0, iterations = {size.iterations}]")
    exact = task.objective(Exact(), size.horizon)
    eval_noise = exact.noise(np.random.default_rng(eval_seed), size.eval_rollouts)

    def exact_return(theta) -> float:
        try:
            return float(exact.rollout(theta, eval_noise, gradient=False).returns.mean())
        except ValueError:  # the policy drives the exact model to non-finite states
            return float("nan")

    eval_iters = sorted(set(range(0, size.iterations + 1, size.eval_every)) | {size.iterations})
    designs, references = {}, {}
    for name, smoothing in DESIGNS.items():
        obj = task.objective(smoothing, size.horizon)
        returns, checkpoints, diverged, errors = [], [], {}, {}
        unconverged, dropped, seconds = 0, 0, 0.0
        for seed in size.seeds:
            if bar is not None:
                bar.set_postfix_str(f"{task.name}: {name}, seed {seed}")
            start = time.perf_counter()
            log = train_design(task, smoothing, size, seed)
            seconds += time.perf_counter() - start
            unconverged += sum(r["unconverged_steps"] for r in log["rows"])
            dropped += sum(r["dropped_rollouts"] for r in log["rows"])
            if log["diverged_at"] is not None:
                diverged[str(seed)] = log["diverged_at"]
                errors[str(seed)] = log["error"]
            thetas = log["thetas"]
            returns.append([exact_return(thetas[k]) if k < len(thetas) else np.nan
                            for k in eval_iters])  # fmt: skip
            for k in [k for k in size.checkpoints if k < len(thetas)]:
                try:
                    checkpoints.append(
                        _checkpoint(obj, exact, thetas[k], size, seed, k, references)
                    )
                except (ValueError, FloatingPointError, UnconvergedStepError) as err:
                    # non-finite or unconverged rollouts: reported
                    checkpoints.append({"seed": seed, "iteration": k, "failed": str(err)})
            if bar is not None:
                bar.update()
        R = np.array(returns)
        alive = np.isfinite(R).sum(axis=0)
        with warnings.catch_warnings():  # all-NaN columns (every seed diverged) stay NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            stats = {"mean": np.nanmean(R, 0), "std": np.nanstd(R, 0), "min": np.nanmin(R, 0),
                     "max": np.nanmax(R, 0)}  # fmt: skip
        designs[name] = {
            "eval_iterations": eval_iters, "returns_per_seed": _json_list(R),
            **{f"return_{k}": _json_list(v) for k, v in stats.items()},
            "seeds_evaluated": alive.tolist(), "diverged_at": diverged,
            "divergence_errors": errors, "checkpoints": checkpoints,
            "bias_by_iteration": _bias_by_iteration(checkpoints, size.checkpoints),
            "unconverged_training_steps": int(unconverged),
            "dropped_training_rollouts": int(dropped), "training_seconds": seconds,
        }  # fmt: skip
    return {"size": asdict(size), "designs": designs}


def _json_list(a: np.ndarray) -> list:
    """NaN (a diverged run) as None in JSON."""
    return np.where(np.isfinite(a), a, None).tolist()


def _bias_by_iteration(checkpoints: list[dict], iterations) -> dict:
    """Per checkpoint iteration: the median resolved bias over seeds, how many seeds resolved
    it, and the median noise floor and variance (None where there is nothing to take)."""

    def median(values: list) -> float | None:
        return float(np.median(values)) if values else None

    out = {}
    for k in iterations:
        cps = [c for c in checkpoints if c["iteration"] == k and "bias" in c]
        resolved = [c["bias"] for c in cps if c["bias"]["resolved"]]
        out[str(k)] = {
            "median_bias": median([b["bias"] for b in resolved]), "resolved": len(resolved),
            "seeds": len(cps), "median_noise": median([c["bias"]["noise"] for c in cps]),
            "median_relative_bias": median([b["relative_bias"] for b in resolved]),
            "median_variance": median([c["variance"] for c in cps]),
        }  # fmt: skip
    return out


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Train and measure every task of ``config``; write the figures and summary.json to ``out``
    (default results/bias-return); ``summary["files"]`` lists them (absolute paths)."""
    config = config or Config()
    out = outputs.results_dir(NAME, out)
    start = time.perf_counter()
    summary = {"config": asdict(config), "tasks": {}, "files": {}}
    sizes = [getattr(config, name) for name in TASKS]
    runs = sum(len(DESIGNS) * len(s.seeds) for s in sizes if s is not None)
    bar = outputs.progress(total=runs, desc="bias-return: training runs")
    with warnings.catch_warnings():
        # counted per step (unconverged_training_steps); the warnings themselves are noise here
        warnings.simplefilter("ignore", LCPConvergenceWarning)
        warnings.simplefilter("ignore", UnconvergedStepWarning)  # counted as dropped_rollouts
        for name in TASKS:
            size = getattr(config, name)
            if size is None:
                continue
            t = time.perf_counter()
            result = run_task(Task(name), size, config.eval_seed, bar)
            result["seconds"] = time.perf_counter() - t
            summary["tasks"][name] = result
            summary["files"][f"figure5_{name}"] = _plot(name, result, out / f"figure5_{name}.png")
    bar.close()
    summary |= {"seconds": time.perf_counter() - start, "folder": str(out)}
    summary["files"] = outputs.file_list({**summary["files"], "summary": out / "summary.json"})
    outputs.write_json(out / "summary.json", summary)
    return summary


def _plot(name: str, result: dict, path: Path) -> Path:
    fig, ax = outputs.pyplot().subplots(1, 2, figsize=(12, 4.5))
    for design, d in result["designs"].items():
        it = np.array(d["eval_iterations"])
        mean = np.array(d["return_mean"], dtype=float)
        std = np.array(d["return_std"], dtype=float)
        line = ax[0].plot(it, mean, label=outputs.readable(design))[0]
        ax[0].fill_between(it, mean - std, mean + std, alpha=0.2, color=line.get_color())
        ks = sorted(int(k) for k in d["bias_by_iteration"])
        b = [d["bias_by_iteration"][str(k)]["median_bias"] for k in ks]
        noise = [d["bias_by_iteration"][str(k)]["median_noise"] or np.nan for k in ks]
        ax[1].plot(ks, [np.nan if x is None else x for x in b], "o-", color=line.get_color(),
                   label=outputs.readable(design))  # fmt: skip
        unresolved = [i for i, x in enumerate(b) if x is None]  # drawn at twice their noise
        ax[1].scatter([ks[i] for i in unresolved], [2 * noise[i] for i in unresolved],
                      marker="v", color=line.get_color())  # fmt: skip
    ax[0].set(xlabel="iteration", ylabel="return on the exact model",
              title=f"(a) Performance ({name})")  # fmt: skip
    ax[1].set(
        xlabel="iteration", ylabel="||E g - grad J_exact|| (median over seeds)", yscale="log",
        title="(b) Gradient bias (triangles: unresolved, below 2 noise)",
    )  # fmt: skip
    ax[0].legend(fontsize=8)
    fig.suptitle("Zhang et al. 2023, Figure 5: barrier smoothing designs for FOPG")
    return outputs.save_figure(fig, path, dpi=130)


def _fmt(x, spec: str = ".4g", none: str = "n/a") -> str:
    return none if x is None else format(x, spec)


def report(summary: dict) -> str:
    lines = [f"FOPG with BS / ABS (Zhang et al. 2023, Figure 5); {summary['seconds']:.0f} s"]
    for task, result in summary["tasks"].items():
        lines.append(f"task {task} ({result['seconds']:.0f} s):")
        for design, d in result["designs"].items():
            it = d["eval_iterations"]
            half = len(it) // 2
            bias = [f"it {k}: {_fmt(b['median_bias'], '.3g', 'unresolved')} ({b['resolved']}/"
                    f"{b['seeds']}; var {_fmt(b['median_variance'])})"
                    for k, b in d["bias_by_iteration"].items()]  # fmt: skip
            mean, std = d["return_mean"], d["return_std"]
            lines.append(
                f"  {design:18s} exact-model return: start {_fmt(mean[0])}, "
                f"it {it[half]} {_fmt(mean[half])} +- {_fmt(std[half])}, "
                f"final {_fmt(mean[-1])} +- {_fmt(std[-1])} "
                f"({d['seeds_evaluated'][-1]} of {len(d['returns_per_seed'])} seeds); "
                f"unconverged steps {d['unconverged_training_steps']} "
                f"(rollouts dropped {d['dropped_training_rollouts']})"
                + (f"; DIVERGED (seed: iteration) {d['diverged_at']}" if d["diverged_at"] else "")
            )
            lines.append("      bias " + "; ".join(bias))
    return "\n".join(lines)


if __name__ == "__main__":
    print(report(run(Config.test_size(), "results/bias-return-test")))
