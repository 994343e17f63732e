"""The 12-state quadcopter (Zuliani et al. 2025, section 7) as a Drake discrete-time system.

Every step calls :func:`drake_abs.tasks.quadcopter.step`, the same code the core runs. Under
AutoDiffXd the step is taken in double and its analytic Jacobians are chained onto the incoming
derivatives.
"""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_abs.systems import autodiff
from drake_abs.tasks import quadcopter
from drake_abs.tasks.quadcopter import NU, NX, QuadcopterParams


@TemplateSystem.define("QuadcopterPlant_", T_list=[float, AutoDiffXd])
def QuadcopterPlant_(T):
    class Impl(LeafSystem_[T]):
        """Forward-Euler quadcopter, updated every ``params.time_step`` seconds (0.1 s).

        .. pydrake_system::

            name: QuadcopterPlant
            input_ports:
            - u
            output_ports:
            - state

        Discrete state and output ``state``: x (12,) = (position (m), velocity (m/s), roll,
        pitch, yaw (rad, Z-Y-X), body rates (rad/s)); input ``u``: the four rotor speeds (rad/s).
        Conventions in :mod:`drake_abs.tasks.quadcopter`.

        Args:
            params: physical constants and time step (default :class:`QuadcopterParams`).
        """

        def _construct(self, params: QuadcopterParams | None = None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            params = params or QuadcopterParams()
            if not isinstance(params, QuadcopterParams):
                raise ValueError(f"params must be a QuadcopterParams; got {type(params).__name__}")
            self.params = params
            self.time_step = params.time_step
            self._x = self.DeclareDiscreteState(NX)
            self.u_port = self.DeclareVectorInputPort("u", NU)
            self.state_port = self.DeclareStateOutputPort("state", self._x)
            self.DeclarePeriodicDiscreteUpdateEvent(self.time_step, 0.0, self._Update)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.params, converter=converter)

        def SetInitialState(self, context, x0) -> None:
            """Set x (12,) in this system's ``context`` (AutoDiffXd values under AutoDiffXd)."""
            context.SetDiscreteState(self._x, np.asarray(x0))

        def _Update(self, context, discrete_state):
            x = context.get_discrete_state(self._x).value()
            u = self.u_port.Eval(context)
            if autodiff.is_autodiff(x) or autodiff.is_autodiff(u):
                (xv, uv), (gx, gu) = autodiff.split([x, u])
                s = quadcopter.step(xv, uv, self.params, jacobians=True)
                x_next = autodiff.chain(s.x_next, s.dx_dx, s.dx_du, gx, gu)
            else:
                x_next = quadcopter.step(x, u, self.params).x_next
            discrete_state.set_value(self._x, x_next)

    return Impl


QuadcopterPlant = QuadcopterPlant_[None]
