"""What a rollout does with a step whose solver did not converge.

Such a step's impulses, next state and Jacobians are not those of the model (a solve stopped
after 2 iterations gave Jacobians 0.38 off). Rollouts and estimators therefore take an explicit
policy, ``on_unconverged``:

- ``"drop"`` (the default): the rollout is marked unused, its derivatives are NaN, and averages
  run over the rest; a :class:`UnconvergedStepWarning` says how many were dropped;
- ``"flag"``: the rollout is kept and counted, with the same warning;
- ``"raise"``: :class:`UnconvergedStepError`.

Why ``"drop"`` by default: averaging wrong Jacobians into a gradient would hide them, and
raising would end a long training run on one rare failure. Dropping conditions the estimate on
convergence, a bias the reported counts make visible.
"""

from __future__ import annotations

import warnings
from typing import Literal

import numpy as np

#: What rollouts and estimators do with a rollout that took an unconverged solver step:
#: ``"drop"`` (default) leaves it out of every average and marks its gradient NaN, ``"flag"``
#: keeps it (counted and warned), ``"raise"`` raises :class:`UnconvergedStepError`.
UnconvergedPolicy = Literal["drop", "flag", "raise"]
UNCONVERGED_POLICIES = ("drop", "flag", "raise")


class UnconvergedStepError(RuntimeError):
    """A rollout took a step whose solver did not converge (``on_unconverged="raise"``)."""


class UnconvergedStepWarning(UserWarning):
    """Rollouts took unconverged solver steps; says how many and what was done with them."""


def check_unconverged_policy(on_unconverged: str) -> None:
    if on_unconverged not in UNCONVERGED_POLICIES:
        raise ValueError(
            f"on_unconverged must be one of {UNCONVERGED_POLICIES}; got {on_unconverged!r}"
        )


def apply_unconverged_policy(converged: np.ndarray, on_unconverged: str) -> np.ndarray:
    """The ``used`` mask (B,) of rollouts with step flags ``converged`` (B, T), after warning or
    raising as ``on_unconverged`` says (see :data:`UnconvergedPolicy`)."""
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
