"""Learning our complementarity model's parameters from data that no one here wrote (Zhang et
al. 2023, section 6 and its model-learning figure; Bianchini et al. 2022's losses), against a
neural-network dynamics model trained on the same data.

For each scene (the pushed box, gymnasium's hopper and half-cheetah) and each data source
(Drake's MultibodyPlant with the SAP solver, MuJoCo; :mod:`drake_abs.reference.scene_sources`),
episodes under random and scripted inputs are recorded by the engine (:func:`collect`) and split
by episode into training and test sets. Then, for each training-set size:

1. our model's parameters theta (the ground height, one friction coefficient for every contact,
   each body's mass, the damping of each joint the model file damps) start from values off the
   model file's (seeded: the ground ``ground_offset`` m higher, the others scaled by factors
   within ``1 +- perturbation``), and are fitted (:mod:`drake_abs.learning.scene_fits`)

   - by random search on eq. 6.1 (the explicit loss through the exact model): the paper's way,
   - by L-BFGS-B on the explicit loss through the model with adaptive barrier smoothing,
   - by L-BFGS-B on the naive-implicit loss (the explicit loss of the exact model),
   - by L-BFGS-B on the violation-implicit loss (``eps``);

2. an ensemble of neural networks (:class:`drake_abs.policy.mbpo.MlpEnsemble`: least squares
   plus a tanh MLP residual, as our MBPO baseline) is fitted to the same transitions;

3. each model predicts the test trajectories open loop (the engine's) from their recorded start
   state and inputs, and the state prediction error is reported against the horizon: the root
   mean square over the state's coordinates of the error divided by that coordinate's standard
   deviation in the data (1 = as far off as the data's own spread), averaged over test windows.
   The models with the model file's parameters ("file") and with the starting parameters
   ("start") are reported beside them.

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

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from drake_abs.engine import open_loop
from drake_abs.experiments import outputs
from drake_abs.learning.prediction import Predictor, prediction_error
from drake_abs.learning.scene_fits import FITS, fit_parameters, learned_names, perturbed_start
from drake_abs.learning.scene_losses import learned_values, stepper_at
from drake_abs.learning.transitions import Transitions
from drake_abs.policy.controls import episode_seed, push_inputs, sinusoid_inputs, uniform_inputs

NAME = "model-learning"
SCENES = ("box_push", "gym_hopper", "gym_half_cheetah")
SOURCES = ("sap", "mujoco")
#: The box's scripted pushes, up to 12 N (it slides beyond mu m g = 4.9 N and sticks below it).
PUSH = 12.0
#: The locomotion scenes' scripted gaits (a share of each motor's effort limit, Hz).
GAITS = {"gym_hopper": (0.3, 2.0), "gym_half_cheetah": (0.5, 2.5)}
#: The box's initial-state noise, as half-widths of the position offset (m), the tilt (rad),
#: the lift (m) and the velocity (m/s, m/s, rad/s); its half length and half height (m).
BOX_NOISE = {"x": 0.1, "pitch": 0.1, "lift": 0.02, "v": (0.5, 0.2, 1.0)}
BOX_HALF = (0.2, 0.1)


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


def initial_states(model, seeds) -> np.ndarray:
    """(E, nx) initial states, one per episode seed: the scene's x0 plus noise drawn from
    ``default_rng(seed)``: for the locomotion scenes gymnasium's reset noise (as
    ``env.reset(seed=seed)`` draws it, so Drake and MuJoCo episodes of one seed start alike);
    for the box a random position offset, tilt (lifted so that no corner starts below the
    ground) and velocity."""
    from drake_abs.tasks.locomotion import TASKS

    scene, nq = model.scene.name, model.contact_model.nq
    out = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        x = np.array(model.x0, dtype=float)
        if scene != "box_push":
            spec = next(t for t in TASKS.values() if t.scene == scene)
            out.append(spec.reset_noise.sample(rng, x, nq, 1)[0])
            continue
        pitch = x[2] + rng.uniform(-BOX_NOISE["pitch"], BOX_NOISE["pitch"])
        # lift so that the lowest corner is where it was before the tilt, then a random gap
        lift = (BOX_HALF[0] * abs(np.sin(pitch)) + BOX_HALF[1] * np.cos(pitch)) - BOX_HALF[1]
        x[0] += rng.uniform(-BOX_NOISE["x"], BOX_NOISE["x"])
        x[1] += lift + rng.uniform(0.0, BOX_NOISE["lift"])
        x[2] = pitch
        x[nq:] += rng.uniform(-1.0, 1.0, 3) * np.asarray(BOX_NOISE["v"])
        out.append(x)
    return np.array(out)


def scripted_inputs(model, steps: int, effort: np.ndarray, seed) -> np.ndarray:
    """(steps, nu) the scene's scripted inputs: the box's pushes (:data:`PUSH`), the locomotion
    scenes' gaits (:data:`GAITS`) with seeded phases."""
    if model.scene.name == "box_push":
        return push_inputs(steps, PUSH, seed=seed)
    share, frequency = GAITS[model.scene.name]
    return sinusoid_inputs(steps, share * effort, frequency, model.scene.time_step, seed=seed)


