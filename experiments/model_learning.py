"""Learning our complementarity model's parameters from data that no one here wrote (Zhang et
al. 2023, section 6 and its model-learning figure; Bianchini et al. 2022's losses), against a
neural-network dynamics model trained on the same data.

For each scene (the pushed box, gymnasium's hopper and half-cheetah) and each data source
(Drake's MultibodyPlant with the SAP solver, MuJoCo), trajectories under random and scripted
policies are collected (:mod:`drake_abs.experiments.transition_sources`) and split by episode
into training and test sets. Then, for each training-set size:

1. our model's parameters theta (the ground height, one friction coefficient for every contact,
   each body's mass, the damping of each joint the model file damps) start from values off the
   model file's (seeded: the ground ``ground_offset`` m higher, the others scaled by factors
   within ``1 +- perturbation``), and are fitted

   - by random search on eq. 6.1 (the explicit loss through the exact model): the paper's way,
   - by L-BFGS-B on the explicit loss through the model with adaptive barrier smoothing,
   - by L-BFGS-B on the naive-implicit loss (the explicit loss of the exact model),
   - by L-BFGS-B on the violation-implicit loss (``eps``);

2. an ensemble of neural networks (:class:`drake_abs.policy.mbpo.MlpEnsemble`: least squares
   plus a tanh MLP residual, as our MBPO baseline) is fitted to the same transitions;

3. each model predicts the test trajectories open loop from their recorded start state and
   inputs, and the state prediction error is reported against the horizon: the root mean square
   over the state's coordinates of the error divided by that coordinate's standard deviation in
   the data (1 = as far off as the data's own spread), averaged over test windows. The models
   with the model file's parameters ("file") and with the starting parameters ("start") are
   reported beside them.

The recovered parameters are reported beside the model file's: with SAP data the file's values
are the data's own masses and damping (the SAP twin is built from the same file), with MuJoCo
data too (the gymnasium scenes load gymnasium's MJCF files); the contact models differ (SAP's
and MuJoCo's contact are compliant and convex, ours rigid), so the ground height and friction
that fit best need not be the file's.

Outputs in ``out``: ``summary.json``, ``parameters.csv`` (recovered theta per fit),
``prediction_error.csv`` (error against horizon per model, data size), ``prediction_error.png``
and ``data_size.png``.
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from drake_abs.contact.smoothing import ContactAware, Exact
from drake_abs.experiments._common import file_list, progress, results_dir
from drake_abs.learning.fitting import fit_gradient, fit_random_search
from drake_abs.learning.scene_losses import ModelLoss, learned_values, stepper_at

NAME = "model-learning"
SCENES = ("box_push", "gym_hopper", "gym_half_cheetah")
SOURCES = ("sap", "mujoco")
FITS = ("random_search", "explicit", "naive_implicit", "violation_implicit")


@dataclass(frozen=True)
class Config:
    """Sizes. ``train_episodes``: the training-set sizes (episodes of ``steps`` steps, half
    under random inputs, half scripted); ``eps``: the violation loss's relaxation (larger:
    looser complementarity); ``contact_aware``: (mu_max, length m) of the smoothing the explicit
    gradient fit uses (larger mu: smoother)."""

    scenes: tuple[str, ...] = SCENES
    sources: tuple[str, ...] = SOURCES
    fits: tuple[str, ...] = FITS
    train_episodes: tuple[int, ...] = (2, 8)
    test_episodes: int = 4
    steps: int = 100
    horizon: int = 25
    seed: int = 0
    ground_offset: float = 0.02
    perturbation: float = 0.3
    eps: float = 1e-3
    contact_aware: tuple[float, float] = (1e-3, 0.02)
    search_iterations: int = 15
    search_directions: int = 4
    gradient_iterations: int = 30
    nn_ensemble: int = 3
    nn_hidden: tuple[int, ...] = (64, 64)
    nn_epochs: int = 100
    max_transitions: int = 800

    @classmethod
    def test_size(cls) -> Config:
        return cls(scenes=("box_push", "gym_hopper"), train_episodes=(1,), test_episodes=1,
                   steps=12, horizon=4, search_iterations=2, search_directions=2,
                   gradient_iterations=3, nn_ensemble=1, nn_hidden=(8,), nn_epochs=2,
                   max_transitions=24)  # fmt: skip


def collect(scene: str, source: str, config: Config) -> tuple:
    """The scene's transitions from ``source``: ``(random, scripted)``, each of
    ``max(train_episodes) + test_episodes`` episodes (seeded), the first under uniformly random
    inputs within the effort limits, the second under the scene's scripted policy (a gait, a
    push profile). gymnasium's Hopper runs without its termination, so that every episode has
    its ``steps`` steps."""
    from drake_abs.experiments import transition_sources as ts

    episodes = max(config.train_episodes) + config.test_episodes
    make = ts.sap_transitions if source == "sap" else ts.mujoco_transitions
    options = {}
    if source == "mujoco" and scene == "gym_hopper":
        options["env_options"] = {"terminate_when_unhealthy": False}
    seed = config.seed * 1000 + SCENES.index(scene) * 10 + SOURCES.index(source)
    low, high = ts.control_range(scene)
    random_data = make(scene, ts.random_policy(low.size, low, high, seed), episodes,
                       config.steps, seed, **options)  # fmt: skip
    scripted = make(scene, ts.scripted_policy(scene, seed + 1), episodes, config.steps, seed + 1,
                    **options)  # fmt: skip
    return random_data, scripted


def learned_names(stepper) -> list[str]:
    """The parameters fitted: the ground height, one friction coefficient for every contact
    (tied), each body's mass, the damping of each joint the model file damps."""
    names = stepper.parameter_names
    out = ["ground_height"]
    if any(n.startswith("friction[") for n in names):
        out.append("friction[*]")
    out += [n for n in names if n.startswith("mass[")]
    values = stepper.parameter_values()
    out += [n for n, v in zip(names, values, strict=True) if n.startswith("damping[") and v > 0]
    return out


