"""What a rollout does with a step whose solver did not converge.

Such a step's impulses, next state and Jacobians are not those of the model (a solve stopped
after 2 iterations gave Jacobians 0.38 off). Rollouts and estimators therefore take an explicit
choice, ``on_unconverged``:

- ``"drop"`` (the default): the rollout is marked unused, its derivatives are NaN, and averages
  run over the rest; a :class:`UnconvergedStepWarning` says how many were dropped;
- ``"flag"``: the rollout is kept and counted, with the same warning;
- ``"raise"``: :class:`UnconvergedStepError`.

Before any of that, a step never moves its state by an unconverged iterate: every contact step
(:meth:`drake_abs.contact.lcs.LCS.step` and
:func:`drake_abs.contact.contact_lcp.contact_step`) passes its solve through
:func:`exact_fallback`, which replaces a smoothed solve that did not converge by the exact
(mu = 0) solution of the same step where that converges. The step stays flagged.

Why ``"drop"`` by default: averaging wrong Jacobians into a gradient would hide them, and
raising would end a long training run on one rare failure. Dropping conditions the estimate on
convergence, a bias the reported counts make visible.
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import Literal

import numpy as np

from drake_abs.lcp.ipm import LCPConvergenceWarning, LCPResult, solve_lcp_trusted

#: What rollouts and estimators do with a rollout that took an unconverged solver step:
#: ``"drop"`` (default) leaves it out of every average and marks its gradient NaN, ``"flag"``
#: keeps it (counted and warned), ``"raise"`` raises :class:`UnconvergedStepError`.
OnUnconverged = Literal["drop", "flag", "raise"]
UNCONVERGED_POLICIES = ("drop", "flag", "raise")


class UnconvergedStepError(RuntimeError):
    """A rollout took a step whose solver did not converge (``on_unconverged="raise"``)."""


class UnconvergedStepWarning(UserWarning):
    """Rollouts took unconverged solver steps; says how many and what was done with them."""


def check_on_unconverged(on_unconverged: str) -> None:
    if on_unconverged not in UNCONVERGED_POLICIES:
        raise ValueError(
            f"on_unconverged must be one of {UNCONVERGED_POLICIES}; got {on_unconverged!r}"
        )


def apply_on_unconverged(converged: np.ndarray, on_unconverged: str) -> np.ndarray:
    """The ``used`` mask (B,) of rollouts with step flags ``converged`` (B, T), after warning or
    raising as ``on_unconverged`` says (see :data:`OnUnconverged`)."""
    clean = converged.all(axis=1)
    if clean.all():
        return clean
    n_bad, n_steps = int((~clean).sum()), int((~converged).sum())
    what = f"{n_bad} of {clean.size} rollouts took unconverged solver steps ({n_steps} steps)"
    if on_unconverged == "raise":
        raise UnconvergedStepError(what + " (on_unconverged='raise')")
    if on_unconverged == "drop":
        warnings.warn(what + "; they are dropped", UnconvergedStepWarning, 3)
        return clean
    warnings.warn(what + "; they are kept (on_unconverged='flag')", UnconvergedStepWarning, 3)
    return np.ones_like(clean)


def exact_fallback(F, z, mu, lcp: LCPResult, *, jacobians: bool, monotone: bool = False,
                   **options) -> LCPResult:  # fmt: skip
    """A step's LCP solve with its unconverged smoothed problems replaced by their exact ones.

    Where a problem with some mu > 0 did not converge and the exact (mu = 0) problem of the
    same step does, the exact solution (hard contact: a physically valid step) replaces the
    unconverged iterate in ``lam``, ``slack``, ``mu``, ``mu_target`` and the Jacobians. Its
    ``converged`` flag stays False (it is not the smoothing asked for), and a warning says how
    many were replaced. F (d, d) shared or (B, d, d); z, mu (B, d); ``monotone`` and
    ``options`` as the first solve's.
    """
    bad = np.flatnonzero(~lcp.converged & np.any(mu > 0, axis=1))
    if not bad.size:
        return lcp
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LCPConvergenceWarning)
        exact = solve_lcp_trusted(F if F.ndim == 2 else F[bad], z[bad], np.zeros_like(mu[bad]),
                                  jacobians=jacobians, monotone=monotone, **options)  # fmt: skip
    rows = bad[exact.converged]
    if not rows.size:
        return lcp
    fields = {}
    for name in ("lam", "slack", "mu", "mu_target", "dlam_dq", "dlam_dmu"):
        value = getattr(lcp, name)
        if value is not None:
            value = value.copy()
            value[rows] = getattr(exact, name)[exact.converged]
            fields[name] = value
    warnings.warn(
        f"{rows.size} smoothed contact step(s) did not converge; they use the exact (mu = 0) "
        "solution of the same step instead of the unconverged iterate and stay flagged "
        "converged = False",
        LCPConvergenceWarning,
        stacklevel=3,
    )
    return dataclasses.replace(lcp, **fields)
