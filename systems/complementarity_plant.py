"""The complementarity plant as a Drake system: a MultibodyPlant's dynamics with the scene's
point contacts, stepped by :class:`drake_abs.multibody.ComplementarityStepper` (the same batched
step the rollouts use; this system only moves values and derivatives in and out of it).
"""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_abs.contact.unconverged import UnconvergedPolicy, check_unconverged_policy
from drake_abs.multibody.stepper import ComplementarityStepper
from drake_abs.systems import autodiff


@TemplateSystem.define("ComplementarityPlant_", T_list=[float, AutoDiffXd])
def ComplementarityPlant_(T):
    class Impl(LeafSystem_[T]):
        """A MultibodyPlant with complementarity contact, stepped every ``time_step`` seconds.

        .. pydrake_system::

            name: ComplementarityPlant
            input_ports:
            - actuation
            output_ports:
            - state
            - normal_impulse
            - mu
            - converged

        Discrete state: x = (q, v) of the plant, and the normal impulses and central-path
        values of the most recent step (zero before the first), and whether its solve
        converged (1.0 or 0.0). Under AutoDiffXd the step is solved in double and the implicit
        Jacobians are chained onto incoming derivatives of the state and the normal impulses
        (the mu port carries values only); those of an unconverged step follow
        ``on_unconverged``.

        Args:
            stepper: the batched step (model, smoothing, gradient mode, activation distance).
            on_unconverged: ``"drop"`` (default: NaN derivatives, with a warning), ``"flag"``
                or ``"raise"`` (:mod:`drake_abs.contact.unconverged`).
        """

        def _construct(
            self,
            stepper: ComplementarityStepper,
            on_unconverged: UnconvergedPolicy = "drop",
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            check_unconverged_policy(on_unconverged)
            self.on_unconverged = on_unconverged
            self.stepper = stepper
            nq, nv, nu, nc = stepper.sizes
            self._x = self.DeclareDiscreteState(nq + nv)
            self._n = self.DeclareDiscreteState(nc)
            self._mu = self.DeclareDiscreteState(nc)
            self._ok = self.DeclareDiscreteState(np.ones(1))
            self.actuation_port = self.DeclareVectorInputPort("actuation", nu)
            self.state_port = self.DeclareStateOutputPort("state", self._x)
            self.impulse_port = self.DeclareStateOutputPort("normal_impulse", self._n)
            self.mu_port = self.DeclareStateOutputPort("mu", self._mu)
            self.converged_port = self.DeclareStateOutputPort("converged", self._ok)
            self.DeclarePeriodicDiscreteUpdateEvent(stepper.model.h, 0.0, self._Update)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.stepper, other.on_unconverged, converter=converter)

        def SetInitialState(self, context, x0) -> None:
            """Set x = (q, v) in this system's ``context``."""
            context.SetDiscreteState(self._x, np.asarray(x0))

        def _Update(self, context, discrete_state):
            x = context.get_discrete_state(self._x).value()
            u = self.actuation_port.Eval(context) if self.stepper.sizes[2] else np.zeros(0)
            if autodiff.is_autodiff(x) or autodiff.is_autodiff(u):
                (xv, uv), (gx, gu) = autodiff.split([x, u])
                r = self.stepper.step(xv[None], uv[None], jacobians=True)
                r = r.first()
                J = autodiff.guarded_jacobians(
                    r.converged, self.on_unconverged, r.dx_dx, r.dx_du, r.dimpulse_dx, r.dimpulse_du
                )
                x_next = autodiff.chain(r.x_next, J[0], J[1], gx, gu)
                impulse = autodiff.chain(r.impulse, J[2], J[3], gx, gu)
                mu = autodiff.join(r.mu, np.zeros((r.mu.shape[0], gx.shape[1])))
            else:
                r = self.stepper.step(np.asarray(x)[None], np.asarray(u)[None], jacobians=False)
                x_next, impulse, mu = r.x_next[0], r.impulse[0], r.mu[0]
            discrete_state.set_value(self._x, x_next)
            discrete_state.set_value(self._n, impulse)
            discrete_state.set_value(self._mu, mu)
            discrete_state.set_value(self._ok, np.array([T(float(np.all(r.converged)))]))

    return Impl


ComplementarityPlant = ComplementarityPlant_[None]