def start_and_scale(names, truth: np.ndarray, config: Config, rng: np.random.Generator):
    """The fits' starting parameters (seeded, off the file's), their scales and bounds."""
    start, scale, lo, hi = [], [], [], []
    for name, value in zip(names, truth, strict=True):
        factor = 1.0 + config.perturbation * rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 1.0)
        if name == "ground_height":
            start.append(value + config.ground_offset)
            scale.append(0.01)
            lo.append(value - 0.2)
            hi.append(value + 0.2)
        elif name.startswith("damping"):
            start.append(value * factor if value > 0 else 0.5)
            scale.append(0.1 * max(value, 1.0))
            lo.append(0.0)
            hi.append(10.0 * max(value, 1.0))
        else:  # friction, mass
            start.append(value * factor)
            scale.append(0.1 * value)
            lo.append(0.02 * value)
            hi.append(5.0 * value)
    return (np.array(a, dtype=float) for a in (start, scale, lo, hi))


def _subsample(x, u, x_next, n: int, rng: np.random.Generator):
    if x.shape[0] <= n:
        return x, u, x_next
    keep = np.sort(rng.choice(x.shape[0], n, replace=False))
    return x[keep], u[keep], x_next[keep]


def fit(stepper, data, fit_name: str, names, start, scale, lo, hi, config: Config, seed: int):
    """One fit of the parameters ``names`` to the transitions ``data`` (x, u, x_next)."""
    rng = np.random.default_rng(seed)
    x, u, x_next = _subsample(*data, config.max_transitions, rng)
    if fit_name == "random_search":
        loss = ModelLoss(stepper.with_smoothing(Exact()), x, u, x_next, names, "explicit",
                         gradient=False)  # fmt: skip
        return fit_random_search(loss, start, scale, iterations=config.search_iterations,
                                 directions=config.search_directions, lower=lo, upper=hi,
                                 seed=seed)  # fmt: skip
    if fit_name == "explicit":
        smoothed = stepper.with_smoothing(ContactAware(*config.contact_aware))
        loss = ModelLoss(smoothed, x, u, x_next, names, "explicit")
    elif fit_name == "naive_implicit":
        loss = ModelLoss(stepper, x, u, x_next, names, "naive_implicit")
    elif fit_name == "violation_implicit":
        loss = ModelLoss(stepper, x, u, x_next, names, "violation_implicit", eps=config.eps)
    else:
        raise ValueError(f"unknown fit {fit_name!r}; known: {FITS}")
    return fit_gradient(loss, start, scale, iterations=config.gradient_iterations, lower=lo,
                        upper=hi)  # fmt: skip


def open_loop(step_fn, data, horizon: int, spread: np.ndarray) -> tuple:
    """Prediction error (horizon,), and the fraction of windows lost (horizon,), of
    ``step_fn(x (B, nx), u (B, nu)) -> x_next`` rolled open loop from each window's recorded
    start (the test ``data``' windows of ``horizon`` steps within one episode), under its
    recorded inputs: per step k, the mean over windows of the
    RMS over coordinates of ``(x_hat - x) / spread``. A window whose prediction is not finite (a
    step that did not converge, a diverging network) is lost from then on: counted, not
    averaged."""
    starts = data.windows(horizon)
    if starts.size == 0:
        raise ValueError(f"no test window of {horizon} steps: the test episodes are too short")
    xh = data.x[starts]
    err, lost = np.empty(horizon), np.empty(horizon)
    for k in range(horizon):
        xh = step_fn(xh, data.u[starts + k])
        e = (xh - data.x_next[starts + k]) / spread
        rms = np.sqrt(np.mean(e**2, axis=1))
        finite = np.isfinite(rms)
        err[k] = float(np.mean(rms[finite])) if finite.any() else np.nan
        lost[k] = 1.0 - finite.mean()
    return err, lost


