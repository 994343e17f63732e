"""The mu-softened LCS as a Drake discrete-time system (docs/math.md section 1).

Every step calls :meth:`drake_abs.LCS.step`, the same code the batched core runs. Under
AutoDiffXd the step is solved in double and the implicit-function-theorem Jacobians are chained
onto the incoming derivatives (docs/math.md section 4).
"""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_abs.contact.lcs import LCS, GradientMode, check_gradient_mode
from drake_abs.contact.smoothing import Exact, SmoothingPolicy
from drake_abs.contact.unconverged import UnconvergedPolicy, check_unconverged_policy
from drake_abs.systems import autodiff


@TemplateSystem.define("LcsPlant_", T_list=[float, AutoDiffXd])
def LcsPlant_(T):
    class Impl(LeafSystem_[T]):
        """A linear complementarity system stepped every ``time_step`` seconds.

        .. pydrake_system::

            name: LcsPlant
            input_ports:
            - u
            output_ports:
            - state
            - lam
            - mu
            - converged

        Discrete state: ``x`` (dx), and the impulses ``lam`` (d) and central-path values ``mu``
        (d) of the most recent step (zero before the first), and whether its solve converged
        (``converged``: 1.0 or 0.0; 1.0 before the first step). Under AutoDiffXd, ``lam`` and
        ``mu`` carry derivatives too (``mu``'s are zero in the frozen gradient mode); the
        derivatives of an unconverged step follow ``on_unconverged``.

        Args:
            lcs: the system; its matrices already include the time step.
            time_step: update period in seconds (the h the LCS was built with).
            smoothing: per-contact mu policy (default Exact); larger mu is smoother.
            gradient: ``"total"`` (default: AutoDiffXd gives the derivative of the simulation)
                or ``"frozen"`` (Zhang et al. 2023, Algorithm 1; biased where mu depends on the
                state).
            on_unconverged: under AutoDiffXd, the derivatives of a step whose solve did not
                converge: ``"drop"`` (default: NaN, with a warning), ``"flag"`` (kept, with a
                warning) or ``"raise"`` (:mod:`drake_abs.contact.unconverged`).
        """

        def _construct(
            self,
            lcs: LCS,
            time_step: float,
            smoothing: SmoothingPolicy | None = None,
            gradient: GradientMode = "total",
            on_unconverged: UnconvergedPolicy = "drop",
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            check_unconverged_policy(on_unconverged)
            self.on_unconverged = on_unconverged
            if not (np.isfinite(time_step) and time_step > 0):
                raise ValueError(f"time_step must be a finite number > 0; got {time_step!r}")
            check_gradient_mode(gradient)
            self.lcs = lcs
            self.time_step = float(time_step)
            self.smoothing = Exact() if smoothing is None else smoothing
            self.gradient = gradient
            nx, nu, nc = lcs.dims
            self._x = self.DeclareDiscreteState(nx)
            self._lam = self.DeclareDiscreteState(nc)
            self._mu = self.DeclareDiscreteState(nc)
            self._ok = self.DeclareDiscreteState(np.ones(1))
            self.u_port = self.DeclareVectorInputPort("u", nu)
            self.state_port = self.DeclareStateOutputPort("state", self._x)
            self.lam_port = self.DeclareStateOutputPort("lam", self._lam)
            self.mu_port = self.DeclareStateOutputPort("mu", self._mu)
            self.converged_port = self.DeclareStateOutputPort("converged", self._ok)
            self.DeclarePeriodicDiscreteUpdateEvent(self.time_step, 0.0, self._Update)

        def _construct_copy(self, other, converter=None):
            Impl._construct(
                self,
                other.lcs,
                other.time_step,
                other.smoothing,
                other.gradient,
                other.on_unconverged,
                converter=converter,
            )

        def get_state_index(self):
            """Index of the discrete-state group that holds x."""
            return self._x

        def SetInitialState(self, context, x0) -> None:
            """Set x in this system's ``context`` (values; AutoDiffXd values under AutoDiffXd)."""
            context.SetDiscreteState(self._x, np.asarray(x0))

        def _Update(self, context, discrete_state):
            x = context.get_discrete_state(self._x).value()
            u = self.u_port.Eval(context)
            step = self.lcs.step
            if autodiff.is_autodiff(x) or autodiff.is_autodiff(u):
                (xv, uv), (gx, gu) = autodiff.split([x, u])
                r = step(xv, uv, self.smoothing, gradient=self.gradient, jacobians=True)
                J = autodiff.guarded_jacobians(
                    r.converged, self.on_unconverged,
                    r.dx_dx, r.dx_du, r.dimpulse_dx, r.dimpulse_du, r.dmu_dx, r.dmu_du,
                )  # fmt: skip
                x_next = autodiff.chain(r.x_next, J[0], J[1], gx, gu)
                lam = autodiff.chain(r.impulse, J[2], J[3], gx, gu)
                mu = autodiff.chain(r.mu, J[4], J[5], gx, gu)
            else:
                r = step(x, u, self.smoothing, gradient=self.gradient, jacobians=False)
                x_next, lam, mu = r.x_next, r.impulse, r.mu
            discrete_state.set_value(self._x, x_next)
            discrete_state.set_value(self._lam, lam)
            discrete_state.set_value(self._mu, mu)
            ok = float(np.all(r.converged))
            discrete_state.set_value(self._ok, np.array([T(ok)]))

    return Impl


LcsPlant = LcsPlant_[None]