def collect(model, effort: np.ndarray, source: str, config: Config) -> tuple:
    """The scene's transitions from ``source`` (Drake's SAP twin or MuJoCo,
    :mod:`drake_abs.reference.scene_sources`): ``(random, scripted)``, each of
    ``max(train_episodes) + test_episodes`` seeded episodes of ``steps`` steps, the first under
    inputs uniform within the effort limits ``effort`` (nu,), the second under the scene's
    scripted inputs. gymnasium's Hopper runs without its termination, so that every episode has
    its ``steps`` steps."""
    from drake_abs.reference.scene_sources import drake_source, mujoco_source

    source_of = drake_source(model) if source == "sap" else mujoco_source(model)
    episodes = max(config.train_episodes) + config.test_episodes
    seed = config.seed * 1000 + SCENES.index(model.scene.name) * 10 + SOURCES.index(source)

    def record(inputs, run_seed: int) -> Transitions:
        seeds = [episode_seed(run_seed, e) for e in range(episodes)]
        u = np.stack([inputs([run_seed, s]) for s in seeds])
        x0, u = initial_states(model, seeds), np.clip(u, -effort, effort)
        run = open_loop(source_of.stepper, x0, u, jacobians=False, on_unconverged="flag")
        return Transitions.from_trajectory(run, source=source_of.name,
                                           time_step=source_of.time_step)  # fmt: skip

    random_data = record(lambda key: uniform_inputs(config.steps, -effort, effort, seed=key), seed)
    scripted = record(lambda key: scripted_inputs(model, config.steps, effort, key), seed + 1)
    return random_data, scripted


def _split(parts: tuple, n_train: int, n_test: int):
    """Training transitions: the first ``n_train`` episodes, alternating between the parts
    (random, scripted); test: the last ``n_test``, alternating likewise. Never the same
    episode in both."""

    def pick(n: int, last: bool):
        chosen = []
        for i, part in enumerate(parts):
            count = len(range(i, n, len(parts)))
            ids = part.episode_ids[-count:] if last else part.episode_ids[:count]
            if count:
                chosen.append(part.select(np.isin(part.episode, ids)))
        return chosen[0].concatenate(*chosen[1:])

    return pick(n_train, False), pick(n_test, True)


