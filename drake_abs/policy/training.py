"""Policy optimisation: gradient ascent on J(theta) with Adam or SGD, a progress bar, seeds, and
a JSON and CSV log of every iteration (Zhang et al. 2023, eq. 4.2).

``estimator(theta, rng) -> GradientEstimate`` is any estimator of :mod:`drake_abs.policy.estimators`
with its sizes bound, e.g. ``lambda th, rng: first_order(obj, th, rng, 64)``.
"""

from __future__ import annotations

import csv
import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from drake_abs.policy.estimators import GradientEstimate


@dataclass
class SGD:
    """``theta <- theta + lr g`` (ascent)."""

    lr: float = 1e-2

    def step(self, theta: np.ndarray, grad: np.ndarray) -> np.ndarray:
        return theta + self.lr * grad


@dataclass
class Adam:
    """Adam (Kingma and Ba 2015), as ascent: ``theta <- theta + lr m_hat / (sqrt(v_hat) + eps)``."""

    lr: float = 1e-2
    beta1: float = 0.9
    beta2: float = 0.999
    eps: float = 1e-8
    _m: np.ndarray | None = field(default=None, repr=False)
    _v: np.ndarray | None = field(default=None, repr=False)
    _t: int = field(default=0, repr=False)

    def step(self, theta: np.ndarray, grad: np.ndarray) -> np.ndarray:
        if self._m is None:
            self._m, self._v = np.zeros_like(theta), np.zeros_like(theta)
        self._t += 1
        self._m = self.beta1 * self._m + (1 - self.beta1) * grad
        self._v = self.beta2 * self._v + (1 - self.beta2) * grad * grad
        m_hat = self._m / (1 - self.beta1**self._t)
        v_hat = self._v / (1 - self.beta2**self._t)
        return theta + self.lr * m_hat / (np.sqrt(v_hat) + self.eps)


@dataclass(frozen=True)
class TrainingRun:
    """The parameters after training and the per-iteration log (``rows``: iteration, the batch's
    mean return, the evaluated return if an evaluation was given, the gradient norm, rollouts,
    unconverged steps, rollouts dropped for them, seconds)."""

    theta: np.ndarray
    rows: list[dict]
    seed: int


def train(
    estimator: Callable[[np.ndarray, np.random.Generator], GradientEstimate],
    theta0,
    optimizer: SGD | Adam,
    iterations: int,
    *,
    seed: int = 0,
    evaluate: Callable[[np.ndarray], float] | None = None,
    log_dir: str | Path | None = None,
    name: str = "run",
    config: dict | None = None,
    progress: bool = True,
) -> TrainingRun:
    """Run ``iterations`` ascent steps from ``theta0``; all randomness from ``seed``.

    Args:
        estimator: gradient estimate of the mean return at theta.
        theta0: (P,) initial parameters.
        optimizer: :class:`SGD` or :class:`Adam` (its state is updated).
        iterations: number of updates.
        seed: seeds the numpy Generator handed to the estimator.
        evaluate: optional ``theta -> return`` (e.g. the exact objective with fixed noise),
            logged every iteration before the update and once at the end.
        log_dir: write ``NAME.json`` (config, seed, rows) and ``NAME.csv`` (rows) there.
        name: file stem of the logs.
        config: anything JSON-serialisable to store with the log.
        progress: show a tqdm progress bar.
    """
    if int(iterations) < 0:
        raise ValueError(f"iterations must be >= 0; got {iterations!r}")
    rng = np.random.default_rng(seed)
    theta = np.array(theta0, dtype=float)
    rows = []
    bar = tqdm(range(int(iterations)), desc=name, disable=not progress, leave=False)
    for k in bar:
        start = time.perf_counter()
        est = estimator(theta, rng)
        row = {
            "iteration": k,
            "batch_return": est.value,
            "eval_return": None if evaluate is None else float(evaluate(theta)),
            "grad_norm": float(np.linalg.norm(est.grad)),
            "rollouts": est.rollouts,
            "unconverged_steps": est.unconverged,
            "dropped_rollouts": est.dropped,
        }
        if not np.all(np.isfinite(est.grad)):
            raise FloatingPointError(f"{name}: non-finite gradient estimate at iteration {k}")
        theta = optimizer.step(theta, est.grad)
        row["seconds"] = time.perf_counter() - start
        rows.append(row)
        bar.set_postfix(ret=f"{est.value:.4g}")
    if evaluate is not None:
        rows.append({"iteration": int(iterations), "eval_return": float(evaluate(theta))})
    run = TrainingRun(theta, rows, seed)
    if log_dir is not None:
        write_log(run, Path(log_dir), name, {**(config or {}), "optimizer": _describe(optimizer)})
    return run


def _describe(optimizer) -> dict:
    return {"kind": type(optimizer).__name__} | {
        k: v for k, v in asdict(optimizer).items() if not k.startswith("_")
    }


def write_log(run: TrainingRun, folder: Path, name: str, config: dict) -> None:
    """``NAME.json`` (config, seed, final theta, rows) and ``NAME.csv`` (rows) in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    payload = {"name": name, "seed": run.seed, "config": config,
               "theta": run.theta.tolist(), "rows": run.rows}  # fmt: skip
    (folder / f"{name}.json").write_text(json.dumps(payload, indent=1, default=float))
    keys = list(dict.fromkeys(k for row in run.rows for k in row))
    with (folder / f"{name}.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=keys)
        writer.writeheader()
        writer.writerows(run.rows)
