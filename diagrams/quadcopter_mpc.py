"""The closed loop of Zuliani et al. (2025) as one Drake diagram: quadcopter + MPC + cost,
differentiable.

``make_quadcopter_mpc_diagram`` connects
:class:`~drake_abs.systems.quadcopter_plant.QuadcopterPlant` (the true, nonlinear dynamics),
:class:`~drake_abs.systems.mpc_controller.MpcController` and :class:`ClosedLoopCost` (the
upper-level cost and penalty of
:class:`drake_abs.mpc.graybox.TrackingCost`, accumulated step by step), plus a log of the
controller's status. ``simulate_closed_loop`` runs it for T steps; with ``gradient="theta"`` it
converts the diagram to AutoDiffXd, seeds the controller's theta parameter and returns
d total / d theta through the whole diagram: the exact-model gradient of eq. 8 (the plant's own
Jacobians), which :func:`drake_abs.mpc.graybox.closed_loop` with ``gradient="exact"`` computes
in the core. ``gradient="x0"`` seeds the initial state instead (d x_T / d x_0, for the LQR check).

Timing: Drake takes the discrete updates of all three systems at t = k dt from the same context,
so the cost system adds stage(x_k, u_k) with the u_k the plant applies; after T steps its
output adds the terminal cost and penalty of x_T.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.systems.analysis import Simulator, Simulator_
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem_
from pydrake.systems.primitives import LogVectorOutput
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_abs.mpc.graybox import TrackingCost
from drake_abs.mpc.qp_mpc import MpcSpec
from drake_abs.systems import autodiff
from drake_abs.systems.mpc_controller import MpcController
from drake_abs.systems.quadcopter_plant import QuadcopterPlant
from drake_abs.tasks.quadcopter import QuadcopterParams

COST_FIELDS = ("tracking_cost", "violation", "total", "fallback_steps")


@TemplateSystem.define("ClosedLoopCost_", T_list=[float, AutoDiffXd])
def ClosedLoopCost_(T):
    class Impl(LeafSystem_[T]):
        """Accumulates the closed-loop cost of Zuliani et al. 2025, section 7 every ``time_step``
        seconds.

        .. pydrake_system::

            name: ClosedLoopCost
            input_ports:
            - x
            - u
            - status
            output_ports:
            - cost

        Discrete state (3,): sum over past steps of the stage cost ||x - x_ref||_Q^2 +
        ||u - u_ref||_R^2, of dist_1(x, X), and of the fallback flag (status[1]). Output
        ``cost`` (4,): tracking cost C (the sum plus the terminal cost of the current x),
        violation dist_1 (sum plus the current x's), total C + w violation, and the number of
        fallback steps. Under AutoDiffXd the gradients of the cost terms are chained in double.

        Args:
            cost: the upper-level cost (weights, reference, state box, penalty weight w).
            time_step: period (s), the plant's.
        """

        def _construct(self, cost: TrackingCost, time_step: float, converter=None):
            LeafSystem_[T].__init__(self, converter)
            if not (np.isfinite(time_step) and time_step > 0):
                raise ValueError(f"time_step must be a finite number > 0; got {time_step!r}")
            self.cost = cost
            self.time_step = float(time_step)
            nx, nu = cost.x_ref.size, cost.u_ref.size
            self._acc = self.DeclareDiscreteState(3)
            self.x_port = self.DeclareVectorInputPort("x", nx)
            self.u_port = self.DeclareVectorInputPort("u", nu)
            self.status_port = self.DeclareVectorInputPort("status", 3)
            self.cost_port = self.DeclareVectorOutputPort("cost", len(COST_FIELDS), self._CalcCost)
            self.DeclarePeriodicDiscreteUpdateEvent(self.time_step, 0.0, self._Update)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.cost, other.time_step, converter=converter)

        def _Update(self, context, discrete_state):
            acc = context.get_discrete_state(self._acc).value()
            x = self.x_port.Eval(context)
            u = self.u_port.Eval(context)
            status = self.status_port.Eval(context)
            if autodiff.is_autodiff(acc) or autodiff.is_autodiff(x) or autodiff.is_autodiff(u):
                (av, xv, uv, sv), (ga, gx, gu, _) = autodiff.split([acc, x, u, status])
                stage, dsx, dsu = self.cost.stage(xv, uv)
                viol, dvx = self.cost.violation(xv)
                value = av + np.array([stage, viol, sv[1]])
                grad = ga + np.vstack([dsx @ gx + dsu @ gu, dvx @ gx, np.zeros(ga.shape[1])])
                discrete_state.set_value(self._acc, autodiff.join(value, grad))
                return
            stage, _, _ = self.cost.stage(x, u)
            viol, _ = self.cost.violation(x)
            discrete_state.set_value(self._acc, acc + np.array([stage, viol, status[1]]))

        def _CalcCost(self, context, output):
            acc = context.get_discrete_state(self._acc).value()
            x = self.x_port.Eval(context)
            w = self.cost.penalty_weight
            if autodiff.is_autodiff(acc) or autodiff.is_autodiff(x):
                (av, xv), (ga, gx) = autodiff.split([acc, x])
                term, dtx = self.cost.terminal(xv)
                viol, dvx = self.cost.violation(xv)
                C, V = av[0] + term, av[1] + viol
                gC, gV = ga[0] + dtx @ gx, ga[1] + dvx @ gx
                value = np.array([C, V, C + w * V, av[2]])
                grad = np.vstack([gC, gV, gC + w * gV, np.zeros_like(gC)])
                output.SetFromVector(autodiff.join(value, grad))
                return
            term, _ = self.cost.terminal(x)
            viol, _ = self.cost.violation(x)
            C, V = acc[0] + term, acc[1] + viol
            output.SetFromVector(np.array([C, V, C + w * V, acc[2]]))

    return Impl


ClosedLoopCost = ClosedLoopCost_[None]


def make_quadcopter_mpc_diagram(
    spec: MpcSpec,
    theta,
    cost: TrackingCost,
    params: QuadcopterParams | None = None,
    *,
    osqp_settings: dict | None = None,
) -> Diagram:
    """Quadcopter (``"quadcopter"``) + MPC (``"mpc"``) + cost (``"cost"``) + a log of the MPC
    status (``"status_log"``), all updated every ``params.time_step``.

    Exported outputs: ``quadcopter.state`` (12,), ``mpc.u`` (4,), ``mpc.status`` (3,),
    ``cost.cost`` (4,: tracking cost, violation, total, fallback steps).
    """
    params = params or QuadcopterParams()
    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("quadcopter", QuadcopterPlant(params))
    mpc = builder.AddNamedSystem("mpc", MpcController(spec, theta, osqp_settings=osqp_settings))
    evaluator = builder.AddNamedSystem("cost", ClosedLoopCost(cost, params.time_step))
    builder.Connect(plant.state_port, mpc.x_port)
    builder.Connect(mpc.u_port, plant.u_port)
    builder.Connect(plant.state_port, evaluator.x_port)
    builder.Connect(mpc.u_port, evaluator.u_port)
    builder.Connect(mpc.status_port, evaluator.status_port)
    log = LogVectorOutput(mpc.status_port, builder, publish_period=params.time_step)
    log.set_name("status_log")
    builder.ExportOutput(plant.state_port, "quadcopter.state")
    builder.ExportOutput(mpc.u_port, "mpc.u")
    builder.ExportOutput(mpc.status_port, "mpc.status")
    builder.ExportOutput(evaluator.cost_port, "cost.cost")
    diagram = builder.Build()
    diagram.set_name("quadcopter_mpc")
    return diagram


@dataclass(frozen=True)
class DiagramClosedLoop:
    """A closed-loop simulation of the diagram.

    Attributes:
        x_final: (12,) x_T. tracking_cost, violation, total: as in
            :class:`drake_abs.mpc.graybox.ClosedLoopResult`.
        status: (T,) MPC status codes per step; fallback: (T,) fallback flags.
        gradient: d total / d theta (n_theta,) for ``gradient="theta"``; d x_T / d x_0
            (12, 12) for ``gradient="x0"``; None otherwise.
    """

    x_final: np.ndarray
    tracking_cost: float
    violation: float
    total: float
    status: np.ndarray
    fallback: np.ndarray
    gradient: np.ndarray | None

    @property
    def fallback_steps(self) -> int:
        return int(np.sum(self.fallback))


def simulate_closed_loop(
    diagram: Diagram,
    theta,
    x0,
    steps: int,
    *,
    gradient: Literal["theta", "x0"] | None = None,
) -> DiagramClosedLoop:
    """Simulate ``steps`` control steps of a :func:`make_quadcopter_mpc_diagram` diagram from
    ``x0`` (12,) with cost parameters ``theta``; with ``gradient``, through AutoDiffXd."""
    if int(steps) != steps or steps < 1:
        raise ValueError(f"steps must be an integer >= 1; got {steps!r}")
    theta = np.asarray(theta, dtype=float)
    x0 = np.asarray(x0, dtype=float)
    if gradient not in (None, "theta", "x0"):
        raise ValueError(f"gradient must be None, 'theta' or 'x0'; got {gradient!r}")
    system = diagram if gradient is None else diagram.ToAutoDiffXd()
    plant = system.GetSubsystemByName("quadcopter")
    mpc = system.GetSubsystemByName("mpc")
    if theta.shape != (mpc.n_theta,):
        raise ValueError(f"theta must have shape ({mpc.n_theta},); got {theta.shape}")
    if x0.shape != (12,) or not np.all(np.isfinite(x0)):
        raise ValueError(f"x0 must be 12 finite numbers; got shape {x0.shape}")
    simulator = Simulator(system) if gradient is None else Simulator_[AutoDiffXd](system)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    mpc_context = mpc.GetMyMutableContextFromRoot(context)
    if gradient is None:
        plant.SetInitialState(plant_context, x0)
        mpc.SetTheta(mpc_context, theta)
    elif gradient == "theta":
        n = theta.size
        plant.SetInitialState(
            plant_context, InitializeAutoDiff(x0.reshape(-1, 1), np.zeros((12, n))).ravel()
        )
        mpc.SetTheta(mpc_context, InitializeAutoDiff(theta.reshape(-1, 1)).ravel())
    else:
        plant.SetInitialState(plant_context, InitializeAutoDiff(x0.reshape(-1, 1)).ravel())
        mpc.SetTheta(
            mpc_context,
            InitializeAutoDiff(theta.reshape(-1, 1), np.zeros((theta.size, 12))).ravel(),
        )
    simulator.Initialize()
    # periodic events fire at t = 0, dt, 2 dt, ...; the one at t = T dt is not taken
    simulator.AdvanceTo(int(steps) * plant.time_step)
    x = plant.state_port.Eval(plant_context)
    out = system.GetOutputPort("cost.cost").Eval(context)
    log = system.GetSubsystemByName("status_log").FindLog(context)
    status = np.asarray(log.data(), dtype=object)[:, : int(steps)]
    if gradient is None:
        x_final, values, grad = np.asarray(x, float), np.asarray(out, float), None
        status = status.astype(float)
    else:
        (x_final, values), (gx, gv) = autodiff.split([x, out])
        grad = gv[2] if gradient == "theta" else gx
        status = np.vectorize(lambda a: a.value())(status).astype(float)
    return DiagramClosedLoop(
        x_final=x_final,
        tracking_cost=float(values[0]),
        violation=float(values[1]),
        total=float(values[2]),
        status=np.rint(status[0]).astype(int),
        fallback=status[1] > 0.5,
        gradient=grad,
    )
