"""The differentiable QP-MPC policy (Zuliani et al. 2025, eq. 4) as a Drake system.

Every evaluation calls :meth:`drake_abs.mpc.qp_mpc.QpMpc.solve`, the same code the core closed loop
runs. Under AutoDiffXd the QP is solved in double and the KKT Jacobians du0/dx and du0/dtheta
are chained onto the derivatives that x (input port) and theta (numeric parameter) carry in, so a
diagram of plant + controller + cost differentiates as a whole with respect to the initial state
and/or theta.
"""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import (
    BasicVector_,
    LeafSystem_,
    NumericParameterIndex,
    ValueProducer,
)
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_abs.mpc.qp_mpc import MpcSpec, MpcStatus, QpMpc
from drake_abs.systems import autodiff

STATUS_FIELDS = ("status", "fallback", "iterations")


@TemplateSystem.define("MpcController_", T_list=[float, AutoDiffXd])
def MpcController_(T):
    class Impl(LeafSystem_[T]):
        """u = MPC(x, theta), solved by OSQP at every evaluation (direct feedthrough).

        .. pydrake_system::

            name: MpcController
            input_ports:
            - x
            output_ports:
            - u
            - status

        Input ``x`` (nx,): the measured state (absolute units). Output ``u`` (nu,): u_0 of the
        QP (absolute units); when the QP is not solved, the documented fallback
        clip(u_ref, u_min, u_max), never NaN. Output ``status`` (3,): the
        :class:`~drake_abs.mpc.qp_mpc.MpcStatus` code (0 = solved), 1.0 if the fallback was
        applied, and OSQP's iteration count (these carry no derivatives).

        The cost parameters theta (n_theta,) (docs/math.md section 9) are a numeric parameter of the
        Context (:meth:`SetTheta`); under AutoDiffXd they may carry derivatives.

        Both outputs come from one cached solve per (x, theta).

        Args:
            spec: the QP data (prediction model, horizon, reference, bounds, slack penalty).
            theta: default theta (n_theta,).
            osqp_settings: overrides of OSQP's settings (see :class:`QpMpc`).
            dual_tolerance: the active-set rule's multiplier threshold (see
                :mod:`~drake_abs.mpc.qp_mpc`).
        """

        def _construct(
            self,
            spec: MpcSpec,
            theta,
            osqp_settings: dict | None = None,
            dual_tolerance: float = 1e-9,
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            self.spec = spec
            self.osqp_settings = dict(osqp_settings or {})
            self.dual_tolerance = dual_tolerance
            self.qp = QpMpc(
                spec, theta, osqp_settings=self.osqp_settings, dual_tolerance=dual_tolerance
            )
            self.theta0 = self.qp.theta
            self.x_port = self.DeclareVectorInputPort("x", spec.nx)
            self._theta = self.DeclareNumericParameter(BasicVector_[T](self.theta0))
            self._solution = self.DeclareCacheEntry(
                "mpc_solution",
                ValueProducer(
                    allocate=AbstractValue.Make((None, None)).Clone, calc=self._CalcSolution
                ),
                {
                    self.input_port_ticket(self.x_port.get_index()),
                    self.numeric_parameter_ticket(NumericParameterIndex(self._theta)),
                },
            )
            self.u_port = self.DeclareVectorOutputPort(
                "u", spec.nu, self._CalcU, {self._solution.ticket()}
            )
            self.status_port = self.DeclareVectorOutputPort(
                "status", len(STATUS_FIELDS), self._CalcStatus, {self._solution.ticket()}
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(
                self,
                other.spec,
                other.theta0,
                other.osqp_settings,
                other.dual_tolerance,
                converter=converter,
            )

        @property
        def n_theta(self) -> int:
            return self.qp.n_theta

        def SetTheta(self, context, theta) -> None:
            """Set theta (n_theta,) in this system's ``context`` (AutoDiffXd values allowed under
            AutoDiffXd)."""
            theta = np.asarray(theta)
            if theta.shape != (self.n_theta,):
                raise ValueError(f"theta must have shape ({self.n_theta},); got {theta.shape}")
            context.get_mutable_numeric_parameter(self._theta).SetFromVector(theta)

        def GetTheta(self, context) -> np.ndarray:
            return context.get_numeric_parameter(self._theta).CopyToVector()

        def _CalcSolution(self, context, abstract_value):
            x = self.x_port.Eval(context)
            theta = context.get_numeric_parameter(self._theta).CopyToVector()
            if autodiff.is_autodiff(x) or autodiff.is_autodiff(theta):
                (xv, tv), (gx, gt) = autodiff.split([x, theta])
                sol = self.qp.solve(xv, tv, jacobians=True)
                u = autodiff.join(sol.u0, sol.du0_dx @ gx + sol.du0_dtheta @ gt)
            else:
                sol = self.qp.solve(x, theta)
                u = sol.u0
            status = np.array([float(sol.status), float(sol.fallback), float(sol.iterations)])
            abstract_value.set_value((u, status))

        def _CalcU(self, context, output):
            u, _ = self._solution.Eval(context)
            output.SetFromVector(u)

        def _CalcStatus(self, context, output):
            _, status = self._solution.Eval(context)
            if T is AutoDiffXd:
                status = np.array([AutoDiffXd(s) for s in status])
            output.SetFromVector(status)

    return Impl


MpcController = MpcController_[None]


def status_name(code: float) -> str:
    """The MpcStatus name of a status-port code."""
    return MpcStatus(int(round(float(code)))).name
