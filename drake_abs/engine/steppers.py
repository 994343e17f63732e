"""Steppers that wrap a model or another stepper (docs/math.md section 7).

- :class:`LinearStepper`: ``x+ = A x + B u``, for tests, LQR checks and identified models.
- :class:`ModelJacobians`: another stepper's next state with a linear model's Jacobians: the
  model-based gradient of gray-box tuning (Zuliani et al. 2025, eq. 8a with J_g = (A, B)), where
  the true
  system is only simulated and its derivatives come from the identified model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from drake_abs._validation import as_finite_array, check_shape
from drake_abs.contact.step import Step, contact_free_step
from drake_abs.engine.protocols import Stepper


def _no_parameters(stepper, parameters: bool) -> None:
    if parameters:
        raise ValueError(f"parameters=True: {type(stepper).__name__} names no model parameters")


@dataclass(frozen=True)
class LinearStepper:
    """``x+ = A x + B u`` for a batch: A (nx, nx), B (nx, nu)."""

    A: np.ndarray
    B: np.ndarray

    def __post_init__(self):
        A = as_finite_array(self.A, "A", ndim=(2,))
        B = as_finite_array(self.B, "B", ndim=(2,))
        check_shape(A, (A.shape[0],) * 2, "A", "(nx, nx)")
        check_shape(B, (A.shape[0], B.shape[1]), "B", "(nx, nu)")
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "B", B)

    parameter_names: ClassVar[tuple[str, ...]] = ()

    def step(self, x, u, *, jacobians: bool = True, parameters: bool = False) -> Step:
        """x (M, nx) or (nx,), u (M, nu) or (nu,)."""
        _no_parameters(self, parameters)
        x = np.asarray(x, dtype=float)
        u = np.asarray(u, dtype=float)
        x_next = x @ self.A.T + u @ self.B.T
        if not jacobians:
            return contact_free_step(x_next)
        batch = x_next.shape[:-1]
        return contact_free_step(
            x_next, np.broadcast_to(self.A, batch + self.A.shape),
            np.broadcast_to(self.B, batch + self.B.shape),
        )  # fmt: skip


@dataclass(frozen=True)
class ModelJacobians:
    """The next state of ``stepper`` (the true system, simulated without derivatives) with the
    Jacobians of the linear model (A, B): gray-box tuning's model-based gradient (Zuliani et al.
    2025,
    section 4.2). Everything but the Jacobians is ``stepper``'s own step."""

    stepper: Stepper
    A: np.ndarray
    B: np.ndarray

    def __post_init__(self):
        model = LinearStepper(self.A, self.B)
        object.__setattr__(self, "A", model.A)
        object.__setattr__(self, "B", model.B)

    parameter_names: ClassVar[tuple[str, ...]] = ()

    def step(self, x, u, *, jacobians: bool = True, parameters: bool = False) -> Step:
        _no_parameters(self, parameters)
        s = self.stepper.step(x, u, jacobians=False)
        if not jacobians:
            return s
        batch = s.x_next.shape[:-1]
        return Step(
            x_next=s.x_next, converged=s.converged, iterations=s.iterations, impulse=s.impulse,
            mu=s.mu, dx_dx=np.broadcast_to(self.A, batch + self.A.shape),
            dx_du=np.broadcast_to(self.B, batch + self.B.shape),
        )  # fmt: skip