def run_case(scene: str, source: str, config: Config) -> dict:
    """Every fit and the NN on one scene's data from one source, for every training size."""
    from drake_abs.multibody import build_scene_model
    from drake_abs.policy.mbpo import MlpEnsemble

    model = build_scene_model(scene)
    stepper = model.stepper()
    parts = collect(model, stepper.effort, source, config)
    everything = parts[0].concatenate(*parts[1:])
    names = learned_names(stepper)
    truth = learned_values(stepper, names)
    start, scale, lo, hi = perturbed_start(
        names, truth, ground_offset=config.ground_offset, perturbation=config.perturbation,
        rng=np.random.default_rng(config.seed),
    )  # fmt: skip
    spread = np.maximum(everything.x.std(axis=0), 1e-3)
    out = {"scene": scene, "source": source, "names": names, "file": truth.tolist(),
           "start": start.tolist(), "transitions": len(everything), "sizes": []}  # fmt: skip
    for n_train in config.train_episodes:
        train, test = _split(parts, n_train, config.test_episodes)
        row = {"train_episodes": n_train, "train_transitions": len(train), "fits": {},
               "errors": {}, "lost": {}}  # fmt: skip

        def record(label: str, predictor: Predictor, row=row, test=test) -> None:
            err, lost = prediction_error(predictor, test, config.horizon, spread)
            row["errors"][label], row["lost"][label] = err.tolist(), lost.tolist()

        record("file", Predictor.of_stepper(stepper))
        record("start", Predictor.of_stepper(stepper_at(stepper, names, start)))
        for k, fit_name in enumerate(config.fits):
            t0 = time.perf_counter()
            result = fit_parameters(
                stepper, train.x, train.u, train.x_next, fit_name, names, start, scale, lo, hi,
                eps=config.eps, contact_aware=config.contact_aware,
                search_iterations=config.search_iterations,
                search_directions=config.search_directions,
                gradient_iterations=config.gradient_iterations,
                max_transitions=config.max_transitions, seed=config.seed + 7 * k + n_train,
            )  # fmt: skip
            row["fits"][fit_name] = {
                "theta": result.theta.tolist(), "loss": result.loss,
                "start_loss": result.start_loss,
                "evaluations": result.evaluations, "seconds": time.perf_counter() - t0,
                "unconverged_evaluations": result.unconverged_evaluations,
                "message": result.message,
            }  # fmt: skip
            record(fit_name, Predictor.of_stepper(stepper_at(stepper, names, result.theta)))
        t0 = time.perf_counter()
        ens = MlpEnsemble(everything.nx, everything.nu, config.nn_ensemble, config.nn_hidden,
                          np.random.default_rng(config.seed + n_train))  # fmt: skip
        held = ens.fit(train.x, train.u, train.x_next, np.random.default_rng(config.seed + 1),
                       epochs=config.nn_epochs)  # fmt: skip
        row["nn"] = {"seconds": time.perf_counter() - t0, "heldout_error": held}
        record("nn", Predictor.of_ensemble(ens))
        out["sizes"].append(row)
    return out


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    config = Config() if config is None else config
    folder = outputs.results_dir(NAME, out)
    start = time.perf_counter()
    pairs = [(s, src) for s in config.scenes for src in config.sources]
    cases = [run_case(*pair, config) for pair in outputs.progress(pairs, desc=NAME)]
    sizes = [(c, row) for c in cases for row in c["sizes"]]
    parameters = [[c["scene"], c["source"], row["train_episodes"], name, c["file"][j],
                   c["start"][j], *[row["fits"][f]["theta"][j] if f in row["fits"] else ""
                                    for f in FITS]]
                  for c, row in sizes for j, name in enumerate(c["names"])]  # fmt: skip
    errors = [[c["scene"], c["source"], row["train_episodes"], model, k + 1, e]
              for c, row in sizes for model, errs in row["errors"].items()
              for k, e in enumerate(errs)]  # fmt: skip
    head = ["scene", "source", "train_episodes"]
    files = {
        "parameters": outputs.write_csv(folder / "parameters.csv", parameters,
                                        [*head, "parameter", "file", "start", *FITS]),
        "errors": outputs.write_csv(folder / "prediction_error.csv", errors,
                                    [*head, "model", "horizon", "error"]),
        "plot": _plot_errors(folder / "prediction_error.png", cases),
        "sizes_plot": _plot_sizes(folder / "data_size.png", cases),
    }  # fmt: skip
    summary = {"experiment": NAME, "config": asdict(config), "cases": cases,
               "seconds": time.perf_counter() - start,
               "files": outputs.file_list(files)}  # fmt: skip
    path = outputs.write_json(folder / "summary.json", summary, indent=1)
    summary["files"]["summary"] = str(path)
    return summary


def _panels(path: Path, cases: list[dict], ylabel: str, draw) -> Path:
    """One log-scale panel per case side by side, ``draw(ax, case)`` filling each, saved."""
    plt = outputs.pyplot()
    fig, axes = plt.subplots(1, len(cases), figsize=(4 * len(cases), 3.4), squeeze=False)
    for ax, c in zip(axes[0], cases, strict=True):
        draw(ax, c)
        ax.set_yscale("log")
    axes[0][0].set_ylabel(ylabel)
    axes[0][-1].legend(fontsize=7)
    return outputs.save_figure(fig, path, dpi=110)


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
        for model in c["sizes"][0]["errors"]:
            ax.plot(sizes, [np.nanmean(row["errors"][model]) for row in c["sizes"]], "o-",
                    label=model)  # fmt: skip
        ax.set(xscale="log", title=f"{c['scene']} / {c['source']}", xlabel="training transitions")
        ax.title.set_fontsize(9)

    return _panels(path, cases, "mean prediction error over the horizon", draw)


def report(summary: dict) -> str:
    lines = [f"# Model learning ({summary['seconds']:.0f} s)", ""]
    for c in summary["cases"]:
        last = c["sizes"][-1]
        lines += [f"## {c['scene']} from {c['source']} ({c['transitions']} transitions)"]
        lines += outputs.markdown_table(["parameter", "file", "start", *last["fits"]], [
            [name, *(f"{v:.4g}" for v in [c["file"][j], c["start"][j]]
                     + [f["theta"][j] for f in last["fits"].values()])]
            for j, name in enumerate(c["names"])])  # fmt: skip
        lines += ["", "mean prediction error over the horizon (data std):", ""]
        lines += outputs.markdown_table(["training episodes", *last["errors"]], [
            [row["train_episodes"], *(f"{np.nanmean(row['errors'][m]):.3g}"
                                      for m in last["errors"])]
            for row in c["sizes"]]) + [""]  # fmt: skip
    return "\n".join(lines)