def _model_step(stepper):
    def step(x, u):
        out = np.full_like(x, np.nan)
        ok = np.isfinite(x).all(axis=1)
        if ok.any():
            r = stepper.step(x[ok], u[ok], jacobians=False)
            nxt = r.x_next.copy()
            nxt[~r.converged] = np.nan  # an unconverged prediction is not passed off as one
            out[ok] = nxt
        return out

    return step


def _nn_step(ensemble):
    def step(x, u):  # the ensemble's mean prediction
        out = np.full_like(x, np.nan)
        ok = np.isfinite(x).all(axis=1)
        if ok.any():
            B = int(ok.sum())
            preds = [ensemble.predict(x[ok], u[ok], np.full(B, e)) for e in range(ensemble.size)]
            out[ok] = np.mean(preds, axis=0)
        return out

    return step


def _split(parts: tuple, n_train: int, n_test: int):
    """Training transitions: the first ``n_train`` episodes, alternating between the parts
    (random, scripted); test: the last ``n_test``, alternating likewise. Never the same
    episode in both."""

    def pick(first: bool, n: int):
        rows = []
        for k in range(n):
            part = parts[k % len(parts)]
            ids = part.episode_ids
            j = k // len(parts)
            rows.append((part, ids[j] if first else ids[len(ids) - 1 - j]))
        chosen = [p.select(np.isin(p.episode, [e for q, e in rows if q is p])) for p in parts]
        chosen = [c for c in chosen if len(c)]
        return chosen[0].concatenate(*chosen[1:]) if len(chosen) > 1 else chosen[0]

    return pick(True, n_train), pick(False, n_test)


def _record(row: dict, label: str, result: tuple) -> None:
    err, lost = result
    row["errors"][label] = err.tolist()
    row.setdefault("lost", {})[label] = lost.tolist()


def run_case(scene: str, source: str, config: Config) -> dict:
    """Every fit and the NN on one scene's data from one source, for every training size."""
    from drake_abs.multibody import build_scene_model
    from drake_abs.policy.mbpo import MlpEnsemble

    stepper = build_scene_model(scene).stepper()
    parts = collect(scene, source, config)
    everything = parts[0].concatenate(*parts[1:])
    names = learned_names(stepper)
    truth = learned_values(stepper, names)
    rng = np.random.default_rng(config.seed)
    start, scale, lo, hi = start_and_scale(names, truth, config, rng)
    start_stepper = stepper_at(stepper, names, start)
    spread = np.maximum(everything.x.std(axis=0), 1e-3)
    out = {"scene": scene, "source": source, "names": names, "file": truth.tolist(),
           "start": start.tolist(), "transitions": len(everything), "sizes": []}  # fmt: skip
    for n_train in config.train_episodes:
        train, test = _split(parts, n_train, config.test_episodes)
        tr = (train.x, train.u, train.x_next)
        row = {"train_episodes": n_train, "train_transitions": len(train), "fits": {},
               "errors": {}}  # fmt: skip
        for label, model in (("file", stepper), ("start", start_stepper)):
            _record(row, label, open_loop(_model_step(model), test, config.horizon, spread))
        for k, fit_name in enumerate(config.fits):
            t0 = time.perf_counter()
            result = fit(stepper, tr, fit_name, names, start, scale, lo, hi, config,
                         config.seed + 7 * k + n_train)  # fmt: skip
            learned = stepper_at(stepper, names, result.theta)
            row["fits"][fit_name] = {
                "theta": result.theta.tolist(), "loss": result.loss,
                "start_loss": result.start_loss,
                "evaluations": result.evaluations, "seconds": time.perf_counter() - t0,
                "unconverged_evaluations": result.unconverged_evaluations,
                "message": result.message,
            }  # fmt: skip
            _record(row, fit_name, open_loop(_model_step(learned), test, config.horizon, spread))
        t0 = time.perf_counter()
        nx, nu = everything.nx, everything.nu
        ens = MlpEnsemble(nx, nu, config.nn_ensemble, config.nn_hidden, np.random.default_rng(
            config.seed + n_train))  # fmt: skip
        held = ens.fit(*tr, np.random.default_rng(config.seed + 1), epochs=config.nn_epochs)
        row["nn"] = {"seconds": time.perf_counter() - t0, "heldout_error": held}
        _record(row, "nn", open_loop(_nn_step(ens), test, config.horizon, spread))
        out["sizes"].append(row)
    return out


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    config = Config() if config is None else config
    folder = results_dir(NAME, out)
    start = time.perf_counter()
    cases = []
    pairs = [(s, src) for s in config.scenes for src in config.sources]
    for scene, source in progress(pairs, desc=NAME):
        cases.append(run_case(scene, source, config))
    files = {
        "parameters": _write_parameters(folder / "parameters.csv", cases),
        "errors": _write_errors(folder / "prediction_error.csv", cases),
        "plot": _plot_errors(folder / "prediction_error.png", cases),
        "sizes_plot": _plot_sizes(folder / "data_size.png", cases),
    }
    summary = {"experiment": NAME, "config": asdict(config), "cases": cases,
               "seconds": time.perf_counter() - start, "files": file_list(files)}  # fmt: skip
    (folder / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    summary["files"]["summary"] = str(folder / "summary.json")
    return summary


def _models(row: dict) -> list[str]:
    return list(row["errors"])


def _write_parameters(path: Path, cases: list[dict]) -> Path:
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "source", "train_episodes", "parameter", "file", "start", *FITS])
        for c in cases:
            for row in c["sizes"]:
                for j, name in enumerate(c["names"]):
                    w.writerow([c["scene"], c["source"], row["train_episodes"], name,
                                c["file"][j], c["start"][j],
                                *[row["fits"][f]["theta"][j] if f in row["fits"] else ""
                                  for f in FITS]])  # fmt: skip
    return path


