"""Steppers that wrap a model or another stepper (docs/math.md section 7).

- :class:`LinearStepper`: ``x+ = A x + B u``, for tests, LQR checks and identified models.
- :class:`ModelJacobians`: another stepper's next state with a linear model's Jacobians: the
  model-based gradient of gray-box tuning (Zuliani et al. 2025, eq. 8a with J_g = (A, B)), where
  the true
  system is only simulated and its derivatives come from the identified model.
- :class:`ZeroOrderHold`: another stepper's input held over ``substeps`` of its steps: a
  controller that acts every ``substeps`` model steps (gymnasium's ``frame_skip``), with the
  chained Jacobians.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from drake_abs._validation import as_finite_array, check_shape
from drake_abs.contact.step import Step, contact_free_step
from drake_abs.engine.protocols import Stepper


def inside_ground(stepper, x) -> tuple[np.ndarray, float] | None:
    """How deep (m) the states x (B, nx) are inside the ground, with the tolerance beyond
    which a state is not one the step models: ``(depth (B,), tolerance)`` from the first
    stepper, following wrappers' ``stepper`` attributes (:class:`ZeroOrderHold`,
    :class:`~drake_abs.tasks.adapters.ActionScaled`), that has ``penetration(x)`` and
    ``penetration_tolerance`` (a scene's
    :class:`~drake_abs.multibody.stepper.ComplementarityStepper`); None when there is none (a
    model without geometry, e.g. an LCS)."""
    seen = 0
    while stepper is not None and seen < 16:  # wrappers of wrappers; never a loop
        measure = getattr(stepper, "penetration", None)
        if callable(measure) and hasattr(stepper, "penetration_tolerance"):
            depth = np.asarray(measure(np.atleast_2d(np.asarray(x, dtype=float))), dtype=float)
            return depth, float(stepper.penetration_tolerance)
        stepper, seen = getattr(stepper, "stepper", None), seen + 1
    return None


def refuse_inside_ground(stepper, x, name: str = "x0") -> None:
    """``ValueError`` naming ``name`` when a state of x is deeper inside the ground than the
    stepper's tolerance (see :func:`inside_ground`): the step would push the body out within
    one step, with an impulse no scene produced, and report it converged."""
    found = inside_ground(stepper, x)
    if found is None:
        return
    depth, tol = found
    if np.any(depth > tol):
        row = int(np.argmax(depth))
        where = "" if np.ndim(x) == 1 else f" (row {row})"
        raise ValueError(
            f"{name}{where} is {float(depth[row]):.4g} m inside the ground, deeper than the "
            f"{tol:g} m a step models (the stepper's penetration_tolerance): move the "
            "body out of the ground"
        )


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


@dataclass(frozen=True)
class ZeroOrderHold:
    """``stepper`` with its input held for ``substeps`` of its steps: one call steps a batch
    over one control period, ``x_{k+1} = f(x_k, u)`` for k = 0 .. substeps - 1 (gymnasium's
    ``frame_skip``; the control period is ``substeps`` times the inner time step).

    Jacobians by the chain rule over the substeps: ``dx/dx = A_n ... A_1`` and
    ``dx/du = sum_k A_n ... A_{k+1} B_k`` (and likewise ``dx_dtheta``). What a substep of the
    record reports is combined over the period: ``converged`` is True only where every substep
    converged, ``iterations`` and the impulses (N s) are summed, ``mu`` is the largest reached
    per contact, ``active`` any. The Jacobians of impulses and mu are not chained (None) when
    ``substeps > 1``; the engine needs only the state's. ``substeps = 1`` is the inner step.

    Args:
        stepper: the inner :class:`~drake_abs.engine.protocols.Stepper`.
        substeps: steps per held input, an integer >= 1.
    """

    stepper: Stepper
    substeps: int

    def __post_init__(self):
        if isinstance(self.substeps, bool) or not isinstance(self.substeps, (int, np.integer)):
            raise ValueError(f"substeps must be an integer >= 1; got {self.substeps!r}")
        if self.substeps < 1:
            raise ValueError(f"substeps must be an integer >= 1; got {self.substeps!r}")
        object.__setattr__(self, "substeps", int(self.substeps))

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """The inner stepper's model parameters."""
        return tuple(self.stepper.parameter_names)

    def step(self, x, u, *, jacobians: bool = True, parameters: bool = False, **options) -> Step:
        """One control period for a batch: x (M, nx), u (M, nu) (or what the inner stepper
        accepts); ``options`` go to every inner step."""
        first = self.stepper.step(x, u, jacobians=jacobians, parameters=parameters, **options)
        if self.substeps == 1:
            return first
        s = first
        Fx, Fu, Fth = s.dx_dx, s.dx_du, s.dx_dtheta
        converged = np.array(s.converged, dtype=bool)
        iterations = np.array(s.iterations)
        sums = {
            name: np.array(getattr(s, name))
            for name in ("impulse", "friction_impulse", "limit_impulse")
            if getattr(s, name) is not None
        }
        mu = np.array(s.mu)
        active = None if s.active is None else np.array(s.active, dtype=bool)
        for _ in range(self.substeps - 1):
            s = self.stepper.step(
                s.x_next, u, jacobians=jacobians, parameters=parameters, **options
            )
            converged &= s.converged
            iterations = iterations + s.iterations
            for name in sums:
                sums[name] = sums[name] + getattr(s, name)
            mu = np.maximum(mu, s.mu)
            if active is not None:
                active |= s.active
            if jacobians:
                Fx = s.dx_dx @ Fx
                Fu = s.dx_dx @ Fu + s.dx_du
            if parameters:
                Fth = s.dx_dx @ Fth + s.dx_dtheta
        return replace(
            s, converged=converged, iterations=iterations, mu=mu, active=active,
            dx_dx=Fx, dx_du=Fu, dx_dtheta=Fth, dimpulse_dx=None, dimpulse_du=None,
            dimpulse_dtheta=None, dmu_dx=None, dmu_du=None, dmu_dtheta=None, lcp=None, **sums,
        )  # fmt: skip
