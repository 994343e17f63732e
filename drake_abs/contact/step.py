"""The one step record: what every stepper returns for a batch of states (docs/math.md
section 4 and 6), whether it steps an LCS, a rigid-body scene or a contact-free model.

One set of names for every stepper, so that the closed-loop engine (:mod:`drake_abs.engine`),
the Drake systems and the experiments read any step the same way:

- the state: ``x_next`` and its Jacobians ``dx_dx``, ``dx_du`` (and ``dx_dtheta`` for the
  model parameters named by ``theta_names``, a block of its own, never part of ``dx_du``);
- the contact impulses: ``impulse`` and ``dimpulse_dx``, ``dimpulse_du``, ``dimpulse_dtheta``;
- the smoothing reached: ``mu`` (and ``dmu_dx``, ``dmu_du`` where the stepper forms them);
- the solver: ``converged`` and ``iterations``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np


@dataclass(frozen=True)
class Step:
    """One batched step. Shapes for a batch of B states with nx states, nu inputs, nc contacts
    and T model parameters (no leading axis where a stepper was given one unbatched state).

    Attributes:
        x_next: (B, nx) next state.
        converged: (B,) whether the step's solver converged (always True without contact
            solve); a False step's values and Jacobians are not the model's.
        iterations: (B,) interior-point iterations (0 where no LCP was solved).
        impulse: (B, nc) contact impulses (N s): for an LCS, the complementarity variable lam
            of every row; for a rigid-body scene, each contact candidate's normal impulse (0
            when the candidate was left out), Drake's plant included; for MuJoCo, each geom's
            normal impulse. nc = 0 for a model without contact.
        mu: (B, nc) central-path value reached per contact (0 when left out).
        dx_dx, dx_du: (B, nx, nx), (B, nx, nu) (None unless Jacobians were asked for).
        dimpulse_dx, dimpulse_du: (B, nc, nx), (B, nc, nu) (likewise).
        dmu_dx, dmu_du: (B, nc, nx), (B, nc, nu) Jacobians of the requested mu (zero in frozen
            mode; None where the stepper does not form them).
        dx_dtheta, dimpulse_dtheta: (B, nx, T), (B, nc, T) derivatives with respect to the model
            parameters named by ``theta_names`` (None unless asked for).
        dmu_dtheta: (B, nc, T) the same for mu, where the stepper forms it (an LCS does).
        theta_names: the T model parameters, in column order.
        friction_impulse: (B, nc, 3) tangential impulse in the world frame (N s), for a
            rigid-body scene (None otherwise).
        active: (B, nc) which candidates were in the step's LCP (None where all always are).
        limit_impulse: (B, nl) the impulses of a rigid-body scene's joint-limit rows (N m s or
            N s; 0 where a row was left out), in the order of the stepper's ``limits.names``
            (None for other steppers).
        joint_friction_impulse: (B, nj) the impulses of a rigid-body scene's dry joint friction
            (N m s or N s, along each joint's velocity: between -h F and h F for a friction
            bound F), in the order of the stepper's ``joint_friction.names`` (None for other
            steppers).
        lcp: the solver's full result, where one LCP was solved for the whole batch.
    """

    x_next: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    impulse: np.ndarray
    mu: np.ndarray
    dx_dx: np.ndarray | None = None
    dx_du: np.ndarray | None = None
    dimpulse_dx: np.ndarray | None = None
    dimpulse_du: np.ndarray | None = None
    dmu_dx: np.ndarray | None = None
    dmu_du: np.ndarray | None = None
    dx_dtheta: np.ndarray | None = None
    dimpulse_dtheta: np.ndarray | None = None
    dmu_dtheta: np.ndarray | None = None
    theta_names: tuple[str, ...] = ()
    friction_impulse: np.ndarray | None = None
    active: np.ndarray | None = None
    limit_impulse: np.ndarray | None = None
    joint_friction_impulse: np.ndarray | None = None
    lcp: object | None = None

    def first(self) -> Step:
        """The step of the first state, without the batch axis (``lcp`` keeps its own)."""
        keep = ("theta_names", "lcp")
        return replace(
            self,
            **{
                f.name: getattr(self, f.name)[0]
                for f in fields(self)
                if f.name not in keep and getattr(self, f.name) is not None
            },
        )


def contact_free_step(
    x_next: np.ndarray,
    dx_dx: np.ndarray | None = None,
    dx_du: np.ndarray | None = None,
) -> Step:
    """The record of a step without contact (e.g. a flying quadcopter, a linear model): no
    impulses; ``converged`` says the step is usable, i.e. its next state and Jacobians are
    finite (an overflowing model is flagged, never passed as valid). x_next has the batch shape
    S + (nx,)."""
    x_next = np.asarray(x_next)
    batch = x_next.shape[:-1]
    usable = np.isfinite(x_next).all(axis=-1)
    for J in (dx_dx, dx_du):
        if J is not None:
            usable &= np.isfinite(J).all(axis=(-2, -1))
    return Step(
        x_next=x_next,
        converged=usable,
        iterations=np.zeros(batch, dtype=np.int64),
        impulse=np.zeros(batch + (0,)),
        mu=np.zeros(batch + (0,)),
        dx_dx=dx_dx,
        dx_du=dx_du,
    )
