"""Benchmark of ``drake_abs.solve_lcp`` (batched interior point for the mu-softened LCP).

Everything below is measured in one run, on seeded random problems (``numpy.random.default_rng``
with a fixed seed), timed with ``time.perf_counter`` after one warm-up call, reporting the median
of several repeats. Unless stated otherwise our solves request ``mu = 1e-10`` with
``jacobians=True``, i.e. the timings include the implicit Jacobians ``dlam_dq`` and ``dlam_dmu``.

Random P-matrix LCPs of size d are ``F = A A^T / d + 0.1 I + 0.3 (W - W^T)`` with ``A, W`` standard
normal (d x d) and ``q`` standard normal (d,) (``drake_abs.lcp.problems.random_p_matrices``): the
symmetric part of F is positive definite, so the LCP has a unique solution for every q.

Sections:

1. Iterations and wall time per solve against d in (1, 2, 5, 10, 20, 50, 100), single problems
   (B = 1), median over the random problems of each d.
   Target: d = 20 single problems reach mu = 1e-10 in <= 20 iterations (median).
2. Batched throughput against batch size B for d = 1 (shared ``F = [[1.0]]``, ``q ~ N(0, 1)``),
   and for d = 4 (one shared random P-matrix), in microseconds per problem.
   Target: a batch of 1e4 single-contact problems at <= 1 microsecond per problem, Jacobians
   included.
3. Drake's ``MobyLcpSolver`` (Lemke) on the same single problems as section 1, as ratios
   ours / Moby: (a) d = 1, 2 against our single solve and our per-problem cost in a batch of
   1e4 problems of the same distribution; (b) d = 5, 10, 20, 50 single problems. Moby is timed
   both for the full per-problem cost (build a ``MathematicalProgram``, add the complementarity
   constraint, construct the solver, solve) and for the solve only (pre-built program, reused
   solver). The agreement ``max |lam_ours(mu = 0) - z_moby|`` is a sanity check.
4. Speed against accuracy for a batch of 1000 random d = 10 problems: (a) for each mu target, the
   smoothing bias ``max_b,i |lam_mu - lam_exact| / (1 + |lam_exact|)`` (``lam_exact`` from
   ``mu = 0``) against time per problem; (b) for the exact LCP (``mu = 0``) and each
   ``exact_tol = tol``, the achieved residual and error against Moby against time per problem.

5. Problem families: for each family and size d in (10, 16, 20, 24, 32, 48, 64, 101) (friction: d =
   12 .. 102), how many problems converge at mu = 0 with the interior point alone (second starts on,
   crossover off) and with the crossover (the default), the interior-point iterations and principal
   pivots taken, the solver's residual and an independent check of each converged answer
   (``max(-w_i, min(lam_i F_ii, |w_i|)) / (|q_i| + (|F| |lam|)_i)``, recomputed in the original
   units), and how many converge at mu = 1e-6 (where the crossover only supplies a start,
   docs/math.md section 3b). Families (``drake_abs.lcp.problems``): Csizmadia (1 on the diagonal, -1
   below; q with solution (1, 0, 1, ...)), Murty (1 on the diagonal, 2 below, q = -1), Fathy (L L^T,
   L with 1 on the diagonal and 2 below, q = -1), random non-symmetric P-matrices with an indefinite
   symmetric part (``D1 P D2``, positive diagonals over two decades), random singular PSD (``J J^T``
   of rank d/2, q strictly feasible), ill-conditioned PD (cond 1e10, q standard normal) and
   frictional contact (Stewart-Trinkle, 4 directions per contact, random Jacobians and velocities;
   copositive, not P, solved with ``on_bad_matrix="attempt"``).

Usage::

    python benchmarks/bench_lcp.py            # full size (a few minutes)
    python benchmarks/bench_lcp.py --quick    # reduced size (under a minute)
    python benchmarks/bench_lcp.py --json results/bench_lcp.json
    python benchmarks/bench_lcp.py --families  # section 5 only

The numbers printed are also written as JSON (default ``results/bench_lcp.json``).
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.metadata
import json
import os
import platform
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from functools import partial
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see drake_abs/__init__

import numpy as np

import drake_abs.lcp.ipm
from drake_abs import solve_lcp
from drake_abs.lcp.matrix_class import _strictly_diagonally_dominant
from drake_abs.lcp.problems import (
    csizmadia,
    fathy,
    friction_problems,
    ill_conditioned_problems,
    murty,
    random_p_matrices,
    scaled_p_problems,
    singular_psd_problems,
)

SEED = 20250101
MU_TARGET = 1e-10
SINGLE_DIMS = (1, 2, 5, 10, 20, 50, 100)
BATCH_SIZES_D1 = (1, 10, 100, 1_000, 10_000, 100_000)
BATCH_SIZES_D4 = (100, 10_000)
MOBY_DIMS_WITH_BATCH = (1, 2)
MOBY_DIMS_SINGLE = (5, 10, 20, 50)
MOBY_BATCH = 10_000
TRADEOFF_D = 10
TRADEOFF_MUS = (1e-1, 1e-2, 1e-4, 1e-6, 1e-8, 1e-10, 0.0)
TRADEOFF_TOLS = (1e-2, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-15)

TARGET_D20_ITERATIONS = 20
TARGET_BATCH_US = 1.0
TARGET_BATCH_B = 10_000


@dataclass(frozen=True)
class Config:
    """Problem counts and timing repeats of one run."""

    name: str
    n_problems: int  # random single problems per d (section 1 and 3)
    n_problems_d100: int  # random single problems for d = 100
    repeats_single: int  # timing repeats per single problem (ours and Moby)
    repeats_batch: int  # minimum timing repeats per batched solve
    batch_time_budget_s: float  # small batches are repeated until about this much time is spent
    tradeoff_batch: int  # batch size of section 4
    repeats_tradeoff: int  # timing repeats per batched solve in section 4


FULL = Config("full", 30, 30, 11, 7, 1.0, 1000, 9)
QUICK = Config("quick", 10, 3, 3, 3, 0.1, 1000, 3)


# --- helpers -----------------------------------------------------------------------------------


def rng_for(*key: int) -> np.random.Generator:
    """A generator seeded by SEED and a section/size key, so that every problem set is
    reproducible and independent of the others (and of --quick, up to the problem count)."""
    return np.random.default_rng([SEED, *key])


def random_problems(key: int, d: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """n random P-matrix LCPs of size d: F (n, d, d) and q (n, d)."""
    rng = rng_for(key, d)
    F = random_p_matrices(rng, d, n)
    q = rng.standard_normal((n, d))
    return F, q


def single_problems(d: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The single problems of sections 1 and 3 (the same ones in both)."""
    return random_problems(1, d, n)