def _write_errors(path: Path, cases: list[dict]) -> Path:
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "source", "train_episodes", "model", "horizon", "error"])
        for c in cases:
            for row in c["sizes"]:
                for model, errs in row["errors"].items():
                    for k, e in enumerate(errs):
                        w.writerow([c["scene"], c["source"], row["train_episodes"], model, k + 1,
                                    e])  # fmt: skip
    return path


def _panels(path: Path, cases: list[dict], ylabel: str, draw) -> Path:
    """One log-scale panel per case side by side, ``draw(ax, case)`` filling each, saved."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(cases), figsize=(4 * len(cases), 3.4), squeeze=False)
    for ax, c in zip(axes[0], cases, strict=True):
        draw(ax, c)
        ax.set_yscale("log")
    axes[0][0].set_ylabel(ylabel)
    axes[0][-1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _plot_errors(path: Path, cases: list[dict]) -> Path:
    """Prediction error against the horizon, the largest training set."""

    def draw(ax, c):
        row = c["sizes"][-1]
        for model, errs in row["errors"].items():
            ax.plot(np.arange(1, len(errs) + 1), errs, label=model,
                    ls="--" if model in ("file", "start") else "-")  # fmt: skip
        ax.set_title(f"{c['scene']} / {c['source']}\n{row['train_episodes']} training episodes",
                     fontsize=9)  # fmt: skip
        ax.set_xlabel("horizon (steps)")

    return _panels(path, cases, "state prediction error (data std)", draw)


def _plot_sizes(path: Path, cases: list[dict]) -> Path:
    """Mean prediction error over the horizon against the training set's size."""

    def draw(ax, c):
        sizes = [row["train_transitions"] for row in c["sizes"]]
        for model in _models(c["sizes"][0]):
            ax.plot(sizes, [np.nanmean(row["errors"][model]) for row in c["sizes"]], "o-",
                    label=model)  # fmt: skip
        ax.set_xscale("log")
        ax.set_title(f"{c['scene']} / {c['source']}", fontsize=9)
        ax.set_xlabel("training transitions")

    return _panels(path, cases, "mean prediction error over the horizon", draw)


def report(summary: dict) -> str:
    lines = [f"# Model learning ({summary['seconds']:.0f} s)", ""]
    for c in summary["cases"]:
        lines.append(f"## {c['scene']} from {c['source']} ({c['transitions']} transitions)")
        last = c["sizes"][-1]
        head = ["parameter", "file", "start", *last["fits"]]
        lines += ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
        for j, name in enumerate(c["names"]):
            vals = [c["file"][j], c["start"][j]] + [f["theta"][j] for f in last["fits"].values()]
            lines.append(f"| {name} | " + " | ".join(f"{v:.4g}" for v in vals) + " |")
        lines.append("")
        head = ["training episodes", *_models(last)]
        lines += ["mean prediction error over the horizon (data std):", "",
                  "| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]  # fmt: skip
        for row in c["sizes"]:
            cells = [f"{np.nanmean(row['errors'][m]):.3g}" for m in _models(last)]
            lines.append(f"| {row['train_episodes']} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)
