"""A stepper that keeps what its steps carried beyond the engine's trajectory.

:class:`~drake_abs.engine.closed_loop.Trajectory` keeps the states, inputs, contact impulses,
``mu`` and ``converged`` of a rollout. A stepper's :class:`~drake_abs.contact.step.Step` may
carry more (a scene's or MuJoCo's joint-limit impulses ``limit_impulse``, a scene's
``friction_impulse``, the solver's ``iterations``): :class:`StepLog` wraps the stepper, passes
every call through unchanged and keeps the named fields of every step, in call order.
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from drake_abs.contact.step import Step
from drake_abs.engine.protocols import Stepper, check_protocol

__all__ = ["StepLog"]

_KEPT = tuple(f.name for f in fields(Step) if f.name not in ("theta_names", "lcp"))


class StepLog:
    """``stepper`` with a record of the named ``Step`` fields of every call.

    Args:
        stepper: the inner :class:`~drake_abs.engine.protocols.Stepper`.
        names: the ``Step`` fields to keep (arrays with the batch as their first axis), e.g.
            ``("limit_impulse",)``.

    After a rollout of H steps of a batch of B, :meth:`stacked` gives a field's values as one
    array (B, H, ...), time on the second axis as in the trajectory.
    """

    def __init__(self, stepper: Stepper, names: tuple[str, ...] = ("limit_impulse",)):
        check_protocol(stepper, Stepper, "stepper", "step(x, u, *, jacobians, parameters) -> Step")
        names = (names,) if isinstance(names, str) else tuple(names)
        unknown = [n for n in names if n not in _KEPT]
        if unknown or not names:
            raise ValueError(f"names must be fields of Step among {list(_KEPT)}; got {names}")
        self.stepper = stepper
        self.names = names
        self.records: dict[str, list] = {n: [] for n in names}

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """The inner stepper's model parameters."""
        return tuple(self.stepper.parameter_names)

    def step(self, x, u, *, jacobians: bool = True, parameters: bool = False, **options) -> Step:
        """The inner stepper's step, unchanged; its named fields are kept."""
        step = self.stepper.step(x, u, jacobians=jacobians, parameters=parameters, **options)
        for name in self.names:
            self.records[name].append(getattr(step, name))
        return step

    def stacked(self, name: str) -> np.ndarray:
        """The kept values of field ``name`` over the calls so far: (B, calls, ...).
        ``ValueError`` when the field was not kept, or a step did not carry it (None)."""
        if name not in self.records:
            raise ValueError(
                f"name must be one of the kept fields {list(self.names)}; got {name!r}"
            )
        values = self.records[name]
        if any(v is None for v in values):
            raise ValueError(f"{type(self.stepper).__name__}'s steps do not carry {name!r}")
        if not values:
            raise ValueError(f"no steps kept yet for {name!r}")
        return np.stack(values, axis=1)