def median_time(fn: Callable[[], object], repeats: int) -> float:
    """Median wall time of ``fn()`` in seconds over ``repeats`` calls, after one warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def budget_repeats(seconds_per_call: float, cfg: Config) -> int:
    """Repeats for a batched solve: at least ``cfg.repeats_batch``, more for fast calls."""
    return max(cfg.repeats_batch, min(200, int(cfg.batch_time_budget_s / seconds_per_call)))


def time_batched(fn: Callable[[], object], cfg: Config) -> float:
    t0 = time.perf_counter()
    fn()
    return median_time(fn, budget_repeats(time.perf_counter() - t0, cfg))


def verdict(ok: bool) -> str:
    return "PASS" if ok else "FAIL"


class WarningLog:
    """Collects the solver's convergence warnings per section instead of printing them."""

    def __init__(self) -> None:
        self.counts: dict[str, int] = {}  # every warning, timing repeats included
        self.distinct: dict[str, set[str]] = {}  # distinct messages

    @contextmanager
    def capture(self, section: str) -> Iterator[None]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            yield
        for w in caught:
            self.counts[section] = self.counts.get(section, 0) + 1
            self.distinct.setdefault(section, set()).add(f"{w.category.__name__}: {w.message}")


def fmt(x: Any) -> str:
    if isinstance(x, str):
        return x
    if isinstance(x, bool | np.bool_):
        return str(bool(x))
    if isinstance(x, int | np.integer):
        return str(int(x))
    x = float(x)
    if x == 0.0:
        return "0"
    if np.isnan(x):
        return "-"
    if 1e-2 <= abs(x) < 1e5:
        return f"{x:.3g}" if abs(x) < 1 else f"{x:.4g}"
    return f"{x:.2e}"


