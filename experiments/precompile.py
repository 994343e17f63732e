"""Compile and cache the project's numba kernels ahead of first use.

The interior-point kernel, the contact assembly and the pinocchio Jacobian kernels are compiled
by numba on their first call and cached on disk (``cache=True``, beside the sources). Without a
cache, a new install's first ``solve_lcp`` spends tens of seconds compiling (measured on this
project's 2-core machine: 17.7 s for the first solve, 0.22 s once cached). ``make`` runs
``drake-abs precompile`` after installing, so a user's first call in a new process loads the
compiled code instead of compiling it.

Each case below calls a public entry point the way users do, with and without Jacobians, on one
problem and on a batch, so that every type signature the common paths use is compiled.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np


def _lcp() -> None:
    from drake_abs import solve_lcp

    F = np.array([[2.0, 1.0], [1.0, 2.0]])
    q = np.array([-1.0, 0.5])
    for jac in (False, True):
        solve_lcp(F, q, mu=1e-6, jacobians=jac)  # one problem, scalar mu
        solve_lcp(F, np.tile(q, (3, 1)), mu=np.full((3, 2), 1e-6), jacobians=jac)  # per contact
        solve_lcp(np.stack([F, 2 * F]), np.tile(q, (2, 1)), mu=0.0, jacobians=jac)  # one F each
    big = np.eye(12) + 0.1 * np.ones((12, 12))  # the LU and LAPACK sizes of the Newton system
    solve_lcp(big, -np.ones(12), mu=1e-8, jacobians=True)
    solve_lcp(np.eye(40), -np.ones(40), mu=1e-8, jacobians=True)


def _lcs() -> None:
    from drake_abs import ContactAware, LcsStepper, open_loop, point_mass_lcs

    lcs = point_mass_lcs(2, time_step=0.01)
    x0 = np.array([[0.0, 0.05, 1.0, -1.0]])
    for gradient in ("frozen", "total"):
        open_loop(LcsStepper(lcs, ContactAware(1e-2, 0.05), gradient), x0, np.zeros((5, 2)))


def _scenes() -> None:
    from drake_abs.contact.smoothing import Exact
    from drake_abs.multibody import build_scene_model

    for name in ("box_push", "hopper"):
        model = build_scene_model(name)
        x, u = model.x0, np.zeros(model.contact_model.nu)
        for smoothing in (Exact(), None):  # exact, and the scene's own smoothing
            stepper = model.stepper(smoothing=smoothing)
            for jac in (False, True):
                stepper.step(x[None], u, jacobians=jac)  # one state: the shared-kinematics path
                stepper.step(np.tile(x, (3, 1)), u, jacobians=jac)  # a batch


CASES: dict[str, Callable[[], None]] = {"lcp": _lcp, "lcs": _lcs, "scenes": _scenes}


def precompile(verbose: bool = True) -> dict[str, float]:
    """Run every case once; returns the seconds each took (compiling, or loading the cache)."""
    times = {}
    for name, case in CASES.items():
        t0 = time.perf_counter()
        case()
        times[name] = time.perf_counter() - t0
        if verbose:
            print(f"  {name:8s} {times[name]:6.1f} s", flush=True)
    return times