def print_table(title: str, headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
    cells = [[fmt(c) for c in row] for row in rows]
    widths = [max(len(h), *(len(r[j]) for r in cells)) for j, h in enumerate(headers)]
    print(f"\n{title}")
    print("  ".join(h.rjust(w) for h, w in zip(headers, widths, strict=True)))
    print("  ".join("-" * w for w in widths))
    for r in cells:
        print("  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)))


# --- section 1: iterations and time against d ----------------------------------------------------


def bench_iterations_vs_d(cfg: Config, log: WarningLog) -> dict[str, Any]:
    rows = []
    with log.capture("1 iterations vs d"):
        for d in SINGLE_DIMS:
            n = cfg.n_problems_d100 if d == 100 else cfg.n_problems
            F, q = single_problems(d, n)
            iterations, times, converged = [], [], []
            for b in range(n):
                solve = partial(solve_lcp, F[b], q[b], MU_TARGET, jacobians=True)
                r = solve()
                iterations.append(int(r.iterations))
                converged.append(bool(r.converged))
                times.append(median_time(solve, cfg.repeats_single))
            rows.append(
                {
                    "d": d,
                    "n_problems": n,
                    "median_iterations": float(np.median(iterations)),
                    "max_iterations": int(np.max(iterations)),
                    "converged_fraction": float(np.mean(converged)),
                    "median_time_us": 1e6 * float(np.median(times)),
                }
            )
    d20 = next(r for r in rows if r["d"] == 20)
    target = {
        "description": f"d = 20 single problems, median iterations <= {TARGET_D20_ITERATIONS} "
        f"to mu = {MU_TARGET:g}",
        "measured_median_iterations": d20["median_iterations"],
        "pass": bool(d20["median_iterations"] <= TARGET_D20_ITERATIONS),
    }
    print_table(
        f"[1] Single problems (B = 1), random P-matrix LCPs, mu = {MU_TARGET:g}, jacobians=True",
        ["d", "problems", "median iters", "max iters", "converged", "median time/solve [us]"],
        [
            [
                r["d"],
                r["n_problems"],
                r["median_iterations"],
                r["max_iterations"],
                f"{r['converged_fraction']:.0%}",
                r["median_time_us"],
            ]
            for r in rows
        ],
    )
    print(
        f"TARGET {target['description']}: measured {fmt(target['measured_median_iterations'])} "
        f"-> {verdict(target['pass'])}"
    )
    return {"rows": rows, "target": target}


# --- section 2: batched throughput -------------------------------------------------------------


def _batch_row(F: np.ndarray, q: np.ndarray, cfg: Config) -> dict[str, Any]:
    solve = partial(solve_lcp, F, q, MU_TARGET, jacobians=True)
    r = solve()
    seconds = time_batched(solve, cfg)
    B, d = q.shape
    return {
        "d": d,
        "B": B,
        "median_iterations": float(np.median(r.iterations)),
        "max_iterations": int(np.max(r.iterations)),
        "converged_fraction": float(np.mean(r.converged)),
        "time_per_batch_ms": 1e3 * seconds,
        "time_per_problem_us": 1e6 * seconds / B,
    }


def bench_batched_throughput(cfg: Config, log: WarningLog) -> dict[str, Any]:
    rows = []
    with log.capture("2 batched throughput"):
        F1 = np.array([[1.0]])
        for B in BATCH_SIZES_D1:
            q = rng_for(2, 1, B).standard_normal((B, 1))
            rows.append(_batch_row(F1, q, cfg))
        F4 = random_p_matrices(rng_for(2, 4), 4, 1)[0]
        for B in BATCH_SIZES_D4:
            q = rng_for(2, 4, B).standard_normal((B, 4))
            rows.append(_batch_row(F4, q, cfg))
    hit = next(r for r in rows if r["d"] == 1 and r["B"] == TARGET_BATCH_B)
    target = {
        "description": f"batch of {TARGET_BATCH_B:g} single-contact problems at <= "
        f"{TARGET_BATCH_US:g} us per problem including Jacobians",
        "measured_us_per_problem": hit["time_per_problem_us"],
        "pass": bool(hit["time_per_problem_us"] <= TARGET_BATCH_US),
    }
    print_table(
        f"[2] Batched throughput, shared F (d = 1: F = [[1]]; d = 4: one random P-matrix), "
        f"q ~ N(0, 1), mu = {MU_TARGET:g}, jacobians=True",
        [
            "d",
            "B",
            "median iters",
            "max iters",
            "converged",
            "time/batch [ms]",
            "time/problem [us]",
        ],
        [
            [
                r["d"],
                r["B"],
                r["median_iterations"],
                r["max_iterations"],
                f"{r['converged_fraction']:.0%}",
                r["time_per_batch_ms"],
                r["time_per_problem_us"],
            ]
            for r in rows
        ],
    )
    print(
        f"TARGET {target['description']}: measured {fmt(target['measured_us_per_problem'])} us "
        f"-> {verdict(target['pass'])}"
    )
    return {"rows": rows, "target": target}


# --- section 3: Drake's MobyLcpSolver ------------------------------------------------------------


def moby_build_and_solve(F: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The full per-problem cost: build the program, construct the solver, solve."""
    from pydrake.solvers import MathematicalProgram, MobyLcpSolver

    prog = MathematicalProgram()
    z = prog.NewContinuousVariables(len(q))
    prog.AddLinearComplementarityConstraint(F, q, z)
    result = MobyLcpSolver().Solve(prog)
    return result.GetSolution(z)


def moby_timings(F: np.ndarray, q: np.ndarray, repeats: int) -> dict[str, Any]:
    """Moby build+solve time, solve-only time (pre-built program, reused solver) and solution."""
    from pydrake.solvers import MathematicalProgram, MobyLcpSolver

    prog = MathematicalProgram()
    z = prog.NewContinuousVariables(len(q))
    prog.AddLinearComplementarityConstraint(F, q, z)
    solver = MobyLcpSolver()
    result = solver.Solve(prog)
    return {
        "z": result.GetSolution(z),
        "success": bool(result.is_success()),
        "solve_only_s": median_time(partial(solver.Solve, prog), repeats),
        "build_and_solve_s": median_time(partial(moby_build_and_solve, F, q), repeats),
    }


def bench_moby(cfg: Config, log: WarningLog) -> dict[str, Any]:
    rows = []
    with log.capture("3 Moby comparison"):
        for d in (*MOBY_DIMS_WITH_BATCH, *MOBY_DIMS_SINGLE):
            F, q = single_problems(d, cfg.n_problems)
            moby_bs, moby_so, ours, errors, success, exact_conv = [], [], [], [], [], []
            for b in range(cfg.n_problems):
                m = moby_timings(F[b], q[b], cfg.repeats_single)
                moby_bs.append(m["build_and_solve_s"])
                moby_so.append(m["solve_only_s"])
                success.append(m["success"])
                solve = partial(solve_lcp, F[b], q[b], MU_TARGET, jacobians=True)
                ours.append(median_time(solve, cfg.repeats_single))
                exact = solve_lcp(F[b], q[b], 0.0)
                exact_conv.append(bool(exact.converged))
                errors.append(float(np.max(np.abs(exact.lam - m["z"]))))
            row: dict[str, Any] = {
                "d": d,
                "n_problems": cfg.n_problems,
                "moby_build_and_solve_us": 1e6 * float(np.median(moby_bs)),
                "moby_solve_only_us": 1e6 * float(np.median(moby_so)),
                "ours_single_us": 1e6 * float(np.median(ours)),
                "max_abs_lam_exact_minus_moby": float(np.max(errors)),
                "moby_success_fraction": float(np.mean(success)),
                "ours_mu0_converged_fraction": float(np.mean(exact_conv)),
            }
            row["ratio_single_vs_solve_only"] = row["ours_single_us"] / row["moby_solve_only_us"]
            row["ratio_single_vs_build_and_solve"] = (
                row["ours_single_us"] / row["moby_build_and_solve_us"]
            )
            if d in MOBY_DIMS_WITH_BATCH:
                Fb, qb = random_problems(3, d, MOBY_BATCH)
                seconds = time_batched(partial(solve_lcp, Fb, qb, MU_TARGET, jacobians=True), cfg)
                row["ours_batch_per_problem_us"] = 1e6 * seconds / MOBY_BATCH
                row["ratio_batch_vs_solve_only"] = (
                    row["ours_batch_per_problem_us"] / row["moby_solve_only_us"]
                )
                row["ratio_batch_vs_build_and_solve"] = (
                    row["ours_batch_per_problem_us"] / row["moby_build_and_solve_us"]
                )
            rows.append(row)

    note = (
        "Moby build+solve = MathematicalProgram() + NewContinuousVariables + "
        "AddLinearComplementarityConstraint + MobyLcpSolver() + Solve, all per problem; "
        "Moby solve = Solve(prog) only, on a pre-built program with a reused solver. "
        f"Ours = solve_lcp(mu = {MU_TARGET:g}, jacobians=True) (Moby solves the exact LCP and "
        "returns no Jacobians). Times are medians over problems of the per-problem median over "
        "repeats. Ratio = ours / Moby (> 1: ours is slower)."
    )
    with_batch = [r for r in rows if r["d"] in MOBY_DIMS_WITH_BATCH]
    print_table(
        f"[3a] vs Drake MobyLcpSolver, d = 1, 2: single solves and our per-problem cost in a "
        f"batch of {MOBY_BATCH:g} random problems (per-problem F) of the same distribution",
        [
            "d",
            "Moby b+s [us]",
            "Moby solve [us]",
            "ours single [us]",
            f"ours in {MOBY_BATCH:g}-batch [us]",
            "single/Moby solve",
            "single/Moby b+s",
            "batch/Moby solve",
            "batch/Moby b+s",
        ],
        [
            [
                r["d"],
                r["moby_build_and_solve_us"],
                r["moby_solve_only_us"],
                r["ours_single_us"],
                r["ours_batch_per_problem_us"],
                r["ratio_single_vs_solve_only"],
                r["ratio_single_vs_build_and_solve"],
                r["ratio_batch_vs_solve_only"],
                r["ratio_batch_vs_build_and_solve"],
            ]
            for r in with_batch
        ],
    )
    print_table(
        "[3b] vs Drake MobyLcpSolver, single problems (the problems of section 1)",
        [
            "d",
            "Moby b+s [us]",
            "Moby solve [us]",
            "ours single [us]",
            "ours/Moby solve",
            "ours/Moby b+s",
        ],
        [
            [
                r["d"],
                r["moby_build_and_solve_us"],
                r["moby_solve_only_us"],
                r["ours_single_us"],
                r["ratio_single_vs_solve_only"],
                r["ratio_single_vs_build_and_solve"],
            ]
            for r in rows
            if r["d"] in MOBY_DIMS_SINGLE
        ],
    )
    print_table(
        "[3c] Agreement with Moby: ours at mu = 0 (default tol) against Moby's z",
        ["d", "problems", "max |lam_ours - z_moby|", "Moby success", "ours mu=0 converged"],
        [
            [
                r["d"],
                r["n_problems"],
                r["max_abs_lam_exact_minus_moby"],
                f"{r['moby_success_fraction']:.0%}",
                f"{r['ours_mu0_converged_fraction']:.0%}",
            ]
            for r in rows
        ],
    )
    print(f"Note: {note}")
    return {"rows": rows, "note": note}


# --- section 4: speed against accuracy ---------------------------------------------------------


def bench_tradeoff(cfg: Config, log: WarningLog) -> dict[str, Any]:
    B, d = cfg.tradeoff_batch, TRADEOFF_D
    F, q = random_problems(4, d, B)
    mu_rows, tol_rows = [], []
    with log.capture("4 speed vs accuracy"):
        lam_exact = solve_lcp(F, q, 0.0).lam
        z_moby = np.array([moby_build_and_solve(F[b], q[b]) for b in range(B)])
        exact_vs_moby = float(np.max(np.abs(lam_exact - z_moby)))
        for mu in TRADEOFF_MUS:
            solve = partial(solve_lcp, F, q, mu, jacobians=True)
            r = solve()
            seconds = median_time(solve, cfg.repeats_tradeoff)
            bias = np.abs(r.lam - lam_exact) / (1.0 + np.abs(lam_exact))
            mu_rows.append(
                {
                    "mu": mu,
                    "median_iterations": float(np.median(r.iterations)),
                    "max_iterations": int(np.max(r.iterations)),
                    "converged_fraction": float(np.mean(r.converged)),
                    "time_per_problem_us": 1e6 * seconds / B,
                    "max_rel_error_vs_exact": float(np.max(bias)),
                    "median_rel_error_vs_exact": float(np.median(np.max(bias, axis=1))),
                }
            )
        for tol in TRADEOFF_TOLS:
            # at mu = 0 the exact floor (exact_tol c)^2 decides when to stop; tol the rest
            solve = partial(
                solve_lcp, F, q, 0.0, jacobians=True, tol=max(tol, 1e-12), exact_tol=tol
            )
            r = solve()
            seconds = median_time(solve, cfg.repeats_tradeoff)
            tol_rows.append(
                {
                    "tol": tol,
                    "median_iterations": float(np.median(r.iterations)),
                    "max_iterations": int(np.max(r.iterations)),
                    "converged_fraction": float(np.mean(r.converged)),
                    "time_per_problem_us": 1e6 * seconds / B,
                    "median_residual": float(np.median(r.residual)),
                    "max_residual": float(np.max(r.residual)),
                    "max_abs_error_vs_moby": float(np.max(np.abs(r.lam - z_moby))),
                }
            )
    print_table(
        f"[4a] Speed vs smoothing bias: batch of {B} random P-matrix LCPs, d = {d}, "
        "jacobians=True, tol = 1e-12; rel. error = |lam_mu - lam_exact| / (1 + |lam_exact|)",
        [
            "mu",
            "median iters",
            "max iters",
            "converged",
            "time/problem [us]",
            "max rel. error",
            "median rel. error",
        ],
        [
            [
                r["mu"],
                r["median_iterations"],
                r["max_iterations"],
                f"{r['converged_fraction']:.0%}",
                r["time_per_problem_us"],
                r["max_rel_error_vs_exact"],
                r["median_rel_error_vs_exact"],
            ]
            for r in mu_rows
        ],
    )
    print(
        f"lam_exact = solve_lcp(mu = 0); its max |lam_exact - z_moby| over the batch = "
        f"{fmt(exact_vs_moby)}"
    )
    print_table(
        f"[4b] Speed vs accuracy of the exact LCP (mu = 0): same batch (B = {B}, d = {d}), "
        "jacobians=True, exact_tol = tol (tol floored at 1e-12)",
        [
            "tol",
            "median iters",
            "max iters",
            "converged",
            "time/problem [us]",
            "median residual",
            "max residual",
            "max |lam - z_moby|",
        ],
        [
            [
                r["tol"],
                r["median_iterations"],
                r["max_iterations"],
                f"{r['converged_fraction']:.0%}",
                r["time_per_problem_us"],
                r["median_residual"],
                r["max_residual"],
                r["max_abs_error_vs_moby"],
            ]
            for r in tol_rows
        ],
    )
    return {
        "d": d,
        "B": B,
        "lam_exact_max_abs_diff_vs_moby": exact_vs_moby,
        "mu_rows": mu_rows,
        "tol_rows": tol_rows,
    }


# --- section 5: problem families ----------------------------------------------------------------

FAMILY_DIMS = (10, 16, 20, 24, 32, 48, 64, 101)
FRICTION_CONTACTS = (2, 4, 8, 10, 17)  # d = 6 per contact: 12 .. 102
FAMILY_SMOOTH_MU = 1e-6


def independent_check(F: np.ndarray, q: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """(B,) the largest relative violation of each answer, recomputed from F, q and lam."""
    w = np.einsum("bij,bj->bi", F, lam) + q
    row = np.abs(q) + np.einsum("bij,bj->bi", np.abs(F), np.abs(lam)) + np.finfo(float).tiny
    diag = np.abs(np.diagonal(F, axis1=-2, axis2=-1))
    comp = np.minimum(np.abs(lam) * diag, np.abs(w))
    return np.max(np.maximum(np.maximum(-w, -lam * diag), comp) / row, axis=1)


def family_problems(cfg: Config) -> Iterator[tuple[str, int, np.ndarray, np.ndarray, str]]:
    """(family, d, F (n, d, d), q (n, d), on_bad_matrix) for every row of section 5."""
    n = max(3, cfg.n_problems // 3)
    for name, make in (
        ("Csizmadia", csizmadia),
        ("Murty", murty),
        ("Fathy", fathy),
    ):
        for d in FAMILY_DIMS:
            F, q, _ = make(d)
            yield name, d, F[None], q[None], "raise"
    for d in FAMILY_DIMS:  # the same matrices, harder right-hand sides
        F = csizmadia(d)[0]
        yield "Csizmadia, q = -1", d, F[None], -np.ones((1, d)), "raise"
    for d in FAMILY_DIMS:
        F = csizmadia(d)[0]
        q = rng_for(5, 8, d).standard_normal((n, d))
        yield "Csizmadia, random q", d, np.broadcast_to(F, (n, d, d)), q, "raise"
    for key, (name, make) in enumerate(
        (
            ("random P (non-sym.)", scaled_p_problems),
            ("random PSD (rank d/2)", singular_psd_problems),
            ("ill-cond. PD (1e10)", ill_conditioned_problems),
        )
    ):
        for d in FAMILY_DIMS:
            F, q = make(rng_for(5, key, d), d, n)
            yield name, d, F, q, "raise"
    for nc in FRICTION_CONTACTS:
        F, q = friction_problems(rng_for(5, 9, nc), nc, n)
        yield "friction (Stewart-Trinkle)", q.shape[1], F, q, "attempt"


def bench_families(cfg: Config, log: WarningLog) -> dict[str, Any]:
    rows = []
    with log.capture("5 problem families"):
        for name, d, F, q, policy in family_problems(cfg):
            n = q.shape[0]
            drake_abs.lcp.ipm.POLISH = False
            try:
                alone = solve_lcp(F, q, 0.0, on_bad_matrix=policy)
            finally:
                drake_abs.lcp.ipm.POLISH = True
            r = solve_lcp(F, q, 0.0, on_bad_matrix=policy)
            smooth = solve_lcp(F, q, FAMILY_SMOOTH_MU, on_bad_matrix=policy)
            check = independent_check(F, q, r.lam)
            # the old default refused every non-PSD F with d > 10 that was
            # not strictly diagonally dominant
            classes_now = np.asarray(r.matrix_class)
            old_refused = int(
                np.sum(
                    (policy == "raise")
                    & (d > 10)
                    & (classes_now != drake_abs.lcp.MatrixClass.PSD)
                    & ~_strictly_diagonally_dominant(F)
                )
            )
            conv = r.converged
            classes = sorted({int(c) for c in r.matrix_class})
            worst_residual = float(np.max(r.residual[conv])) if conv.any() else np.nan
            worst_check = float(np.max(check[conv])) if conv.any() else np.nan
            rows.append(
                {
                    "family": name,
                    "d": d,
                    "n_problems": n,
                    "matrix_class": "/".join(
                        "attempt" if c < 0 else drake_abs.lcp.MatrixClass(c).name for c in classes
                    ),
                    "old_default_refused": old_refused,
                    "ipm_alone_converged": int(alone.converged.sum()),
                    "converged": int(conv.sum()),
                    "polished": int(r.polished.sum()),
                    "median_iterations": float(np.median(r.iterations)),
                    "max_iterations": int(np.max(r.iterations)),
                    "max_pivots": int(np.max(r.pivots)),
                    "max_residual_converged": worst_residual,
                    "max_check_converged": worst_check,
                    "smoothed_converged": int(smooth.converged.sum()),
                }
            )
    print_table(
        "[5] Problem families at mu = 0: converged of attempted, interior point alone (second "
        "starts, no crossover) and with the crossover; iterations are the interior point's "
        "(all starts and the crossover's check), pivots the crossover's; check = independent "
        f"relative violation of the converged answers; last column: converged at mu = "
        f"{FAMILY_SMOOTH_MU:g}",
        [
            "family",
            "d",
            "class",
            "old: refused",
            "IPM alone",
            "with crossover",
            "polished",
            "median iters",
            "max iters",
            "max pivots",
            "max residual",
            "max check",
            f"mu={FAMILY_SMOOTH_MU:g}",
        ],
        [
            [
                r["family"],
                r["d"],
                r["matrix_class"],
                r["old_default_refused"],
                f"{r['ipm_alone_converged']}/{r['n_problems']}",
                f"{r['converged']}/{r['n_problems']}",
                r["polished"],
                r["median_iterations"],
                r["max_iterations"],
                r["max_pivots"],
                r["max_residual_converged"],
                r["max_check_converged"],
                f"{r['smoothed_converged']}/{r['n_problems']}",
            ]
            for r in rows
        ],
    )
    return {"rows": rows, "smoothed_mu": FAMILY_SMOOTH_MU}


# --- driver ------------------------------------------------------------------------------------


def metadata(cfg: Config) -> dict[str, Any]:
    try:
        drake_version = importlib.metadata.version("drake")
    except importlib.metadata.PackageNotFoundError:
        drake_version = "unknown"
    return {
        "config": asdict(cfg),
        "seed": SEED,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "drake": drake_version,
        "ipm_sha256": hashlib.sha256(Path(drake_abs.lcp.ipm.__file__).read_bytes()).hexdigest()[
            :12
        ],
        "platform": platform.platform(),
        "cpu_count": os.cpu_count(),
    }


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="reduced size (under a minute)")
    parser.add_argument(
        "--json",
        type=Path,
        default=Path("results/bench_lcp.json"),
        help="where to write the numbers as JSON (default: results/bench_lcp.json)",
    )
    parser.add_argument(
        "--families", action="store_true", help="run section 5 (problem families) only"
    )
    args = parser.parse_args(argv)
    cfg = QUICK if args.quick else FULL
    if args.families:
        log = WarningLog()
        results = {"meta": metadata(cfg), "families": bench_families(cfg, log)}
        args.json.parent.mkdir(parents=True, exist_ok=True)
        path = args.json.with_name(args.json.stem + "_families.json")
        path.write_text(json.dumps(results, indent=2, default=float) + "\n")
        print(f"Wrote {path}")
        return

    t_start = time.perf_counter()
    meta = metadata(cfg)
    print(
        f"bench_lcp ({cfg.name}): seed {SEED}, numpy {meta['numpy']}, drake {meta['drake']}, "
        f"python {meta['python']}, {meta['cpu_count']} CPU(s), drake_abs/lcp/ipm.py sha256 "
        f"{meta['ipm_sha256']}"
    )
    log = WarningLog()
    results: dict[str, Any] = {"meta": meta}
    results["iterations_vs_d"] = bench_iterations_vs_d(cfg, log)
    results["batched_throughput"] = bench_batched_throughput(cfg, log)
    results["moby"] = bench_moby(cfg, log)
    results["speed_vs_accuracy"] = bench_tradeoff(cfg, log)
    results["families"] = bench_families(cfg, log)

    distinct = {k: sorted(v) for k, v in log.distinct.items()}
    results["warnings"] = {"counts": log.counts, "distinct_messages": distinct}
    print("\nWarnings raised by the solver (captured; counts include timing repeats):")
    if not log.counts:
        print("  none")
    for section, count in log.counts.items():
        messages = distinct[section]
        print(f"  section {section}: {count} warning(s), {len(messages)} distinct, e.g.")
        for message in messages[:3]:
            print(f"    {message}")
    print("\nTargets:")
    for key in ("iterations_vs_d", "batched_throughput"):
        target = results[key]["target"]
        print(f"  {verdict(target['pass'])}  {target['description']}")
    elapsed = time.perf_counter() - t_start
    results["meta"]["elapsed_s"] = elapsed
    print(f"\nTotal benchmark time: {elapsed:.1f} s")

    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=2, default=float) + "\n")
    print(f"Wrote {args.json}")


if __name__ == "__main__":
    main()
